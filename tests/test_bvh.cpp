// BVH8 + triangle leaves against the double-precision brute-force reference.
#include <gtest/gtest.h>

#include "bvh/bvh8.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

class TriangleConfigs : public ::testing::TestWithParam<const char*> {};

TEST_P(TriangleConfigs, RandomSoupMatchesReference) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    PolyMesh m = random_soup(3000, seed);
    Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    Agreement a = compare_with_reference(s, {&m}, 2000, seed);
    EXPECT_GT(a.hits, 500u);
    EXPECT_EQ(a.agree, a.rays) << GetParam() << " seed " << seed;
    // Random vertices: no two triangles share an edge or a vertex, so ties are impossible and
    // every hit names the reference's face.
    EXPECT_EQ(a.same_face, a.hits) << GetParam() << " seed " << seed << ":" << a.wrong;
  }
}

TEST_P(TriangleConfigs, MixedPolygonsAndSeveralMeshes) {
  // Quads, pentagons and two meshes: primID names the input face, geomID the mesh.
  PolyMesh a = random_soup(500, 9);
  PolyMesh b;
  Rng rng(4);
  for (int f = 0; f < 400; ++f) {
    int n = 4 + f % 3;
    Vec3f c(rng.uniform(), rng.uniform(), rng.uniform());
    uint32_t base = uint32_t(b.positions.size());
    for (int k = 0; k < n; ++k) {
      float ang = 6.2831853f * k / n;
      b.positions.push_back(c + Vec3f(std::cos(ang), std::sin(ang), 0.3f * (rng.uniform() - 0.5f)) *
                                    0.03f);
      b.face_indices.push_back(base + k);
    }
    b.face_sizes.push_back(n);
  }
  Scene s =
      Scene::build(std::vector<const PolyMesh*>{&a, &b}, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  Agreement ag = compare_with_reference(s, {&a, &b}, 3000, 5);
  EXPECT_EQ(ag.agree, ag.rays);
  // Random polygons share no edge with another face (fan diagonals are inside one face): every
  // hit names the reference's face and mesh.
  EXPECT_GT(ag.hits, 300u);
  EXPECT_EQ(ag.same_face, ag.hits) << GetParam() << ":" << ag.wrong;
  EXPECT_EQ(s.memory().triangles, a.fan_triangle_count() + b.fan_triangle_count());
}

INSTANTIATE_TEST_SUITE_P(Bvh, TriangleConfigs,
                         ::testing::Values("bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "qbvh8-tri4i",
                                           "clbvh-tri4v", "clbvh-tri4i", "clbvh-compact"));

TEST(Bvh, BadRaysMiss) {
  PolyMesh m = random_soup(100, 1);
  Scene s = Scene::build(m);
  Ray r;
  r.org = Vec3f(0.5f, 0.5f, -1);
  r.dir = Vec3f(0, 0, 0);
  EXPECT_FALSE(s.intersect(r).valid());
  EXPECT_FALSE(s.occluded(r));
  r.dir = Vec3f(NAN, 0, 1);
  EXPECT_FALSE(s.intersect(r).valid());
  r.dir = Vec3f(0, 0, 1);
  r.org = Vec3f(NAN, 0, 0);
  EXPECT_FALSE(s.intersect(r).valid());
  r.org = Vec3f(0.5f, 0.5f, -1);
  r.tnear = 2;
  r.tfar = 1;
  EXPECT_FALSE(s.intersect(r).valid());
  EXPECT_FALSE(s.occluded(r));
  r.tnear = NAN;
  r.tfar = kInf;
  EXPECT_FALSE(s.intersect(r).valid());
}

TEST(Bvh, EmptyAndSingleTriangle) {
  PolyMesh empty;
  Scene s = Scene::build(empty);
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << why;
  Ray r;
  r.org = Vec3f(0, 0, -1);
  r.dir = Vec3f(0, 0, 1);
  EXPECT_FALSE(s.intersect(r).valid());
  EXPECT_EQ(s.memory().total(), 0u);

  PolyMesh one;
  one.positions = {{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}};
  one.face_sizes = {3};
  one.face_indices = {0, 1, 2};
  for (const char* c : {"bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "clbvh-tri4v"}) {
    Scene s1 = Scene::build(one, BuildOptions::from_config(c));
    EXPECT_TRUE(s1.validate(&why)) << why;
    Hit h = s1.intersect(r);
    ASSERT_TRUE(h.valid()) << c;
    EXPECT_FLOAT_EQ(h.t, 1.0f);
    EXPECT_EQ(h.primID, 0u);
    EXPECT_GT(std::fabs(h.Ng.z), 0.0f);
  }
}

TEST(Bvh, QuantizedBoxesAreConservative) {
  Rng rng(11);
  for (int iter = 0; iter < 2000; ++iter) {
    float scale = std::pow(10.0f, float(int(rng.next() % 60) - 30));
    float offset = (rng.uniform() - 0.5f) * scale * float(rng.next() % 2 ? 1e4 : 1);
    Box3f boxes[8];
    Box3f parent;
    int n = 1 + rng.next() % 8;
    for (int i = 0; i < n; ++i) {
      Vec3f a(offset + rng.uniform() * scale, offset + rng.uniform() * scale,
              offset + rng.uniform() * scale);
      Vec3f b = a;
      if (rng.next() % 3) b = b + Vec3f(rng.uniform(), rng.uniform(), 0) * scale;  // flat in z
      boxes[i] = Box3f(min(a, b), max(a, b));
      parent.extend(boxes[i]);
    }
    QuantBoxes8 q;
    quantize_boxes(parent, boxes, n, q);
    for (int i = 0; i < n; ++i) {
      Box3f d = dequantize_box(q, i);
      ASSERT_TRUE(d.contains(boxes[i])) << "iter " << iter << " child " << i;
    }
    for (int i = n; i < 8; ++i) {
      Box3f d = dequantize_box(q, i);
      EXPECT_TRUE(d.lo.x > d.hi.x && d.lo.y > d.hi.y && d.lo.z > d.hi.z) << "empty slot " << i;
    }
  }
}

TEST(Bvh, DuplicateAndDegenerateTriangles) {
  // Many identical triangles (no SAH split possible) and zero-area ones.
  PolyMesh m;
  for (int i = 0; i < 1000; ++i) {
    uint32_t b = uint32_t(m.positions.size());
    m.positions.push_back({0, 0, 0});
    m.positions.push_back({1, 0, 0});
    m.positions.push_back(i % 2 ? Vec3f(0, 1, 0) : Vec3f(2, 0, 0));  // odd: real, even: degenerate
    m.face_sizes.push_back(3);
    m.face_indices.insert(m.face_indices.end(), {b, b + 1, b + 2});
  }
  for (const char* c : {"bvh8-tri4v", "clbvh-tri4i"}) {
    Scene s = Scene::build(m, BuildOptions::from_config(c));
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    Ray r;
    r.org = Vec3f(0.25f, 0.25f, 1);
    r.dir = Vec3f(0, 0, -1);
    Hit h = s.intersect(r);
    ASSERT_TRUE(h.valid());
    EXPECT_EQ(h.primID % 2, 1u);
    EXPECT_FLOAT_EQ(h.t, 1.0f);
  }
}

}  // namespace
