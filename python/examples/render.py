#!/usr/bin/python3
"""Renders a mesh with slimrt and numpy alone: camera rays from create_rays_pinhole, one
cast_rays for the primary hits, one test_occlusions for sun shadows, Lambert shading under a sun
and a sky, written as an 8-bit PNG (zlib from the standard library).

    PYTHONPATH=build/python /usr/bin/python3 python/examples/render.py [MESH] [-o out.png]
        [--res 800x600] [--config clbvh-compact] [--up z]

MESH is a mesh file (.obj .ply .gltf .glb, optionally .xz) or a procedural scene (terrain:N,
torus:N, canyon:N); default canyon:512."""
import argparse
import struct
import time
import zlib

import numpy as np

import slimrt


def write_png(path, rgb):
    """rgb: uint8 [h, w, 3]."""
    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].tobytes() for y in range(h))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + \
            struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b""))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mesh", nargs="?", default="canyon:512")
    ap.add_argument("-o", "--output", default="render.png")
    ap.add_argument("--res", default="800x600")
    ap.add_argument("--config", default="clbvh-compact")
    ap.add_argument("--up", choices="xyz", default="z")
    args = ap.parse_args()
    w, h = (int(x) for x in args.res.lower().split("x"))

    scene = slimrt.RaycastingScene(args.config)
    v, t, _ = slimrt.load_triangles(args.mesh)
    scene.add_triangles(v, t)

    up = np.eye(3)["xyz".index(args.up)]
    lo, hi = v.min(0).astype(np.float64), v.max(0).astype(np.float64)
    center, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    # From the front-right, 35 degrees above the horizon (front: -y for z up, +z otherwise).
    front = {"z": [0, -1, 0], "y": [0, 0, 1], "x": [0, 0, 1]}[args.up]
    side = np.cross(front, up)
    view = np.cos(np.radians(35)) * (np.cos(np.radians(30)) * np.array(front, float)
                                     + np.sin(np.radians(30)) * side) + np.sin(np.radians(35)) * up
    fov = 45.0  # horizontal, as Open3D's create_rays_pinhole takes it
    eye = center + view * radius / np.sin(np.radians(fov / 2))
    # Open3D's convention: the image's rows run along the up vector given (row 0 on the side of
    # -up), so -up gives an upright picture.
    rays = slimrt.RaycastingScene.create_rays_pinhole(fov, center, eye, -up, w, h)

    t0 = time.perf_counter()
    hit = scene.cast_rays(rays)
    t_hit, n = hit["t_hit"], hit["primitive_normals"]
    d = rays[..., 3:] / np.linalg.norm(rays[..., 3:], axis=-1, keepdims=True)
    n = np.where((np.sum(n * d, axis=-1) > 0)[..., None], -n, n)  # face the camera
    valid = np.isfinite(t_hit)
    p = rays[..., :3] + rays[..., 3:] * np.where(valid, t_hit, 0)[..., None]

    sun = view * 0.3 + np.cross(up, view) * 0.8 + up * 0.6
    sun = (sun / np.linalg.norm(sun)).astype(np.float32)
    eps = 1e-4 * radius
    shadow_rays = np.concatenate([p + n * eps, np.broadcast_to(sun, p.shape)], axis=-1)
    lit = ~scene.test_occlusions(shadow_rays.astype(np.float32)) & valid
    seconds = time.perf_counter() - t0

    lambert = np.clip(np.sum(n * sun, axis=-1), 0, None) * lit
    sky = 0.5 + 0.5 * (n @ up)  # hemisphere ambient
    albedo = np.array([0.75, 0.62, 0.48])
    color = albedo * (1.0 * lambert[..., None] + 0.3 * sky[..., None] * np.array([0.6, 0.7, 1.0]))
    bg = np.array([0.55, 0.7, 0.95]) * (0.6 + 0.4 * np.linspace(1, 0, h))[:, None, None]
    color = np.where(valid[..., None], color, bg)
    srgb = np.where(color <= 0.0031308, 12.92 * color, 1.055 * np.power(np.clip(color, 0, None),
                                                                         1 / 2.4) - 0.055)
    write_png(args.output, (np.clip(srgb, 0, 1) * 255 + 0.5).astype(np.uint8))
    print(f"{args.mesh}: {len(t)} triangles, {args.config}: "
          f"{scene.memory()['total'] / 1e6:.1f} MB; {2 * w * h} rays in {seconds:.2f} s; "
          f"wrote {args.output}")


if __name__ == "__main__":
    main()
