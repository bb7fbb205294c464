// Shared test helpers: random scenes, a double-precision brute-force reference, data paths.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "slimrt/analysis.h"

namespace slim::test {

// The message of the slim::Error fn throws, "" when it throws none.
template <class Fn>
std::string error_of(Fn&& fn) {
  try {
    fn();
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// slim::stat_detail's value (slimrt/analysis.h); a test failure, and -1, when the scene has no
// such detail.
inline double detail_value(const Scene& s, std::string_view key) {
  if (const std::optional<double> v = stat_detail(s, key)) return *v;
  ADD_FAILURE() << "no detail " << key;
  return -1;
}

inline std::string shared_data_dir() { return SLIM_SHARED_DATA; }
inline bool have_shared_data() { return std::filesystem::exists(shared_data_dir() + "/MANIFEST"); }
// SLIM_REQUIRE_DATA=1 (set by .ci/run): a test that needs ../shared/data fails instead of
// skipping when the data (or one of its files) is missing, so real-mesh evidence cannot vanish
// from CI while ctest stays green.
inline bool data_required() {
  const char* e = std::getenv("SLIM_REQUIRE_DATA");
  return e && *e && std::string(e) != "0";
}
#define SLIM_MISSING_DATA(what)                                                  \
  do {                                                                           \
    if (slim::test::data_required())                                             \
      GTEST_FAIL() << what << " (SLIM_REQUIRE_DATA is set: missing data fails)"; \
    GTEST_SKIP() << what;                                                        \
  } while (0)
#define SLIM_REQUIRE_SHARED_DATA()                                   \
  do {                                                               \
    if (!slim::test::have_shared_data())                             \
      SLIM_MISSING_DATA("../shared/data not found at "               \
                        << slim::test::shared_data_dir()             \
                        << ": a test that needs the shared meshes"); \
  } while (0)
// The same for one file of ../shared/data (a full path).
#define SLIM_REQUIRE_SHARED_FILE(path)                                                       \
  do {                                                                                       \
    SLIM_REQUIRE_SHARED_DATA();                                                              \
    if (!std::filesystem::exists(path)) SLIM_MISSING_DATA("missing shared file " << (path)); \
  } while (0)

// ---- configuration properties (the registry of slimrt/scene.h) ----

// The build says "this configuration does not apply to this mesh". Any other error is a failure,
// never a skip.
inline bool not_applicable(const Error& e) {
  return dynamic_cast<const NotApplicable*>(&e) != nullptr;
}
// Lossy: the format moves vertices (lossy-grid*, costa-*V*). Its hits are held to the bound its
// specification promises (test_lossy_accuracy.cpp).
inline bool is_lossy_config(const std::string& c) { return config_info(c).lossy; }

// The box diagonal in doubles, as cluster::quantize takes it (the cluster error bound's scale).
inline double diagonal(const Box3f& b) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double e = double(b.hi[a]) - double(b.lo[a]);
    d2 += e * e;
  }
  return std::sqrt(d2);
}
// Own geometry: the format intersects triangles of its own (decoded_triangles()), not the input's
// fan triangles.
inline bool has_own_geometry(const std::string& c) { return config_info(c).own_geometry; }

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
  uint32_t tri = kInvalidID;  // index of the hit triangle in the reference's triangles
  bool valid() const { return geom != kInvalidID; }
};

// Double-precision ray/triangle (Moller-Trumbore, edges inclusive); brute force over all.
inline RefHit reference_intersect(const std::vector<RefTri>& tris, const Ray& r) {
  RefHit best;
  double o[3] = {r.org.x, r.org.y, r.org.z}, d[3] = {r.dir.x, r.dir.y, r.dir.z};
  for (uint32_t ti = 0; ti < tris.size(); ++ti) {
    const RefTri& t = tris[ti];
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
      best.tri = ti;
    }
  }
  return best;
}

// ---- point/triangle distances in double (Ericson, "Real-Time Collision Detection", 5.1.5) ----

inline double dist3(const double a[3], const double b[3]) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                   (a[2] - b[2]) * (a[2] - b[2]));
}

