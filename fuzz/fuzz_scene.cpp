// libFuzzer target: Scene::build, validate(), intersect() and occluded() of every configuration
// (all_config_names(): BVH8, QBVH8, CLBVH and its compact form over triangles, pairs, grids, lossy
// grids and the Costa quantized meshes) on meshes and rays made from the fuzz input.
//
// Input bytes:
//   [0]      bit 0: raw float vertices and rays (any bits: NaN, Inf, huge, denormal) instead of
//            int8 lattice points times 2^scale; bits 1-5: scale exponent - 16
//   [1]      vertex count - 1 (1..256)
//   [2]      ray count (0..255)
//   then     vertices (3 x int8 or 3 x float each), rays (origin and direction, 6 x int8 or
//            6 x float each), then faces until the input ends: a size byte (3 + byte % 4 corners)
//            and one index byte per corner (modulo the vertex count)
// Checks, for every configuration (README.md: untrusted input gets an error, never a crash):
//   - build either succeeds or throws slim::Error with a message (coordinates beyond
//     kMaxCoordinate, a configuration that does not apply); validate() accepts what was built;
//   - every hit names a face of the mesh, with tnear <= t <= tfar, finite t; occluded() is true
//     exactly when intersect() hits; a ray with a NaN or zero direction (below kMinDirection) or a
//     NaN origin misses;
//   - lattice input, lossless configurations (all but lossy-grid* and costa*, which intersect
//     their own decoded triangles): against a double-precision brute force over the fan
//     triangles with margins relative to the scene's scale (away from edges, grazing angles and
//     the origin), no robust hit is missed or passed over, and the reported face has a fan
//     triangle that may be hit at the reported t.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "slimrt/error.h"
#include "slimrt/scene.h"

