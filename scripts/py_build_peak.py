#!/usr/bin/python3
"""Peak memory of building a large triangle mesh from numpy arrays through the Python module.

  /usr/bin/time -v /usr/bin/python3 scripts/py_build_peak.py [--n N] [--config NAME]

Makes an N x N heightfield of 2 N^2 triangles as float32 vertices and uint32 triangles (the
arrays add_triangles references without copying), builds the scene with one query, and prints
the resident size before the build, the peak (ru_maxrss, which /usr/bin/time also reports as
"Maximum resident set size") and the scene's memory(). Needs PYTHONPATH=build/python.
"""
import argparse
import resource
import time

import numpy as np

import slimrt


def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=2829, help="quads per side (2 n^2 triangles)")
    ap.add_argument("--config", default="bvh8-tri4v")
    a = ap.parse_args()
    n = a.n
    x, y = np.meshgrid(np.arange(n + 1, dtype=np.float32), np.arange(n + 1, dtype=np.float32))
    z = (np.sin(x * 0.05) * np.cos(y * 0.07) * 20.0).astype(np.float32)
    vertices = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    del x, y, z
    i = np.arange(n, dtype=np.uint32)
    a0 = (i[None, :] + (n + 1) * i[:, None]).ravel()
    triangles = np.empty((2 * n * n, 3), dtype=np.uint32)
    triangles[0::2, 0] = a0
    triangles[0::2, 1] = a0 + 1
    triangles[0::2, 2] = a0 + n + 2
    triangles[1::2, 0] = a0
    triangles[1::2, 1] = a0 + n + 2
    triangles[1::2, 2] = a0 + n + 1
    del a0, i
    arrays_mb = (vertices.nbytes + triangles.nbytes) / 2**20

    scene = slimrt.RaycastingScene(config=a.config)
    scene.add_triangles(vertices, triangles)
    before = rss_mb()
    t0 = time.perf_counter()
    hit = scene.cast_rays(np.array([[n / 2, n / 2, 100.0, 0, 0, -1]], dtype=np.float32))
    build_s = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    mem = scene.memory()
    print(f"config {a.config}: {len(triangles)} triangles, {len(vertices)} vertices, "
          f"arrays {arrays_mb:.0f} MB")
    print(f"rss before build {before:.0f} MB, peak {peak:.0f} MB, after {rss_mb():.0f} MB, "
          f"build+1 ray {build_s:.1f} s, hit t={float(hit['t_hit'][0]):.3f}")
    print("memory():", {k: v for k, v in mem.items()})


if __name__ == "__main__":
    main()
