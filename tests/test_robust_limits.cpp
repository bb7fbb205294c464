// Limits: what every configuration does with meshes of 0 and 1 faces, with
// coordinates near 1e30 and 1e-30, with all-coplanar and all-degenerate input, and with rays that
// start exactly on a surface. Each result is documented in the test that checks it. (Headers
// claiming 2^31 - 1 faces: RobustLimits.HeaderClaimingTwoToThe31Faces... in
// test_robust_io.cpp.)
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "slimrt/costa.h"
#include "slimrt/grids.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// Configurations build_or_skip() found not applicable since the last took_not_applied().
std::vector<std::string> not_applied;

// " a b c": the configurations that did not apply (for "at least N of M" messages); clears them.
std::string took_not_applied() {
  std::string s;
  for (const std::string& c : not_applied) s += " " + c;
  not_applied.clear();
  return s.empty() ? " none" : s;
}

// Builds `config` over the mesh; false (and no failure) if it does not apply.
bool build_or_skip(const PolyMesh& m, const std::string& config, Scene& s) {
  try {
    s = Scene::build(m, BuildOptions::from_config(config));
  } catch (const NotApplicable&) {
    not_applied.push_back(config);
    return false;
  } catch (const Error& e) {
    ADD_FAILURE() << config << ": " << e.what();
    return false;
  }
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << config << ": " << why;
  return true;
}

Ray make_ray(Vec3f org, Vec3f dir, float tnear = 0.0f, float tfar = kInf) {
  Ray r;
  r.org = org;
  r.dir = dir;
  r.tnear = tnear;
  r.tfar = tfar;
  return r;
}

// A flat n x n grid of quads in the plane z = 0 over [0, n]^2 (face j*n + i covers cell (i, j)).
PolyMesh flat_grid(int n) {
  PolyMesh m;
  m.name = "flat";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.positions.push_back({float(i), float(j), 0.0f});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t a = j * (n + 1) + i;
      m.face_sizes.push_back(4);
      m.face_indices.insert(m.face_indices.end(), {a, a + 1, a + n + 2, a + n + 1});
    }
  return m;
}

// Icosphere (3 subdivisions, 1280 triangles) of radius `scale`, jittered radially by +-1%.
PolyMesh sphere(float scale) {
  PolyMesh m = icosphere(3);
  Rng rng(3);
  for (Vec3f& p : m.positions) {
    const double r = 1.0 + 0.02 * (rng.uniform() - 0.5);
    // Scale in double so that the tiny and huge spheres are the same shape, not underflowed.
    p = Vec3f(float(double(p.x) * r * scale), float(double(p.y) * r * scale),
              float(double(p.z) * r * scale));
  }
  return m;
}

}  // namespace

// 0 faces (with and without vertices): every configuration builds an empty scene (README:
// "a mesh with no faces builds an empty scene"); every query misses; memory is small.
TEST(RobustLimits, ZeroFacesBuildAnEmptyScene) {
  PolyMesh none;
  PolyMesh verts;
  verts.positions = {{0, 0, 0}, {1, 2, 3}};
  for (const PolyMesh* m : {&none, &verts}) {
    int built = 0;
    for (const std::string& c : all_config_names()) {
      SCOPED_TRACE(c);
      Scene s;
      if (!build_or_skip(*m, c, s)) continue;
      ++built;
      EXPECT_EQ(s.stats().triangles, 0u);
      EXPECT_FALSE(s.intersect(make_ray({0, 0, -1}, {0, 0, 1})).valid());
      EXPECT_FALSE(s.occluded(make_ray({0, 0, -1}, {0, 0, 1})));
      EXPECT_LT(s.memory().total(), 4096u) << c;
    }
    EXPECT_EQ(built, int(all_config_names().size())) << "every configuration applies";
  }
}

