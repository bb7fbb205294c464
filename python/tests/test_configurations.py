"""Every registry configuration on every mesh of the shared data folder (../shared/data, listed
in its MANIFEST) against bvh8-tri4v, on sampled rays:
- lossless configurations: the same hits up to geometric ties: a ray may hit another primitive
  only at the same distance (a shared edge or vertex, coincident faces), and hit/miss may differ
  only for the few rays that graze an edge;
- lossy configurations: every hit lies within the scene's error bound (stats()["error_bound"],
  the largest distance between a decoded and an input vertex) of the plane of the face the
  reference hits, when both hit the same face; other differences only for the few rays that pass
  within the error bound of an edge or silhouette.
Configurations with their own geometry (config_info()["own_geometry"]: grids, costa) split quads
and n-gons their own way: for a non-planar or concave polygon that is another surface than the
reference's fan of triangles. So where either hits a polygon of 4+ corners: when both hit the
same polygon, the hit lies within the error bound (0 when lossless) plus the polygon's own
deviation from the plane the reference hits (the largest distance of its corners from that plane,
which bounds any split of it) of that plane; another polygon or hit/miss may differ for at most 3%
of the rays (at most 1.8% do on these meshes). Hits on triangles are checked as above.
Triangle meshes above CROP triangles are cut to the CROP triangles nearest a point on them (so
that the whole registry runs in well under two minutes); polygon meshes are used whole.
Without the data folder the test skips and says where it looked; SLIM_REQUIRE_DATA=1 makes that
a failure."""
import os
import re

import numpy as np
import pytest

from conftest import SHARED_DATA, data_required, import_slimrt, random_rays

slimrt = import_slimrt()

REFERENCE = "bvh8-tri4v"
CROP = 40000   # triangles kept of the larger triangle meshes
RAYS = 3000    # sampled rays per mesh


def manifest_meshes():
    path = os.path.join(SHARED_DATA, "MANIFEST")
    if not os.path.exists(path):
        return []
    names = []
    for line in open(path, encoding="utf-8"):
        m = re.match(r"^(\S+\.(?:obj|ply|gltf|glb)(?:\.xz)?) \|", line)
        if m:
            names.append(m.group(1))
    return names


MESHES = manifest_meshes()


def require_data():
    if MESHES and all(os.path.exists(os.path.join(SHARED_DATA, n)) for n in MESHES):
        return
    why = (f"the shared meshes are missing: no MANIFEST or mesh files in {SHARED_DATA} "
           "(set SLIMRT_SHARED_DATA to the data folder)")
    if data_required():
        pytest.fail(why + "; SLIM_REQUIRE_DATA=1 requires them")
    pytest.skip(why)


def test_the_data_folder_is_there():
    require_data()
    assert len(MESHES) >= 11, MESHES


