"""Shared helpers of the slimrt Python tests: the module from the build tree, the meshes of
../shared/data and a double-precision numpy brute force to check hits against."""
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BUILD = os.environ.get("SLIMRT_BUILD_DIR", os.path.join(ROOT, "build"))
if os.path.isdir(os.path.join(BUILD, "python")):
    sys.path.insert(0, os.path.join(BUILD, "python"))
# The real meshes (MANIFEST there), beside the repository; tests that need them skip without,
# or fail when SLIM_REQUIRE_DATA is set (see data_required()).
SHARED_DATA = os.environ.get("SLIMRT_SHARED_DATA", os.path.join(ROOT, "..", "shared", "data"))


def data_required():
    """SLIM_REQUIRE_DATA=1 (set by .ci/run): a test that needs ../shared/data fails instead of
    skipping when the data (or one of its files) is missing, as the C++ tests do
    (tests/test_util.h), so the real-mesh evidence cannot vanish from CI while pytest stays
    green."""
    e = os.environ.get("SLIM_REQUIRE_DATA", "")
    return e not in ("", "0")


def import_slimrt():
    try:
        import slimrt  # noqa: F401
    except ImportError as e:
        pytest.skip(f"the slimrt module is not built ({e}); build it with cmake "
                    f"(pybind11-dev, python3-numpy, python3-dev) into {BUILD}/python")
    return slimrt


def is_lossy(config):
    """Formats whose decoded positions may differ from the input (the registry's row)."""
    return import_slimrt().config_info(config)["lossy"]


