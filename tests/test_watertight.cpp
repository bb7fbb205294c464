// Watertightness: rays from inside a closed, finely tessellated, jittered sphere never escape,
// even when aimed exactly at its vertices and edges (Woop et al. 2013 + conservative traversal).
#include <gtest/gtest.h>

#include <map>

#include "test_util.h"

using namespace slim;

namespace {

// Icosphere subdivided `levels` times, vertices jittered radially; closed and welded.
PolyMesh jittered_sphere(int levels, uint32_t seed) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3f> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                          {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<uint32_t> f = {0, 11, 5, 0, 5,  1,  0,  1,  7,  0,  7,  10, 0,  10, 11,
                             1, 5,  9, 5, 11, 4,  11, 10, 2,  10, 7,  6,  7,  1,  8,
                             3, 9,  4, 3, 4,  2,  3,  2,  6,  3,  6,  8,  3,  8,  9,
                             4, 9,  5, 2, 4,  11, 6,  2,  10, 8,  6,  7,  9,  8,  1};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]) * 0.5f);
      return mid[key] = uint32_t(v.size() - 1);
    };
    std::vector<uint32_t> nf;
    for (size_t i = 0; i < f.size(); i += 3) {
      uint32_t a = f[i], b = f[i + 1], c = f[i + 2];
      uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      nf.insert(nf.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
    }
    f.swap(nf);
  }
  Rng rng(seed);
  for (Vec3f& p : v) p = normalize(p) * (1.0f + 0.02f * (rng.uniform() - 0.5f));
  PolyMesh m;
  m.name = "sphere";
  m.positions = v;
  m.face_indices = f;
  m.face_sizes.assign(f.size() / 3, 3);
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
      Vec3f a = m.positions[m.face_indices[i + k]], b = m.positions[m.face_indices[i + (k + 1) % 3]];
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
                         ::testing::Values("bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v",
                                           "clbvh-tri4v", "clbvh-tri4i", "clbvh-compact"));

}  // namespace