namespace {

using namespace slim;

struct Reader : fuzz::Reader {
  Vec3f lattice(float scale) {
    int8_t c[3];
    bytes(c, sizeof c);
    return {c[0] * scale, c[1] * scale, c[2] * scale};
  }
  Vec3f raw() {
    float c[3];
    bytes(c, sizeof c);
    return {c[0], c[1], c[2]};
  }
};

struct D3 {
  double x, y, z;
};
D3 d3(const Vec3f& v) { return {v.x, v.y, v.z}; }
D3 sub(D3 a, D3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
D3 cross(D3 a, D3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double dot(D3 a, D3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
double len(D3 a) { return std::sqrt(dot(a, a)); }

// A fan triangle against the ray in double precision, in the plane perpendicular to the ray (as
// the watertight test works): E_k = the edge functions of the corners projected relative to the
// origin. With S the scene's coordinate scale, slimrt's float E_k are within ~1e-6 S^2 of these.
// `robust`: every E_k at least tau = 1e-5 S^2 on the side of their sum, the ray at least 0.01
// (cosine) off the plane and the hit at least tol = 1e-3 S along the ray; `possible`: no E_k
// beyond tau on the wrong side; `any_t`: degenerate (|sum| <= 3 tau) or grazing, where any t goes.
struct RefTest {
  bool robust = false, possible = false, any_t = false;
  double dist = 0;  // distance along the ray (t * |dir|) unless any_t
};
RefTest ref_test(const Vec3f p[3], D3 o, D3 d, double S) {
  RefTest r;
  const double tau = 1e-5 * S * S, tol = 1e-3 * S;
  const double dl = len(d);
  const D3 w = {d.x / dl, d.y / dl, d.z / dl};
  // Orthonormal u, v perpendicular to w.
  const D3 helper = std::fabs(w.x) < 0.5 ? D3{1, 0, 0} : D3{0, 1, 0};
  D3 u = cross(w, helper);
  const double ul = len(u);
  u = {u.x / ul, u.y / ul, u.z / ul};
  const D3 v = cross(w, u);
  double P[3][2];
  for (int k = 0; k < 3; ++k) {
    const D3 q = sub(d3(p[k]), o);
    P[k][0] = dot(q, u);
    P[k][1] = dot(q, v);
  }
  double E[3], sum = 0;
  for (int k = 0; k < 3; ++k) {
    const double* a = P[k];
    const double* b = P[(k + 1) % 3];
    E[k] = a[0] * b[1] - a[1] * b[0];
    sum += E[k];
  }
  const double sg = sum >= 0 ? 1.0 : -1.0;
  double worst = INFINITY;
  for (double e : E) worst = std::min(worst, sg * e);
  r.possible = worst >= -tau;
  const D3 a = d3(p[0]), b = d3(p[1]), c = d3(p[2]);
  const D3 n = cross(sub(b, a), sub(c, a));
  const double nn = len(n);
  const double cosine = nn > 0 ? std::fabs(dot(n, w)) / nn : 0.0;
  if (std::fabs(sum) <= 3 * tau || cosine < 0.01) {
    r.any_t = true;
    return r;
  }
  r.dist = dot(n, sub(a, o)) / dot(n, w);
  r.possible = r.possible && r.dist >= -tol;
  r.robust = worst >= tau && r.dist >= tol;
  return r;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader rd{{data, size}};
  const uint8_t flags = rd.byte();
  const bool raw = flags & 1;
  const float scale = std::ldexp(1.0f, int((flags >> 1) & 31) - 16);
  const uint32_t nv = 1 + rd.byte(), nr = rd.byte();
  PolyMesh m;
  m.name = "fuzz";
  for (uint32_t i = 0; i < nv; ++i) m.positions.push_back(raw ? rd.raw() : rd.lattice(scale));
  std::vector<Ray> rays;
  for (uint32_t i = 0; i < nr; ++i) {
    Ray r;
    r.org = raw ? rd.raw() : rd.lattice(2 * scale);
    r.dir = raw ? rd.raw() : rd.lattice(1.0f);
    rays.push_back(r);
  }
  while (rd.n > 0) {
    const uint32_t corners = 3 + rd.byte() % 4;
    for (uint32_t k = 0; k < corners; ++k) m.face_indices.push_back(rd.byte() % nv);
    m.face_sizes.push_back(corners);
  }

  // Fan triangles of each face (the lossless configurations' geometry), finite faces only.
  struct Fan {
    Vec3f p[3];
    uint32_t face;
  };
  std::vector<Fan> fans;
  bool all_finite = true;
  uint64_t c = 0;
  for (uint32_t f = 0; f < m.face_count(); ++f) {
    const uint32_t n = m.face_sizes[f];
    bool ok = true;
    for (uint32_t k = 0; k < n; ++k) ok = ok && is_finite(m.positions[m.face_indices[c + k]]);
    all_finite = all_finite && ok;
    for (uint32_t k = 1; ok && k + 1 < n; ++k)
      fans.push_back({{m.positions[m.face_indices[c]], m.positions[m.face_indices[c + k]],
                       m.positions[m.face_indices[c + k + 1]]},
                      f});
    c += n;
  }
  // The coordinate scale S of the vertices and ray origins (ref_test's margins are relative to it).
  double S = scale;
  for (const Vec3f& p : m.positions)
    for (int a = 0; a < 3; ++a) S = std::max(S, double(std::fabs(p[a])));
  for (const Ray& r : rays)
    for (int a = 0; a < 3; ++a) S = std::max(S, double(std::fabs(r.org[a])));
  const double tol = 1e-3 * S;

  // The reference of each ray, once for all configurations (it depends on the ray and the fan
  // triangles only): the nearest robust hit, and the fan triangles a hit may land on.
  struct Candidate {
    uint32_t face;
    bool any_t;
    double dist;
  };
  struct RayRef {
    bool dead = false;
    double nearest = INFINITY;  // the nearest robust hit's distance along the ray
    uint32_t nearest_face = 0;
    std::vector<Candidate> possible;
  };
  std::vector<RayRef> refs(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    const Ray& ray = rays[i];
    RayRef& rr = refs[i];
    rr.dead = !is_finite(ray.org) || std::isnan(ray.dir.x) || std::isnan(ray.dir.y) ||
              std::isnan(ray.dir.z) ||
              (std::fabs(ray.dir.x) < kMinDirection && std::fabs(ray.dir.y) < kMinDirection &&
               std::fabs(ray.dir.z) < kMinDirection);
    if (raw || !all_finite || rr.dead) continue;
    const D3 o = d3(ray.org), d = d3(ray.dir);
    for (const Fan& f : fans) {
      const RefTest r = ref_test(f.p, o, d, S);
      if (r.robust && r.dist < rr.nearest) rr.nearest = r.dist, rr.nearest_face = f.face;
      if (r.possible) rr.possible.push_back({f.face, r.any_t, r.dist});
    }
  }

  for (const std::string& config : all_config_names()) {
    const BuildOptions opt = BuildOptions::from_config(config);
    Scene scene;
    try {
      scene = Scene::build(m, opt);
    } catch (const Error& e) {
      SLIM_FUZZ_CHECK(std::strlen(e.what()) > 0, config + ": empty error message");
      continue;
    }
    std::string why;
    SLIM_FUZZ_CHECK(scene.validate(&why), config + ": validate: " + why);
    const bool oracle = !raw && all_finite && !config_info(config).own_geometry;
    for (size_t i = 0; i < rays.size(); ++i) {
      const Ray& ray = rays[i];
      const std::string what = config + " ray " + std::to_string(i);
      const Hit h = scene.intersect(ray);
      const bool occ = scene.occluded(ray);
      SLIM_FUZZ_CHECK(occ == h.valid(), what + ": occluded() != intersect().valid()");
      const RayRef& rr = refs[i];
      const bool dead = rr.dead;
      if (dead) SLIM_FUZZ_CHECK(!h.valid(), what + ": a NaN/zero-direction ray hit");
      if (!h.valid()) {
        SLIM_FUZZ_CHECK(h.primID == kInvalidID, what + ": miss with a primID");
      } else {
        SLIM_FUZZ_CHECK(h.geomID == 0 && h.primID < m.face_count(), what + ": hit names no face");
        SLIM_FUZZ_CHECK(std::isfinite(h.t) && h.t >= ray.tnear && h.t <= ray.tfar,
                        what + ": t out of [tnear, tfar]");
      }
      if (!oracle || dead) continue;
      const double got = h.valid() ? double(h.t) * len(d3(ray.dir)) : INFINITY;
      SLIM_FUZZ_CHECK(got <= rr.nearest + tol,
                      what + ": passed over face " + std::to_string(rr.nearest_face) + " at " +
                          std::to_string(rr.nearest) + " (got " + std::to_string(got) + ")");
      bool face_ok = !h.valid();
      for (const Candidate& c : rr.possible)
        if (h.valid() && c.face == h.primID && (c.any_t || std::fabs(c.dist - got) <= tol))
          face_ok = true;
      SLIM_FUZZ_CHECK(face_ok, what + ": no fan triangle of face " + std::to_string(h.primID) +
                                   " at distance " + std::to_string(got));
    }
  }
  return 0;
}
