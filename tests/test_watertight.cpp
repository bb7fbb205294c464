// Watertightness: rays from inside a closed, finely tessellated, jittered sphere never escape,
// even when aimed exactly at its vertices and edges (Woop et al. 2013 + conservative traversal).
#include <gtest/gtest.h>

#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// Icosphere subdivided `levels` times, vertices jittered radially by +-1%; closed and welded.
PolyMesh jittered_sphere(int levels, uint32_t seed) {
  PolyMesh m = icosphere(levels);
  Rng rng(seed);
  for (Vec3f& p : m.positions) p = p * (1.0f + 0.02f * (rng.uniform() - 0.5f));
  return m;
}

struct LeakCount {
  uint64_t rays = 0, misses = 0;
};

LeakCount shoot(const Scene& s, const PolyMesh& m, int random_rays, uint32_t seed) {
  Rng rng(seed, 3);
  LeakCount c;
  auto one = [&](Vec3f org, Vec3f target) {
    Ray r;
    r.org = org;
    r.dir = target - org;  // not normalized: aimed exactly at the target
    c.rays++;
    Hit h = s.intersect(r);
    if (!h.valid()) c.misses++;
    if (!s.occluded(r)) c.misses++;
  };
  auto inside = [&] {
    return Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f) * 0.9f;
  };
  // Random directions.
  for (int i = 0; i < random_rays; ++i) {
    Vec3f d(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
    one(inside(), inside() + d);
  }
  // Exactly at every vertex and at every edge midpoint (computed in float), from random origins.
  for (const Vec3f& p : m.positions) one(inside(), p);
  for (size_t i = 0; i < m.face_indices.size(); i += 3)
    for (int k = 0; k < 3; ++k) {
      Vec3f a = m.positions[m.face_indices[i + k]],
            b = m.positions[m.face_indices[i + (k + 1) % 3]];
      one(inside(), (a + b) * 0.5f);
    }
  return c;
}

class Watertight : public ::testing::TestWithParam<const char*> {};

TEST_P(Watertight, NoRayEscapesAClosedSphere) {
  PolyMesh m = jittered_sphere(6, 5);  // 81920 triangles, 40962 vertices
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  // 10^6 rays in all: ~750k random + 41k vertices + 246k edges (each traced twice: closest/any).
  LeakCount c = shoot(s, m, 750000, 17);
  EXPECT_GE(c.rays, 1000000u);
  EXPECT_EQ(c.misses, 0u) << GetParam() << ": " << c.misses << " of " << c.rays << " rays leaked";
}

INSTANTIATE_TEST_SUITE_P(Bvh, Watertight,
                         ::testing::Values("bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "clbvh-tri4v",
                                           "clbvh-tri4i", "clbvh-compact"));

}  // namespace