// 1 face (a triangle, a quad, a pentagon): every configuration hits it exactly where the
// double-precision reference does, and misses beside it.
TEST(RobustLimits, OneFace) {
  PolyMesh tri, quad, penta;
  tri.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  tri.face_sizes = {3};
  tri.face_indices = {0, 1, 2};
  quad.positions = {{0, 0, 0}, {1, 0, 0.1f}, {1, 1, 0}, {0, 1, 0.1f}};
  quad.face_sizes = {4};
  quad.face_indices = {0, 1, 2, 3};
  penta.positions = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {1, 1, 0}, {0, 2, 0}};
  penta.face_sizes = {5};
  penta.face_indices = {0, 1, 2, 3, 4};
  for (const PolyMesh* m : {&tri, &quad, &penta}) {
    const std::vector<RefTri> ref = reference_triangles({m});
    int built = 0;
    for (const std::string& c : all_config_names()) {
      SCOPED_TRACE(c + " on a " + std::to_string(m->face_sizes[0]) + "-gon");
      Scene s;
      if (!build_or_skip(*m, c, s)) continue;
      ++built;
      Rng rng(9);
      for (int i = 0; i < 200; ++i) {
        const Vec3f o(rng.uniform() * 2.4f - 0.2f, rng.uniform() * 2.4f - 0.2f, 1.0f);
        const Ray r = make_ray(o, {0.01f, -0.02f, -1.0f});
        const Hit h = s.intersect(r);
        const RefHit rh = reference_intersect(ref, r);
        // Lossy formats move vertices; the test points stay off the edges by 1e-3.
        const bool near_edge = std::fabs(o.x) < 1e-2f || std::fabs(o.y) < 1e-2f;
        if (near_edge) continue;
        if (config_info(c).lossy) {
          EXPECT_EQ(h.valid(), rh.valid()) << o.x << "," << o.y;
        } else {
          EXPECT_TRUE(agrees(h, rh, 1e-5)) << o.x << "," << o.y << ": " << h.t << " vs " << rh.t;
        }
        if (h.valid()) {
          EXPECT_EQ(h.primID, 0u);
        }
        EXPECT_EQ(s.occluded(r), h.valid());
      }
    }
    EXPECT_GE(built, 20) << "did not apply:" << took_not_applied();
  }
}

// Coordinates near 1e30 and 1e-30. Measured with a jittered sphere of radius r and rays from
// inside (directions of length ~0.5, so t ~ r), the float watertight test shared by every
// configuration (src/core/watertight.h) behaves so, by radius:
//   1e-22 and below   exact: every edge function underflows to 0, the double fallback decides
//   1e-21 .. 1e-15    most or all rays miss: T = U*az + V*bz + W*cz (~ r^3) underflows to 0
//   1e-14 .. 1e-13    hits, but t is off (denormal T loses its bits)
//   1e-12 .. 1e13     exact
//   1e14 .. 1e20      hits with a wrong t, up to t = +inf (T overflows)
//   1e21 and above    every ray misses: the edge functions overflow
// So slimrt supports coordinates within +-kMaxCoordinate (1e12) and extents from kMinExtent
// (1e-12) (slimrt/scene.h): Scene::build refuses anything else with a clear slim::Error, for
// every configuration, instead of answering wrongly.
TEST(RobustLimits, CoordinatesNear1e30And1e30AreRefused) {
  for (float scale : {0x1p-100f, 0x1p100f}) {
    const PolyMesh m = sphere(scale);
    for (const std::string& c : all_config_names()) {
      SCOPED_TRACE(c + " at radius " + std::to_string(scale));
      try {
        Scene::build(m, BuildOptions::from_config(c));
        ADD_FAILURE() << "built a scene outside the supported coordinate range";
      } catch (const Error& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find(scale > 1.0f ? "beyond +-1e12" : "below 1e-12"), std::string::npos)
            << what;
      }
    }
  }
  // A ray whose origin lies beyond the range misses, by definition (not by overflow).
  const Scene s = Scene::build(sphere(1.0f), BuildOptions::from_config("bvh8-tri4v"));
  EXPECT_FALSE(s.intersect(make_ray({2e12f, 0, 0}, {-1, 0, 0})).valid());
  EXPECT_FALSE(s.occluded(make_ray({0, -2e12f, 0}, {0, 1, 0})));
  EXPECT_TRUE(s.intersect(make_ray({1e12f, 0, 0}, {-1, 0, 0})).valid());
}

