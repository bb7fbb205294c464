// Shared test helpers: random scenes, a double-precision brute-force reference, data paths.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "slimrt/analysis.h"

namespace slim::test {

inline std::string shared_data_dir() { return SLIM_SHARED_DATA; }
inline bool have_shared_data() { return std::filesystem::exists(shared_data_dir() + "/MANIFEST"); }
#define SLIM_REQUIRE_SHARED_DATA()                                                    \
  do {                                                                                \
    if (!slim::test::have_shared_data())                                              \
      GTEST_SKIP() << "../shared/data not found at " << slim::test::shared_data_dir() \
                   << ": skipping a test that needs the shared meshes";               \
  } while (0)

// Random triangles inside the unit cube (sizes around `size`), as a PolyMesh of triangles.
inline PolyMesh random_soup(uint32_t tris, uint32_t seed, float size = 0.05f) {
  Rng rng(seed, 7);
  PolyMesh m;
  m.name = "soup";
  for (uint32_t i = 0; i < tris; ++i) {
    Vec3f c(rng.uniform(), rng.uniform(), rng.uniform());
    for (int k = 0; k < 3; ++k) {
      Vec3f d(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
      m.positions.push_back(c + d * size);
      m.face_indices.push_back(3 * i + k);
    }
    m.face_sizes.push_back(3);
  }
  return m;
}

// Fan-triangulated triangles of the mesh in double precision, with the face they come from.
struct RefTri {
  double v[3][3];
  uint32_t geom, prim;
};
inline std::vector<RefTri> reference_triangles(const std::vector<const PolyMesh*>& meshes) {
  std::vector<RefTri> out;
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    const PolyMesh& m = *meshes[g];
    uint64_t c = 0;
    for (uint32_t f = 0; f < m.face_sizes.size(); ++f) {
      uint32_t n = m.face_sizes[f];
      bool ok = true;
      for (uint32_t k = 0; k < n; ++k) ok = ok && is_finite(m.positions[m.face_indices[c + k]]);
      for (uint32_t k = 1; ok && k + 1 < n; ++k) {
        RefTri t;
        uint32_t idx[3] = {m.face_indices[c], m.face_indices[c + k], m.face_indices[c + k + 1]};
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) t.v[j][a] = m.positions[idx[j]][a];
        t.geom = g;
        t.prim = f;
        out.push_back(t);
      }
      c += n;
    }
  }
  return out;
}

struct RefHit {
  double t = INFINITY;
  uint32_t geom = kInvalidID, prim = kInvalidID;
  bool valid() const { return geom != kInvalidID; }
};

// Double-precision ray/triangle (Moller-Trumbore, edges inclusive); brute force over all.
inline RefHit reference_intersect(const std::vector<RefTri>& tris, const Ray& r) {
  RefHit best;
  double o[3] = {r.org.x, r.org.y, r.org.z}, d[3] = {r.dir.x, r.dir.y, r.dir.z};
  for (const RefTri& t : tris) {
    double e1[3], e2[3], s[3];
    for (int a = 0; a < 3; ++a) {
      e1[a] = t.v[1][a] - t.v[0][a];
      e2[a] = t.v[2][a] - t.v[0][a];
      s[a] = o[a] - t.v[0][a];
    }
    double p[3] = {d[1] * e2[2] - d[2] * e2[1], d[2] * e2[0] - d[0] * e2[2],
                   d[0] * e2[1] - d[1] * e2[0]};
    double det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    if (det == 0) continue;
    double inv = 1.0 / det;
    double u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
    if (u < 0 || u > 1) continue;
    double q[3] = {s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2],
                   s[0] * e1[1] - s[1] * e1[0]};
    double v = (d[0] * q[0] + d[1] * q[1] + d[2] * q[2]) * inv;
    if (v < 0 || u + v > 1) continue;
    double tt = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
    if (tt > r.tnear && tt <= r.tfar && tt < best.t) {
      best.t = tt;
      best.geom = t.geom;
      best.prim = t.prim;
    }
  }
  return best;
}

// Random ray from a point around the box towards a point inside it.
inline Ray random_ray(Rng& rng, const Box3f& box) {
  Vec3f c = box.center(), s = box.size();
  float r = 1.5f * reduce_max(s);
  Vec3f o(c.x + (rng.uniform() - 0.5f) * 2 * r, c.y + (rng.uniform() - 0.5f) * 2 * r,
          c.z + (rng.uniform() - 0.5f) * 2 * r);
  Vec3f target(box.lo.x + rng.uniform() * s.x, box.lo.y + rng.uniform() * s.y,
               box.lo.z + rng.uniform() * s.z);
  Ray ray;
  ray.org = o;
  ray.dir = normalize(target - o);
  return ray;
}

// Hit agreement as BENCHMARK.md defines it: both miss, or both hit with t equal within rel_tol
// (same face, or a tie at a shared edge/vertex).
inline bool agrees(const Hit& h, const RefHit& r, double rel_tol = 1e-5) {
  if (!h.valid() || !r.valid()) return h.valid() == r.valid();
  return std::fabs(double(h.t) - r.t) <= rel_tol * std::max(1.0, std::fabs(r.t));
}

// Counts of compare_with_reference().
struct Agreement {
  uint64_t rays = 0, agree = 0, same_face = 0, hits = 0;
};

// `nrays` random rays through the scene box: closest hits against the brute-force reference over
// `meshes` (agreement counted; same input face as `same_face(hit, ref)` says when both hit), and
// occluded() == (closest hit exists).
template <class SameFace>
Agreement compare_with_reference(const Scene& scene, const std::vector<const PolyMesh*>& meshes,
                                 int nrays, uint32_t seed, SameFace&& same_face) {
  std::vector<RefTri> ref = reference_triangles(meshes);
  Rng rng(seed);
  Agreement a;
  for (int i = 0; i < nrays; ++i) {
    Ray r = random_ray(rng, scene.bounds());
    Hit h = scene.intersect(r);
    RefHit rh = reference_intersect(ref, r);
    a.rays++;
    a.hits += rh.valid();
    a.agree += agrees(h, rh);
    a.same_face += h.valid() && rh.valid() && same_face(h, rh);
    EXPECT_EQ(scene.occluded(r), h.valid());
  }
  return a;
}

// The same, the reference's face being the input face.
inline Agreement compare_with_reference(const Scene& scene,
                                        const std::vector<const PolyMesh*>& meshes, int nrays,
                                        uint32_t seed) {
  return compare_with_reference(scene, meshes, nrays, seed, [](const Hit& h, const RefHit& rh) {
    return h.primID == rh.prim && h.geomID == rh.geom;
  });
}

// Icosahedron subdivided `levels` times (20 * 4^levels triangles), vertices on the unit sphere;
// closed and welded (the sphere of `slimrt verify sphere:L`, without its jitter).
inline PolyMesh icosphere(int levels) {
  PolyMesh m = make_sphere(levels);
  m.name = "sphere";
  return m;
}

}  // namespace slim::test