def brute_force(vertices, triangles, rays, tnear=0.0, tfar=np.inf, edge_eps=1e-6):
    """Closest hits in double precision (Moller-Trumbore, both sides) of every ray against every
    triangle. Returns t (inf on a miss), the triangle index (-1 on a miss), the barycentric u, v
    of the hit, and `ambiguous`: rays for which a float tracer may legitimately differ: a
    candidate hit within edge_eps of a triangle's edge (the ray grazes an edge or a vertex) or a
    second triangle within a relative 1e-5 of the closest t (a tie)."""
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    r = np.asarray(rays, np.float64).reshape(-1, 6)
    p0, p1, p2 = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    n = len(r)
    best_t = np.full(n, np.inf)
    best_i = np.full(n, -1, np.int64)
    best_u = np.zeros(n)
    best_v = np.zeros(n)
    ambiguous = np.zeros(n, bool)
    second_t = np.full(n, np.inf)
    chunk = max(1, 4_000_000 // max(len(tri), 1))
    for b in range(0, n, chunk):
        o = r[b:b + chunk, None, :3]
        d = r[b:b + chunk, None, 3:]
        pvec = np.cross(d, e2[None])
        det = np.einsum("rtk,tk->rt", pvec, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            tvec = o - p0[None]
            u = np.einsum("rtk,rtk->rt", tvec, pvec) * inv
            qvec = np.cross(tvec, e1[None])
            w = np.einsum("rtk,rtk->rt", d, qvec) * inv
            t = np.einsum("rtk,tk->rt", qvec, e2) * inv
            valid = (det != 0) & np.isfinite(t) & (t >= tnear) & (t <= tfar)
            inside = valid & (u >= 0) & (w >= 0) & (u + w <= 1)
            near_edge = valid & (u >= -edge_eps) & (w >= -edge_eps) & \
                (u + w <= 1 + edge_eps) & ((np.abs(u) <= edge_eps) | (np.abs(w) <= edge_eps) |
                                           (np.abs(1 - u - w) <= edge_eps))
        tt = np.where(inside, t, np.inf)
        i = np.argmin(tt, axis=1)
        rows = np.arange(len(i))
        bt = tt[rows, i]
        tt2 = tt.copy()
        tt2[rows, i] = np.inf
        best_t[b:b + chunk] = bt
        second_t[b:b + chunk] = tt2.min(axis=1)
        hit = np.isfinite(bt)
        best_i[b:b + chunk] = np.where(hit, i, -1)
        best_u[b:b + chunk] = np.where(hit, u[rows, i], 0)
        best_v[b:b + chunk] = np.where(hit, w[rows, i], 0)
        # An edge-grazing candidate no farther than the closest hit can change the answer.
        graze_t = np.where(near_edge, t, np.inf).min(axis=1)
        ambiguous[b:b + chunk] = np.isfinite(graze_t) & \
            (graze_t <= np.where(hit, bt * (1 + 1e-5) + 1e-30, np.inf))
    tie = np.isfinite(best_t) & (second_t <= best_t * (1 + 1e-5) + 1e-30)
    return best_t, best_i, best_u, best_v, ambiguous | tie


def brute_force_counts(vertices, triangles, rays, rel=1e-6):
    """Number of distinct hit distances per ray (t >= 0) in double precision, hits within a
    relative `rel` of each other counting once, and rays with an edge-grazing candidate."""
    v = np.asarray(vertices, np.float64)
    tri = np.asarray(triangles, np.int64)
    r = np.asarray(rays, np.float64).reshape(-1, 6)
    p0, p1, p2 = v[tri[:, 0]], v[tri[:, 1]], v[tri[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    o, d = r[:, None, :3], r[:, None, 3:]
    pvec = np.cross(d, e2[None])
    det = np.einsum("rtk,tk->rt", pvec, e1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        tvec = o - p0[None]
        u = np.einsum("rtk,rtk->rt", tvec, pvec) * inv
        qvec = np.cross(tvec, e1[None])
        w = np.einsum("rtk,rtk->rt", d, qvec) * inv
        t = np.einsum("rtk,tk->rt", qvec, e2) * inv
        eps = 1e-6
        valid = (det != 0) & np.isfinite(t) & (t >= 0)
        inside = valid & (u >= 0) & (w >= 0) & (u + w <= 1)
        grazing = valid & (u >= -eps) & (w >= -eps) & (u + w <= 1 + eps) & \
            ((np.abs(u) <= eps) | (np.abs(w) <= eps) | (np.abs(1 - u - w) <= eps))
    counts = np.zeros(len(r), np.int64)
    for k in range(len(r)):
        ts = np.sort(t[k][inside[k]])
        if len(ts):
            counts[k] = 1 + int(np.sum(np.diff(ts) > rel * np.maximum(ts[1:], 1e-30)))
    return counts, grazing.any(axis=1)


def icosphere(subdiv=2, radius=1.0, center=(0.0, 0.0, 0.0)):
    """A closed triangle mesh (vertices float32 [N,3], triangles uint32 [M,3])."""
    t = (1 + 5 ** 0.5) / 2
    verts = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
             (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
             (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8),
             (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.array(p, float) / np.linalg.norm(p) for p in verts]
    for _ in range(subdiv):
        cache = {}
        new_faces = []

        def mid(a, b):
            key = (min(a, b), max(a, b))
            if key not in cache:
                m = verts[a] + verts[b]
                verts.append(m / np.linalg.norm(m))
                cache[key] = len(verts) - 1
            return cache[key]
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    v = np.array(verts) * radius + np.array(center)
    return v.astype(np.float32), np.array(faces, np.uint32)


def random_rays(rng, lo, hi, n, origin_scale=2.0):
    """Rays from points around the box [lo, hi] towards points inside it (unnormalized)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, ext = (lo + hi) / 2, (hi - lo) / 2 + 1e-9
    org = c + (rng.random((n, 3)) * 2 - 1) * ext * origin_scale
    target = c + (rng.random((n, 3)) * 2 - 1) * ext
    d = (target - org) * rng.uniform(0.5, 2.0, (n, 1))
    return np.concatenate([org, d], axis=1).astype(np.float32)


def shared_mesh(name):
    path = os.path.join(SHARED_DATA, name)
    missing = None
    if not os.path.exists(os.path.join(SHARED_DATA, "MANIFEST")):
        missing = f"{SHARED_DATA}/MANIFEST is missing (the real meshes live in ../shared/data)"
    elif not os.path.exists(path):
        missing = f"{path} is missing (a file of ../shared/data)"
    if missing:
        if data_required():
            pytest.fail(f"{missing} (SLIM_REQUIRE_DATA is set: missing data fails)")
        pytest.skip(missing)
    return path
