// The double-precision fallback of the watertight test (src/core/watertight.h; Woop, Benthin,
// Wald, "Watertight Ray/Triangle Intersection", JCGT 2013, section 3.3) reached on purpose with
// NON-degenerate triangles.
//
// Construction (ray space = scene space: org (0,0,0), dir (0,0,1), so kz = z, Sx = Sy = 0 and
// the transformed vertices are the input floats bit for bit):
//   b = (1, 3), c = (cx, cy) with cx = -(1 + k 2^-23) and cy = fl(3 cx), a float that is NOT 3 cx;
//   the edge function of the edge bc, U = c.x*b.y - c.y*b.x, is fl(3 cx) - cy = 0 in float (each
//   product rounded, as the test computes it) but 3 cx - cy != 0 exactly (double products of
//   floats are exact). The ray passes within 1e-7 of the edge bc, on one side of it.
// Two triangles of area 10 share bc, in the plane z = 1: T0 = (a0, b, c) with a0 = (3, -1) and
// T1 = (a1, c, b) with a1 = (-3, 1). k is chosen so that 3 cx - cy > 0: the ray is on T1's side,
// so the exact answer is "T1 at t = 1, T0 missed". Without the fallback, U = 0 counts as inside
// for both triangles and T0 is hit too (checked by removing the fallback).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "core/simd.h"
#include "core/watertight.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

struct EdgeCase {
  float cx = 0, cy = 0;
  double exact_u = 0;  // 3 cx - cy in double (exact)
};

// The first k = 1, 2, ... whose c = (-(1 + k 2^-23), fl(3 cx)) has a float edge function of
// exactly 0 and an exact one > 0.
EdgeCase find_case() {
  for (int k = 1; k < 64; ++k) {
    EdgeCase e;
    e.cx = -(1.0f + float(k) * std::ldexp(1.0f, -23));
    volatile float p = e.cx * 3.0f;  // rounded to float, as the test's product is
    e.cy = p;
    volatile float q1 = e.cx * 3.0f, q2 = e.cy * 1.0f;
    const float u_float = q1 - q2;
    e.exact_u = double(e.cx) * 3.0 - double(e.cy) * 1.0;
    if (u_float == 0.0f && e.exact_u > 0) return e;
  }
  ADD_FAILURE() << "no k gives a float-zero, exactly-positive edge function";
  return {};
}

struct Tri {
  Vec3f a, b, c;
};

// T0 (the exact answer misses it) and T1 (the exact answer hits it at t = 1).
void make_triangles(const EdgeCase& e, Tri& t0, Tri& t1) {
  const Vec3f b(1, 3, 1), c(e.cx, e.cy, 1);
  t0 = {Vec3f(3, -1, 1), b, c};
  t1 = {Vec3f(-3, 1, 1), c, b};
}

Ray the_ray() {
  Ray r;
  r.org = Vec3f(0, 0, 0);
  r.dir = Vec3f(0, 0, 1);
  r.tnear = 0;
  r.tfar = kInf;
  return r;
}

TEST(WatertightFallback, ConstructionIsAnExactZeroOnANonDegenerateTriangle) {
  const EdgeCase e = find_case();
  Tri t0, t1;
  make_triangles(e, t0, t1);
  // Independent of the code under test: the float edge function in the test's operation order
  // (unfused products) is 0, the exact one is not, and the triangles have area 10 (> 0).
  volatile float p1 = t0.c.x * t0.b.y, p2 = t0.c.y * t0.b.x;
  EXPECT_EQ(p1 - p2, 0.0f);
  EXPECT_GT(e.exact_u, 0.0);
  EXPECT_LT(e.exact_u, 1e-6);
  auto area = [](const Tri& t) {
    const Vec3f n = cross(t.b - t.a, t.c - t.a);
    return 0.5 * std::sqrt(double(dot(n, n)));
  };
  EXPECT_NEAR(area(t0), 10.0, 1e-5);
  EXPECT_NEAR(area(t1), 10.0, 1e-5);
  // The double-precision brute force agrees: T1 is hit, T0 is not.
  PolyMesh m;
  m.positions = {t0.a, t0.b, t0.c, t1.a};
  m.face_indices = {0, 1, 2, 3, 2, 1};
  m.face_sizes = {3, 3};
  const RefHit rh = reference_intersect(reference_triangles({&m}), the_ray());
  ASSERT_TRUE(rh.valid());
  EXPECT_EQ(rh.prim, 1u);
  EXPECT_DOUBLE_EQ(rh.t, 1.0);
}