// Distance from p to the segment ab.
inline double segment_distance(const double p[3], const double a[3], const double b[3]) {
  double ab[3], ap[3];
  for (int k = 0; k < 3; ++k) ab[k] = b[k] - a[k], ap[k] = p[k] - a[k];
  const double l2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
  double s = l2 > 0 ? (ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / l2 : 0.0;
  s = std::clamp(s, 0.0, 1.0);
  const double q[3] = {a[0] + s * ab[0], a[1] + s * ab[1], a[2] + s * ab[2]};
  return dist3(p, q);
}

// Distance from p to the boundary (the 3 edges) of t.
inline double boundary_distance(const RefTri& t, const double p[3]) {
  return std::min({segment_distance(p, t.v[0], t.v[1]), segment_distance(p, t.v[1], t.v[2]),
                   segment_distance(p, t.v[2], t.v[0])});
}

// Distance from p to the (closed) triangle t: to its plane when p projects inside it, else to its
// boundary. Degenerate triangles: to the boundary.
inline double triangle_distance(const RefTri& t, const double p[3]) {
  double e1[3], e2[3], w[3];
  for (int k = 0; k < 3; ++k)
    e1[k] = t.v[1][k] - t.v[0][k], e2[k] = t.v[2][k] - t.v[0][k], w[k] = p[k] - t.v[0][k];
  const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                       e1[0] * e2[1] - e1[1] * e2[0]};
  const double n2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  const double b = boundary_distance(t, p);
  if (!(n2 > 0)) return b;
  // Barycentric coordinates of the projection of p.
  const double d11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
  const double d12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2];
  const double d22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
  const double w1 = w[0] * e1[0] + w[1] * e1[1] + w[2] * e1[2];
  const double w2 = w[0] * e2[0] + w[1] * e2[1] + w[2] * e2[2];
  const double den = d11 * d22 - d12 * d12;
  const double u = (d22 * w1 - d12 * w2) / den, v = (d11 * w2 - d12 * w1) / den;
  if (u >= 0 && v >= 0 && u + v <= 1)
    return std::fabs(w[0] * n[0] + w[1] * n[1] + w[2] * n[2]) / std::sqrt(n2);
  return b;
}

// Distance from p to the nearest of `tris` (brute force).
inline double surface_distance(const std::vector<RefTri>& tris, const double p[3]) {
  double d = INFINITY;
  for (const RefTri& t : tris) d = std::min(d, triangle_distance(t, p));
  return d;
}

// The smallest distance from p to the boundary of one of the triangles of the face (geom, prim);
// INFINITY when no triangle of `tris` stands for the face.
inline double face_boundary_distance(const std::vector<RefTri>& tris, uint32_t geom, uint32_t prim,
                                     const double p[3]) {
  double d = INFINITY;
  for (const RefTri& t : tris)
    if (t.geom == geom && t.prim == prim) d = std::min(d, boundary_distance(t, p));
  return d;
}

// The point org + t * dir in double.
inline void point_on_ray(const Ray& r, double t, double p[3]) {
  for (int k = 0; k < 3; ++k) p[k] = double(r.org[k]) + t * double(r.dir[k]);
}

// A tie, checked geometrically: the reference hit point p (face A = ref) lies within `delta` of
// the boundary of one of A's triangles and within `delta` of face B (the one slimrt reported), so
// the ray passes through (or within rounding of) an edge or vertex both faces share, or through
// coincident faces. `delta` is in scene units.
enum class TieKind { None, Edge, Coincident };
// Classifies a hit on face B where the reference hit face A at p: Edge when p lies within `delta`
// of the boundary of one of A's triangles and within `delta` of B (a shared edge or vertex);
// Coincident when p lies within `delta` of B but away from A's boundary (coincident or crossing
// faces); None otherwise (B does not pass through p: a wrong face).
inline TieKind geometric_tie(const std::vector<RefTri>& tris, const Ray& r, const RefHit& ref,
                             uint32_t geom_b, uint32_t prim_b, double delta) {
  double p[3];
  point_on_ray(r, ref.t, p);
  double da = INFINITY, db = INFINITY;
  for (const RefTri& t : tris) {
    if (t.geom == ref.geom && t.prim == ref.prim) da = std::min(da, boundary_distance(t, p));
    if (t.geom == geom_b && t.prim == prim_b) db = std::min(db, triangle_distance(t, p));
  }
  if (db > delta) return TieKind::None;
  return da <= delta ? TieKind::Edge : TieKind::Coincident;
}
inline bool is_geometric_tie(const std::vector<RefTri>& tris, const Ray& r, const RefHit& ref,
                             uint32_t geom_b, uint32_t prim_b, double delta) {
  return geometric_tie(tris, r, ref, geom_b, prim_b, delta) == TieKind::Edge;
}