def geometry(name):
    """(add(scene), lo, hi, triangles, polygons): how to add the mesh, its box, its triangle
    count and, for a mesh with polygons, (polygon, corners): per primitive id (face) whether it
    has 4+ corners, and corners(faces) -> [len(faces), k, 3] float64, each face's corners (the
    first repeated to pad to the largest k)."""
    path = os.path.join(SHARED_DATA, name)
    mesh = slimrt.Mesh(path)
    if mesh.face_count == mesh.triangle_count and mesh.triangle_count > CROP:
        # A triangle mesh: the CROP triangles nearest a vertex, vertices renumbered.
        v, t, _ = slimrt.load_triangles(path)
        c = v[t].mean(axis=1)
        seed = c[len(c) // 3]
        keep = np.argpartition(np.linalg.norm(c - seed, axis=1), CROP)[:CROP]
        used, t2 = np.unique(t[keep], return_inverse=True)
        v2 = np.ascontiguousarray(v[used])
        t2 = t2.reshape(-1, 3).astype(np.uint32)
        return (lambda s: s.add_triangles(v2, t2)), v2.min(0), v2.max(0), len(t2), None
    v, t, face = slimrt.load_triangles(path)
    fans = np.bincount(face, minlength=mesh.face_count)  # fan triangles per face
    start = np.searchsorted(face, np.arange(mesh.face_count))  # fans are in face order
    v64 = v.astype(np.float64)

    def corners(faces):
        k = fans[faces]
        j = np.arange(max(int(k.max()), 1))[None, :]
        tri = np.where(j < k[:, None], start[faces][:, None] + j, start[faces][:, None])
        return v64[t[tri]].reshape(len(faces), -1, 3)  # every fan triangle's corners
    polygons = (fans > 1, corners) if (fans > 1).any() else None
    return (lambda s: s.add_mesh(mesh)), v.min(0), v.max(0), mesh.triangle_count, polygons


def compare(config, ref, r, rays, diag, error_bound, lossy, polygons):
    """The failures of one configuration's hits against the reference's (empty: agrees)."""
    bad = []
    n = len(rays)
    if slimrt.config_info(config)["own_geometry"] and polygons is not None:
        polygon, corners = polygons
        def on_polygon(x):
            ok = np.isfinite(x["t_hit"])
            p = np.zeros(n, bool)
            p[ok] = polygon[x["primitive_ids"][ok]]
            return p
        exempt = on_polygon(ref) | on_polygon(r)
        agree = (r["primitive_ids"] == ref["primitive_ids"]) & \
            (np.isfinite(r["t_hit"]) == np.isfinite(ref["t_hit"]))
        if (exempt & ~agree).sum() > 0.03 * n:
            bad.append(f"{(exempt & ~agree).sum()} of {n} rays through polygons differ")
        # The same polygon hit: within the error bound plus the polygon's deviation from the
        # plane the reference hits.
        same = exempt & agree & np.isfinite(ref["t_hit"])
        if same.any():
            d = rays[same, 3:].astype(np.float64)
            pr = rays[same, :3] + ref["t_hit"][same, None].astype(np.float64) * d
            pc = rays[same, :3] + r["t_hit"][same, None].astype(np.float64) * d
            nr = ref["primitive_normals"][same].astype(np.float64)
            c = corners(ref["primitive_ids"][same])
            flat = np.abs(np.einsum("rkj,rj->rk", c - pr[:, None, :], nr)).max(axis=1)
            off = np.abs(np.einsum("ij,ij->i", pc - pr, nr))
            allowed = error_bound + flat + 1e-6 * diag
            if (off > allowed).any():
                i = np.argmax(off - allowed)
                bad.append(f"{(off > allowed).sum()} hits on a polygon farther from the "
                           f"reference's plane than the error bound {error_bound:.3g} plus the "
                           f"polygon's deviation {flat[i]:.3g} (by {off[i] - allowed[i]:.3g})")
        keep = ~exempt
        rays = rays[keep]
        ref = {k: a[keep] for k, a in ref.items()}
        r = {k: a[keep] for k, a in r.items()}
    d = rays[:, 3:].astype(np.float64)
    dlen = np.linalg.norm(d, axis=1)
    hr, hc = np.isfinite(ref["t_hit"]), np.isfinite(r["t_hit"])
    both = hr & hc
    tr = ref["t_hit"].astype(np.float64)
    tc = r["t_hit"].astype(np.float64)
    same = both & (r["primitive_ids"] == ref["primitive_ids"]) & \
        (r["geometry_ids"] == ref["geometry_ids"])
    # Distances along the ray in scene units; ties within float rounding of the scene's size.
    slack = 1e-6 * diag
    dist = np.abs(tc - tr) * dlen
    if not lossy:
        # Geometric ties: another primitive hit at the same distance.
        other = both & ~same
        not_tie = other & (dist > slack + 1e-6 * tr * dlen)
        if not_tie.any():
            i = np.flatnonzero(not_tie)[0]
            bad.append(f"{not_tie.sum()} rays hit another primitive at another distance "
                       f"(ray {i}: {r['primitive_ids'][i]} at {tc[i]} vs "
                       f"{ref['primitive_ids'][i]} at {tr[i]})")
        far = same & (dist > slack + 1e-6 * tr * dlen)
        if far.any():
            bad.append(f"{far.sum()} rays hit the same primitive at another distance "
                       f"(largest {dist[far].max():.3g})")
        if (hr != hc).sum() > max(2, n // 1000):  # edge-grazing rays
            bad.append(f"{(hr != hc).sum()} of {n} rays differ in hit/miss")
    else:
        # The hit point within the error bound of the plane of the face the reference hits.
        pr = rays[:, :3] + tr[:, None] * d
        pc = rays[:, :3] + tc[:, None] * d
        nr = ref["primitive_normals"].astype(np.float64)
        off = np.abs(np.einsum("ij,ij->i", pc - pr, nr))
        out = same & (off > error_bound + slack)
        if out.any():
            bad.append(f"{out.sum()} hits farther than the error bound {error_bound:.3g} from "
                       f"the reference face's plane (largest {off[out].max():.3g})")
        # Elsewhere (another face hit, hit/miss differs): only near edges and silhouettes.
        differ = (hr != hc) | (both & ~same)
        if differ.sum() > max(3, n // 200):
            bad.append(f"{differ.sum()} of {n} rays hit another face or differ in hit/miss")
    return bad


@pytest.mark.parametrize("mesh", MESHES or ["(no MANIFEST)"])
def test_every_configuration_agrees_with_the_reference(mesh):
    require_data()
    add, lo, hi, triangles, polygons = geometry(mesh)
    diag = float(np.linalg.norm(hi.astype(np.float64) - lo))
    rays = random_rays(np.random.default_rng(11), lo, hi, RAYS)
    s = slimrt.RaycastingScene(REFERENCE)
    add(s)
    ref = s.cast_rays(rays)
    assert np.isfinite(ref["t_hit"]).sum() >= RAYS // 10, "too few rays hit the mesh"
    failures, ran, not_applicable = [], [], []
    for config in slimrt.configs():
        if config == REFERENCE:
            continue
        s = slimrt.RaycastingScene(config)
        add(s)
        try:
            st = s.stats()
        except slimrt.NotApplicable as e:
            not_applicable.append(f"{config}: {e}")
            continue
        r = s.cast_rays(rays)
        lossy = bool(st["lossy"])
        assert lossy == slimrt.config_info(config)["lossy"], config
        if not lossy:
            assert st["error_bound"] == 0, config
        with np.errstate(invalid="ignore"):  # inf - inf on misses, masked out
            found = compare(config, ref, r, rays, diag, st["error_bound"], lossy, polygons)
        failures += [f"{config}: {b}" for b in found]
        ran.append(config)
    assert not failures, f"{mesh} ({triangles} triangles):\n" + "\n".join(failures)
    # Every configuration runs on these meshes; one that cannot says why.
    assert not not_applicable, not_applicable
    assert len(ran) == len(slimrt.configs()) - 1