TEST(WatertightFallback, ScalarTestTakesTheExactSide) {
  const EdgeCase e = find_case();
  Tri tri[2];
  make_triangles(e, tri[0], tri[1]);
  const Ray r = the_ray();
  const WatertightRay wr(r.org, r.dir);
  for (int i = 0; i < 2; ++i) {
    const RayVertex<float> a = to_ray_space(wr, tri[i].a.x, tri[i].a.y, tri[i].a.z);
    const RayVertex<float> b = to_ray_space(wr, tri[i].b.x, tri[i].b.y, tri[i].b.z);
    const RayVertex<float> c = to_ray_space(wr, tri[i].c.x, tri[i].c.y, tri[i].c.z);
    ASSERT_EQ(c.x * b.y - c.y * b.x, 0.0f) << "the float edge function must be exactly 0";
    float t = -1, u = -1, v = -1;
    const bool hit = intersect_triangle(a, b, c, r.tnear, r.tfar, t, u, v);
    EXPECT_EQ(hit, i == 1) << "triangle T" << i << ": the exact edge function is "
                           << (i == 0 ? e.exact_u : -e.exact_u);
    if (i == 1 && hit) {
      EXPECT_EQ(t, 1.0f);
    }
  }
}

template <class VF>
void simd_case() {
  constexpr int N = sizeof(VF) / sizeof(float);
  const EdgeCase e = find_case();
  Tri tri[2];
  make_triangles(e, tri[0], tri[1]);
  const Ray r = the_ray();
  const WatertightRay wr(r.org, r.dir);
  // Lanes alternate T0, T1; every lane valid.
  alignas(32) float v[9][N];
  for (int l = 0; l < N; ++l) {
    const Tri& t = tri[l & 1];
    const Vec3f p[3] = {t.a, t.b, t.c};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) v[3 * k + a][l] = p[k][a];
  }
  RayVertex<VF> rv[3];
  for (int k = 0; k < 3; ++k)
    rv[k] = to_ray_space(wr, VF::loadu(v[3 * k]), VF::loadu(v[3 * k + 1]), VF::loadu(v[3 * k + 2]));
  VF t(0.0f), u(0.0f), w(0.0f);
  const uint32_t all = (1u << N) - 1;
  const uint32_t m = intersect_triangles(rv[0], rv[1], rv[2], all, r.tnear, r.tfar, t, u, w);
  uint32_t odd = 0;
  for (int l = 1; l < N; l += 2) odd |= 1u << l;
  EXPECT_EQ(m, odd) << N << " lanes: only the T1 lanes may hit (exact edge function " << e.exact_u
                    << " puts the ray on T1's side)";
  alignas(32) float tt[N];
  t.storeu(tt);
  for (int l = 1; l < N; l += 2) EXPECT_EQ(tt[l], 1.0f);
}

TEST(WatertightFallback, SimdTestTakesTheExactSide) {
  simd_case<simd::vfloat4>();
  simd_case<simd::vfloat8>();
}

// Every configuration that intersects the input's own vertices (the lossless ones) reports T1,
// whichever order the two faces come in.
TEST(WatertightFallback, EveryLosslessConfigurationReportsTheExactFace) {
  const EdgeCase e = find_case();
  Tri t0, t1;
  make_triangles(e, t0, t1);
  for (int order = 0; order < 2; ++order) {
    PolyMesh m;
    m.positions = {t0.a, t0.b, t0.c, t1.a};
    // Face `hit_face` is T1.
    const uint32_t hit_face = order == 0 ? 1 : 0;
    m.face_indices = order == 0 ? std::vector<uint32_t>{0, 1, 2, 3, 2, 1}
                                : std::vector<uint32_t>{3, 2, 1, 0, 1, 2};
    m.face_sizes = {3, 3};
    for (const std::string& config : all_config_names()) {
      if (is_lossy_config(config)) continue;
      Scene s;
      try {
        s = Scene::build(m, BuildOptions::from_config(config));
      } catch (const Error& err) {
        if (!not_applicable(err)) ADD_FAILURE() << config << ": " << err.what();
        std::printf("  %s: %s\n", config.c_str(), err.what());
        continue;
      }
      const Hit h = s.intersect(the_ray());
      ASSERT_TRUE(h.valid()) << config << " order " << order;
      EXPECT_EQ(h.primID, hit_face) << config << " order " << order;
      EXPECT_EQ(h.t, 1.0f) << config;
    }
  }
}

}  // namespace