// The same over decoded triangles that stand for input faces (formats with their own geometry):
// `input_of(tri)` is the input (geom, face) of a reference triangle; face A is the input face of
// the reference hit's triangle, face B = (geom_b, prim_b) the one slimrt reported.
template <class InputOf>
TieKind input_face_tie(const std::vector<RefTri>& tris, const Ray& r, const RefHit& ref,
                       InputOf&& input_of, uint32_t geom_b, uint32_t prim_b, double delta) {
  double p[3];
  point_on_ray(r, ref.t, p);
  const std::pair<uint32_t, uint32_t> a = input_of(tris[ref.tri]), b = {geom_b, prim_b};
  double da = INFINITY, db = INFINITY;
  for (const RefTri& t : tris) {
    const std::pair<uint32_t, uint32_t> f = input_of(t);
    if (f == a) da = std::min(da, boundary_distance(t, p));
    if (f == b) db = std::min(db, triangle_distance(t, p));
  }
  if (db > delta) return TieKind::None;
  return da <= delta ? TieKind::Edge : TieKind::Coincident;
}

// The tie distance for a hit at p seen from org: a few float roundings of the coordinates the
// watertight test works with (relative to the origin and to the scene's origin).
inline double tie_delta(const Ray& r, double t) {
  double p[3];
  point_on_ray(r, t, p);
  const double o[3] = {r.org.x, r.org.y, r.org.z}, zero[3] = {0, 0, 0};
  return 1e-6 * std::max(dist3(p, o), dist3(p, zero));
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

// Hit agreement as docs/benchmark.md defines it: both miss, or both hit with t equal within rel_tol
// (same face, or a tie at a shared edge/vertex).
inline bool agrees(const Hit& h, const RefHit& r, double rel_tol = 1e-5) {
  if (!h.valid() || !r.valid()) return h.valid() == r.valid();
  return std::fabs(double(h.t) - r.t) <= rel_tol * std::max(1.0, std::fabs(r.t));
}

// Counts of compare_with_reference().
struct Agreement {
  uint64_t rays = 0, agree = 0, same_face = 0, hits = 0;
  // Hits on another face than the reference's that is_geometric_tie() confirms (the default
  // same-face test only), and hits on another face that it does not (listed in `wrong`).
  uint64_t ties = 0, wrong_face = 0;
  std::string wrong;
};

// `nrays` random rays through the scene box: closest hits against the brute-force reference over
// `meshes` (agreement counted; same input face as `same_face(hit, ref)` says when both hit), and
// occluded() == (closest hit exists). check_ties: hits on another face are checked with
// is_geometric_tie() (needs Hit::primID/geomID to name the reference's faces).
template <class SameFace>
Agreement compare_with_reference(const Scene& scene, const std::vector<const PolyMesh*>& meshes,
                                 int nrays, uint32_t seed, SameFace&& same_face,
                                 bool check_ties = false) {
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
    const bool same = h.valid() && rh.valid() && same_face(h, rh);
    a.same_face += same;
    if (check_ties && h.valid() && rh.valid() && !same) {
      if (is_geometric_tie(ref, r, rh, h.geomID, h.primID, tie_delta(r, rh.t))) {
        a.ties++;
      } else if (++a.wrong_face <= 5) {
        a.wrong += " ray " + std::to_string(i) + ": face " + std::to_string(h.geomID) + "/" +
                   std::to_string(h.primID) + " instead of " + std::to_string(rh.geom) + "/" +
                   std::to_string(rh.prim) + " at t " + std::to_string(rh.t) + ";";
      }
    }
    EXPECT_EQ(scene.occluded(r), h.valid());
  }
  return a;
}

// The same, the reference's face being the input face.
inline Agreement compare_with_reference(const Scene& scene,
                                        const std::vector<const PolyMesh*>& meshes, int nrays,
                                        uint32_t seed) {
  return compare_with_reference(
      scene, meshes, nrays, seed,
      [](const Hit& h, const RefHit& rh) { return h.primID == rh.prim && h.geomID == rh.geom; },
      true);
}

// Icosahedron subdivided `levels` times (20 * 4^levels triangles), vertices on the unit sphere;
// closed and welded (the sphere of `slimrt verify sphere:L`, without its jitter).
inline PolyMesh icosphere(int levels) {
  PolyMesh m = make_sphere(levels);
  m.name = "sphere";
  return m;
}

}  // namespace slim::test
