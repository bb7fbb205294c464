#!/usr/bin/python3
"""Casts the same rays through Open3D's RaycastingScene (Debian python3-open3d) and slimrt's
configurations; prints hits found, agreement with slimrt's uncompressed reference (bvh8-tri4v),
memory and Mrays/s for each.

    PYTHONPATH=build/python /usr/bin/python3 python/examples/compare_open3d.py [MESH ...]
        [--rays N] [--configs a,b,c] [--threads N]

MESH is a mesh file (.obj .ply .gltf .glb, optionally .xz) or a procedural scene (terrain:N,
torus:N, canyon:N); default terrain:512. Memory: slimrt's own count (RaycastingScene.memory(),
the scene without the input copy) and, for both libraries, the growth of the process's resident
size while the scene is built (Open3D reports none of its own). Where Open3D returns no hit at
all (Debian's 0.16.1 build does not, even for a ray straight at a box), the table says so instead
of comparing."""
import argparse
import os
import sys
import time

import numpy as np

try:
    import slimrt
except ImportError:
    sys.exit("slimrt is not importable: build it (cmake) and set PYTHONPATH=build/python")


def rss_bytes():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def make_rays(v, n, seed=1):
    """Rays from a sphere around the mesh towards points inside its box (unnormalized)."""
    rng = np.random.default_rng(seed)
    lo, hi = v.min(0).astype(np.float64), v.max(0).astype(np.float64)
    c, r = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    d = rng.normal(size=(n, 3))
    org = c + d / np.linalg.norm(d, axis=1, keepdims=True) * r * 1.5
    target = lo + rng.random((n, 3)) * (hi - lo)
    return np.concatenate([org, target - org], axis=1).astype(np.float32)


def timed(fn, repeat=3):
    best = np.inf
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def run_open3d(v, t, rays, threads):
    try:
        import open3d as o3d
    except ImportError:
        return None, "Open3D is not installed (Debian: apt-get install python3-open3d)"
    rss0 = rss_bytes()
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(t))
    scene.cast_rays(o3d.core.Tensor(rays[:1]))  # builds the BVH
    rss = rss_bytes() - rss0
    r_t = o3d.core.Tensor(rays)
    res, sec = timed(lambda: scene.cast_rays(r_t, nthreads=threads))
    res = {k: x.numpy() for k, x in res.items()}
    return dict(res=res, rss=rss, mrays=len(rays) / sec * 1e-6, mb=None), None


def run_slimrt(config, v, t, rays, threads):
    rss0 = rss_bytes()
    scene = slimrt.RaycastingScene(config, threads)
    scene.add_triangles(v, t)
    try:
        scene.cast_rays(rays[:1])  # builds the scene
    except slimrt.NotApplicable:
        return None
    rss = rss_bytes() - rss0
    res, sec = timed(lambda: scene.cast_rays(rays, nthreads=threads))
    return dict(res=res, rss=rss, mrays=len(rays) / sec * 1e-6, mb=scene.memory()["total"] / 1e6,
                build=scene.stats()["build_seconds"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("meshes", nargs="*", default=["terrain:512"])
    ap.add_argument("--rays", type=int, default=200_000)
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--configs", default="bvh8-tri4v,clbvh-compact,bvh8-pairs,grid,lossy-grid,"
                                         "lossy-grid-shared,costa-PFV")
    args = ap.parse_args()
    configs = args.configs.split(",")
    print("| mesh | triangles | library / config | hits | same hit as bvh8-tri4v | MB (own) "
          "| RSS growth MB | Mrays/s |")
    print("| --- | ---: | --- | ---: | ---: | ---: | ---: | ---: |")
    for mesh in args.meshes:
        v, t, _ = slimrt.load_triangles(mesh)
        rays = make_rays(v, args.rays)
        name = os.path.basename(mesh)
        rows = []
        o3d, why = run_open3d(v, t, rays, args.threads)
        ref = run_slimrt("bvh8-tri4v", v, t, rays, args.threads)
        ref_hit = np.isfinite(ref["res"]["t_hit"])
        ref_prim = ref["res"]["primitive_ids"]
        if o3d is None:
            rows.append(("Open3D", "-", "-", "-", "-", "-", why))
        else:
            hits = int(np.isfinite(o3d["res"]["t_hit"]).sum())
            agree = "no hits returned: nothing to compare" if hits == 0 else \
                f"{np.mean(o3d['res']['primitive_ids'] == ref_prim):.4f}"
            rows.append(("Open3D", hits, agree, "-", f"{o3d['rss'] / 1e6:.1f}",
                         f"{o3d['mrays']:.2f}", ""))
        for config in configs:
            r = ref if config == "bvh8-tri4v" else run_slimrt(config, v, t, rays, args.threads)
            if r is None:
                rows.append((config, "-", "-", "-", "-", "-", "does not apply"))
                continue
            hit = np.isfinite(r["res"]["t_hit"])
            agree = np.mean((r["res"]["primitive_ids"] == ref_prim) | (~hit & ~ref_hit))
            rows.append((config, int(hit.sum()), f"{agree:.4f}", f"{r['mb']:.1f}",
                         f"{r['rss'] / 1e6:.1f}", f"{r['mrays']:.2f}", ""))
        for lib, hits, agree, mb, rss, mrays, note in rows:
            print(f"| {name} | {len(t)} | {lib}{' (' + note + ')' if note else ''} | {hits} "
                  f"| {agree} | {mb} | {rss} | {mrays} |")
    print(f"\n{args.rays} rays per mesh, best of 3; threads: {args.threads or 'all'} "
          f"({os.cpu_count()} cores); slimrt {slimrt.__version__} ({slimrt.simd_isa()})")


if __name__ == "__main__":
    main()