// Across the whole float range, in decades: a scene either is refused at build (outside the
// supported range) or every ray from inside hits at the exact t. The boundaries are tested too.
TEST(RobustLimits, EveryBuiltScaleGivesExactHits) {
  int built = 0;
  for (int k = -32; k <= 32; ++k) {
    const float scale = float(std::pow(10.0, k));
    const PolyMesh m = sphere(scale);
    const std::vector<RefTri> ref = reference_triangles({&m});
    Scene s;
    try {
      s = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
    } catch (const Error&) {
      EXPECT_TRUE(k < -12 || k > 11) << "radius 1e" << k << " is inside the supported range";
      continue;
    }
    ++built;
    Rng rng(77);
    for (int i = 0; i < 100; ++i) {
      Vec3f o(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
      const Vec3f d(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
      o = Vec3f(float(double(o.x) * scale), float(double(o.y) * scale), float(double(o.z) * scale));
      const Ray ray = make_ray(o, d);
      const Hit h = s.intersect(ray);
      const RefHit rh = reference_intersect(ref, ray);
      ASSERT_TRUE(rh.valid());
      EXPECT_TRUE(h.valid()) << "radius 1e" << k;
      if (h.valid()) {
        EXPECT_NEAR(h.t, rh.t, 1e-5 * rh.t) << "radius 1e" << k;
      }
    }
  }
  EXPECT_EQ(built, 24) << "radii 1e-12 .. 1e11 build (the sphere reaches 1.9 * radius)";
}

// The lossy grid encoders within the supported range: the error relative to the scene's size
// does not depend on the scale (the displacement exponent bias follows the scene's box).
TEST(RobustLimits, LossyGridErrorIsScaleFree) {
  const PolyMesh unit = load("torus:32");
  for (float scale : {0x1p-36f, 0x1p36f})
    for (int enc : {1, 2}) {
      PolyMesh m = unit;
      for (Vec3f& p : m.positions) p = p * scale;
      const GridErrorStats e1 = grid_error({&unit}, enc), e = grid_error({&m}, enc);
      EXPECT_NEAR(e.rms / scale, e1.rms, 1e-3 * e1.rms) << scale << " encoding " << enc;
      EXPECT_NEAR(e.diag_max_pct, e1.diag_max_pct, 1e-3 * e1.diag_max_pct) << scale;
    }
}

// All faces in one plane (a flat 16 x 16 quad grid at z = 0; every configuration, including the
// grids and the quantized meshes whose box is flat in z):
//   rays crossing the plane hit the face under them at the exact t (lossy formats too: a flat
//     grid has no displacement and a flat box quantizes z exactly);
//   rays lying in the plane (parallel to it, starting on it) miss everything: the watertight
//     test sees every triangle edge-on (det = 0), as Embree does;
//   rays parallel to the plane, just above it, miss.
TEST(RobustLimits, AllCoplanar) {
  const int n = 16;
  const PolyMesh m = flat_grid(n);
  int built = 0;
  for (const std::string& c : all_config_names()) {
    SCOPED_TRACE(c);
    Scene s;
    if (!build_or_skip(m, c, s)) continue;
    ++built;
    Rng rng(5);
    for (int i = 0; i < 300; ++i) {
      const float x = 0.05f + (n - 0.1f) * rng.uniform(), y = 0.05f + (n - 0.1f) * rng.uniform();
      if (std::fabs(x - std::round(x)) < 1e-3f || std::fabs(y - std::round(y)) < 1e-3f) continue;
      const uint32_t face = uint32_t(std::floor(y)) * n + uint32_t(std::floor(x));
      for (const Vec3f d : {Vec3f(0, 0, -1), Vec3f(0.001f, -0.002f, -1)}) {
        const Hit h = s.intersect(make_ray({x, y, 1.0f}, d));
        ASSERT_TRUE(h.valid()) << x << "," << y;
        EXPECT_NEAR(h.t, 1.0f, 1e-6f);
        // The face under the hit point (x + d.x, y + d.y at t = 1), where it is not within 1e-3
        // of a face border.
        const float hx = x + d.x, hy = y + d.y;
        if (std::fabs(hx - std::round(hx)) >= 1e-3f && std::fabs(hy - std::round(hy)) >= 1e-3f) {
          EXPECT_EQ(h.primID, uint32_t(std::floor(hy)) * n + uint32_t(std::floor(hx)))
              << x << "," << y << " along " << d.x << "," << d.y;
        }
      }
      const Hit up = s.intersect(make_ray({x, y, -2.0f}, {0, 0, 1}));
      ASSERT_TRUE(up.valid());
      EXPECT_EQ(up.primID, face);
      EXPECT_NEAR(up.t, 2.0f, 2e-6f);  // 1 ulp: T / det rounds when the vertices are quantized
      // In the plane: from outside the grid across it, and from inside a face along it.
      EXPECT_FALSE(s.intersect(make_ray({-1.0f, y, 0.0f}, {1, 0, 0})).valid());
      EXPECT_FALSE(s.occluded(make_ray({-1.0f, y, 0.0f}, {1, 0.3f, 0})));
      EXPECT_FALSE(s.intersect(make_ray({x, y, 0.0f}, {1, 1, 0})).valid());
      EXPECT_FALSE(s.intersect(make_ray({x, y, 1e-6f}, {1, 0.5f, 0})).valid());
    }
  }
  EXPECT_GE(built, 20) << "did not apply:" << took_not_applied();
}

// All faces degenerate or using a NaN/Inf vertex. Degenerate faces here are exactly so in float:
// corners on a dyadic lattice, so that "collinear" is exact, repeated indices, or one point.
// Documented result, every configuration:
//   - faces with a NaN/Inf vertex are skipped and counted (README), nothing is hit;
//   - faces with a repeated corner (a triangle A, C, A or a quad of one point) are never hit:
//     an edge function of a repeated pair is exactly 0, and the double-precision fallback then
//     finds det = 0;
//   - exactly collinear corners can be hit, but only ON their segment: the shear into ray space
//     rounds, which can give the projected triangle a tiny area (Woop et al. accept it; so does
//     Embree's robust mode). So a ray aimed exactly at a corner of such a face may hit it at that
//     corner (t = 1 here), and a ray that passes the segment misses it.
TEST(RobustLimits, AllDegenerate) {
  PolyMesh m;
  Rng rng(11);
  auto dyadic = [&] { return float(int(rng.next() % 512) - 256) / 256.0f; };
  for (int i = 0; i < 200; ++i) {
    const Vec3f a(dyadic(), dyadic(), dyadic());
    const Vec3f d(dyadic(), dyadic(), dyadic());
    const uint32_t b = uint32_t(m.positions.size());
    m.positions.insert(m.positions.end(), {a, a + d * 0.5f, a + d});  // exact: dyadic
    switch (i % 4) {
      case 0:  // collinear triangle
        m.face_sizes.push_back(3), m.face_indices.insert(m.face_indices.end(), {b, b + 1, b + 2});
        break;
      case 1:  // repeated index
        m.face_sizes.push_back(3), m.face_indices.insert(m.face_indices.end(), {b, b + 2, b});
        break;
      case 2:  // one point, as a quad
        m.face_sizes.push_back(4), m.face_indices.insert(m.face_indices.end(), {b, b, b, b});
        break;
      default:  // collinear quad
        m.face_sizes.push_back(4),
            m.face_indices.insert(m.face_indices.end(), {b, b + 1, b + 2, b + 1});
    }
  }
  PolyMesh nan = flat_grid(4);
  for (size_t i = 0; i < nan.positions.size(); i += 2)
    nan.positions[i].z = i % 4 ? std::numeric_limits<float>::infinity() : NAN;
  EXPECT_EQ(summarize(m).degenerate_faces, m.face_count());
  for (const PolyMesh* mesh : {&m, &nan}) {
    int built = 0;
    uint64_t corner_hits = 0, corner_rays = 0;
    for (const std::string& c : all_config_names()) {
      SCOPED_TRACE(c);
      Scene s;
      if (!build_or_skip(*mesh, c, s)) continue;
      ++built;
      if (mesh == &nan) {
        EXPECT_EQ(s.stats().skipped_faces, 16u);  // every face has a bad corner
      }
      Rng r2(3);
      for (int i = 0; i < 300; ++i) {
        // Exactly at a corner (t = 1), or at random points of the box.
        const bool at_corner = mesh == &m && i % 2 == 0;
        const Vec3f p = at_corner ? mesh->positions[r2.next() % mesh->positions.size()]
                                  : Vec3f(4 * r2.uniform() - 2, 4 * r2.uniform() - 2, 0.3f);
        const Vec3f o(p.x + 0.3f, p.y - 2.0f, p.z + 1.0f);
        const Ray ray = make_ray(o, p - o);
        const Hit h = s.intersect(ray);
        corner_rays += at_corner;
        if (!h.valid()) {
          EXPECT_FALSE(s.occluded(ray));
          continue;
        }
        corner_hits++;
        EXPECT_TRUE(at_corner) << "a ray that passes no corner hit face " << h.primID;
        EXPECT_TRUE(h.primID % 4 == 0 || h.primID % 4 == 3)
            << "face " << h.primID << " with a repeated corner was hit";
        EXPECT_NEAR(h.t, 1.0f, 1e-5f) << "a collinear face was hit off its segment";
      }
    }
    EXPECT_GE(built, 20) << "did not apply:" << took_not_applied();
    if (mesh == &m)
      std::printf("  degenerate faces: %llu of %llu rays aimed at corners hit a collinear face\n",
                  (unsigned long long)corner_hits, (unsigned long long)corner_rays);
  }
}

// Rays that start exactly on a surface. slimrt reports hits with tnear < t <= tfar (Woop et al.,
// as Embree) and treats a negative tnear as 0, so a surface through the origin (t = 0) is never
// reported: a ray leaving a face, edge or vertex of a closed mesh does not hit that surface again,
// whichever way it points, and finds the next surface instead. A hit at t = 0 is only possible for
// no ray at all; a surface at the smallest t > 0 (an origin 1e-30 below the plane) is reported.
TEST(RobustLimits, RaysStartingOnASurface) {
  const PolyMesh flat = flat_grid(4);
  for (const std::string& c : all_config_names()) {
    SCOPED_TRACE(c);
    Scene s;
    if (!build_or_skip(flat, c, s)) continue;
    for (const Vec3f o : {Vec3f(1.25f, 2.5f, 0), Vec3f(1.0f, 2.5f, 0), Vec3f(2, 2, 0)})  // face,
      for (const Vec3f d : {Vec3f(0, 0, 1), Vec3f(0, 0, -1), Vec3f(0.3f, 0.1f, 1)})      // edge,
        for (float tnear : {0.0f, -1.0f}) {                                              // vertex
          EXPECT_FALSE(s.intersect(make_ray(o, d, tnear)).valid()) << o.x << "," << o.y;
          EXPECT_FALSE(s.occluded(make_ray(o, d, tnear)));
        }
    const Hit h = s.intersect(make_ray({1.25f, 2.5f, -1e-30f}, {0, 0, 1}));
    ASSERT_TRUE(h.valid());
    EXPECT_NEAR(h.t, 1e-30f, 1e-36f);
  }
  // A closed sphere: rays starting exactly at a vertex, pointing inward, hit the far side (never
  // t = 0, nor a t of rounding size); pointing outward, they hit nothing. For the lossy formats
  // the surface is their decoded one (an input vertex is up to their error off it, so a ray from
  // it may meet the decoded surface right away): their rays start at decoded vertices.
  const PolyMesh ball = sphere(1.0f);
  for (const std::string& c : all_config_names()) {
    SCOPED_TRACE(c);
    Scene s;
    if (!build_or_skip(ball, c, s)) continue;
    const BuildOptions opt = BuildOptions::from_config(c);
    std::vector<Vec3f> origins = ball.positions;
    if (std::optional<DecodedTriangles> t = decoded_triangles(s, {&ball})) origins = t->vertices;
    for (size_t i = 0; i < origins.size(); i += 7) {
      const Vec3f o = origins[i];
      const Hit h = s.intersect(make_ray(o, o * -1.0f));
      ASSERT_TRUE(h.valid());
      EXPECT_GT(h.t, 1.5f) << "vertex " << i;  // the far side: t ~ 2 (direction = -radius)
      EXPECT_FALSE(s.intersect(make_ray(o, o)).valid()) << "outward from vertex " << i;
    }
  }
}

// Tiny ray directions: t ~ distance / |dir| can reach 1e30 with coordinates within the supported
// range, where the float T = U az + V bz + W cz of the watertight test overflows. Such a hit is
// re-evaluated in double (src/core/watertight.h): every configuration reports the right finite t.
// Directions below kMinDirection are zero directions (a miss).
TEST(RobustLimits, TinyDirectionsGiveFiniteT) {
  PolyMesh m;
  m.name = "far wall";
  const float x = 1e10f, e = 1e10f;
  m.positions = {{x, -e, -e}, {x, e, -e}, {x, e, e}, {x, -e, e}};
  m.face_sizes = {4};
  m.face_indices = {0, 1, 2, 3};
  int built = 0;
  for (const std::string& c : all_config_names()) {
    SCOPED_TRACE(c);
    Scene s;
    if (!build_or_skip(m, c, s)) continue;
    ++built;
    for (const Vec3f& o : {Vec3f(0, 0, 0), Vec3f(0, 1e9f, -3e9f)}) {
      const Hit h = s.intersect(make_ray(o, {1e-17f, 0, 0}));
      ASSERT_TRUE(h.valid());
      EXPECT_TRUE(std::isfinite(h.t));
      EXPECT_NEAR(h.t / 1e27f, 1.0f, 1e-4f);  // (1e10 - 0) / 1e-17; T ~ 1e48 overflows
      EXPECT_TRUE(s.occluded(make_ray(o, {1e-17f, 0, 0})));
      // 1e-30: below kMinDirection, a zero direction (a miss).
      EXPECT_FALSE(s.intersect(make_ray(o, {1e-30f, 0, 0})).valid());
      // Far away with the smallest direction: t = 2e12 / 1e-18 = 2e30, T ~ 1e55 overflows.
      const Hit h2 = s.intersect(make_ray(o - Vec3f(1e12f, 0, 0), {kMinDirection, 0, 0}));
      ASSERT_TRUE(h2.valid());
      EXPECT_NEAR(h2.t / ((x - (o.x - 1e12f)) / kMinDirection), 1.0f, 1e-4f);
    }
  }
  EXPECT_GE(built, 20) << "did not apply:" << took_not_applied();
}
