// BVH8 + triangle leaves against the double-precision brute-force reference.
#include <gtest/gtest.h>

#include "bvh/bvh8.h"
#include "bvh/traverse.h"
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

// A leaf format of one axis-aligned box per 4 KiB block (id, box), for the collapse test below:
// big blocks make a leaf arena beyond a CQNode8's reach from a few thousand primitives.
struct BigBoxLeaf {
  struct Context {};
  static constexpr uint32_t kBlockPrims = 1;
  static constexpr uint32_t kBlockBytes = 4096;
  struct Block {
    uint32_t id;
    Box3f box;
  };
  // Entry distance of the ray into the box, or +inf (the same float operations as the reference).
  static float entry(const Box3f& b, const Vec3f& org, const Vec3f& rdir, float tnear, float tfar) {
    float t0 = tnear, t1 = tfar;
    for (int a = 0; a < 3; ++a) {
      float u = (b.lo[a] - org[a]) * rdir[a], w = (b.hi[a] - org[a]) * rdir[a];
      t0 = std::max(t0, std::min(u, w));
      t1 = std::min(t1, std::max(u, w));
    }
    return t0 <= t1 ? t0 : kInf;
  }
  template <bool kAny, class Stats>
  static bool intersect(const Context&, const uint8_t* block, TravRay& ray, Hit& hit, Stats&) {
    Block blk;
    std::memcpy(&blk, block, sizeof blk);
    const float t = entry(blk.box, ray.org, ray.rdir, ray.tnear, ray.tfar);
    if (!(t < ray.tfar)) return false;
    ray.tfar = hit.t = t;
    hit.primID = blk.id;
    hit.geomID = 0;
    return true;
  }
};

// The clusters' kind of tree (QCompressedLeaf) over a leaf arena larger than a CQNode8 reaches
// (16 MiB): the top nodes are wide QNode8 at multiples of 8 bytes, everything below them CQNode8,
// and traversal finds the same nearest box as a loop over all boxes.
TEST(Bvh, CompactNodesBelowWideOnes) {
  Rng rng(5);
  const uint32_t n = 6000;  // 6000 x 4 KiB of leaves: 24 MB
  std::vector<PrimRef> refs(n);
  for (uint32_t i = 0; i < n; ++i) {
    const Vec3f c(rng.uniform(), rng.uniform(), rng.uniform());
    const Vec3f h(0.001f + 0.004f * rng.uniform(), 0.001f + 0.004f * rng.uniform(),
                  0.001f + 0.004f * rng.uniform());
    refs[i] = {Box3f(c - h, c + h), i};
  }
  Bvh2BuildConfig cfg;
  cfg.max_leaf_size = 1;
  cfg.block_prims = 1;
  const Bvh2 b2 = build_bvh2(refs, cfg);
  LeafEncoder enc;
  enc.block_prims = 1;
  enc.block_bytes = BigBoxLeaf::kBlockBytes;
  enc.encode = [&](const uint32_t* prims, uint32_t, uint8_t* out) {
    const BigBoxLeaf::Block blk{prims[0], refs[prims[0]].box};
    std::memcpy(out, &blk, sizeof blk);
  };
  const Bvh8 bvh = collapse_bvh8(b2, NodeKind::QCompressedLeaf, enc, CollapseRule::Optimal);
  ASSERT_GT(bvh.leaves.size(), kCQOffsetLimit);
  EXPECT_GT(bvh.stats.cqnode8, 0u);
  EXPECT_LT(bvh.stats.cqnode8, bvh.stats.qnode8);
  EXPECT_EQ(bvh.node_bytes, bvh.stats.cqnode8 * sizeof(CQNode8) +
                                (bvh.stats.qnode8 - bvh.stats.cqnode8) * sizeof(QNode8));
  EXPECT_EQ(NodeRef::tag(bvh.root), kRefQNode8);

  // Every node aligned for its loads, no wide node below a compact one, every ref counted once,
  // the padding between nodes zero (scene files store the arena as it is).
  uint64_t wide = 0, compact = 0;
  std::vector<uint8_t> is_node(bvh.nodes.size(), 0);
  std::function<void(uint64_t, bool)> walk = [&](uint64_t ref, bool below_compact) {
    const uint64_t off = NodeRef::offset(ref);
    const uint32_t tag = NodeRef::tag(ref);
    if (tag != kRefQNode8 && tag != kRefCQNode8) return;
    if (tag == kRefQNode8) {
      ++wide;
      EXPECT_FALSE(below_compact);
      EXPECT_EQ(off % 8, 0u);
    } else {
      ++compact;
      EXPECT_EQ(off % 4, 0u);
    }
    ASSERT_LE(off + node_size(tag), bvh.nodes.size());
    std::fill_n(is_node.begin() + off, node_size(tag), 1);
    uint64_t child[8];
    child_refs(ref, bvh.nodes.data() + off, child);
    for (uint64_t c : child)
      if (c) walk(c, tag == kRefCQNode8);
  };
  walk(bvh.root, false);
  EXPECT_EQ(compact, bvh.stats.cqnode8);
  EXPECT_EQ(wide + compact, bvh.stats.qnode8);
  uint64_t padding = 0;
  for (uint64_t i = 0; i < bvh.nodes.size(); ++i) {
    if (is_node[i]) continue;
    ++padding;
    ASSERT_EQ(bvh.nodes.data()[i], 0) << "padding byte " << i;
  }
  EXPECT_EQ(padding, bvh.nodes.size() - bvh.node_bytes);
  EXPECT_GT(padding, 0u);

  std::string why;
  const LeafValidator leaf = [](const uint8_t* block, Box3f& bounds, std::string*) {
    BigBoxLeaf::Block blk;
    std::memcpy(&blk, block, sizeof blk);
    bounds = blk.box;
    return true;
  };
  ASSERT_TRUE(validate_bvh8(bvh, leaf, &why)) << why;

  const Box3f all(Vec3f(0, 0, 0), Vec3f(1, 1, 1));
  const RaySetupBounds sb(bvh.bounds);
  int hits = 0;
  for (int r = 0; r < 3000; ++r) {
    const Ray ray = random_ray(rng, all);
    TravRay tr;
    ASSERT_TRUE(make_trav_ray(ray, sb, tr));
    float best = kInf;
    uint32_t best_id = kInvalidID;
    for (const PrimRef& p : refs) {
      const float t = BigBoxLeaf::entry(p.box, tr.org, tr.rdir, tr.tnear, tr.tfar);
      if (t < best) {
        best = t;
        best_id = p.id;
      }
    }
    Hit hit;
    NoStats st;
    const bool found = traverse_bvh8<BigBoxLeaf, false>(bvh, {}, tr, hit, st);
    ASSERT_EQ(found, best_id != kInvalidID) << "ray " << r;
    if (found) {
      ++hits;
      EXPECT_EQ(hit.primID, best_id) << "ray " << r;
      EXPECT_EQ(hit.t, best) << "ray " << r;
    }
    TravRay any;
    ASSERT_TRUE(make_trav_ray(ray, sb, any));
    Hit ah;
    EXPECT_EQ((traverse_bvh8<BigBoxLeaf, true>(bvh, {}, any, ah, st)), found) << "ray " << r;
  }
  EXPECT_GT(hits, 500);
}

// cq_child_ref: the tag and block count as stored, the offset after the node (inner nodes) or
// after the leaf base (leaves), for every tag.
TEST(Bvh, CompactRefsExpand) {
  Rng rng(3);
  for (int iter = 0; iter < 2000; ++iter) {
    const uint32_t c = std::max(uint32_t(rng.next()), 1u);  // non-zero
    const uint64_t off = (uint64_t(rng.next()) << 8) + rng.next() % 256,
                   leaf = uint64_t(rng.next() % (1u << 31)) * kCQLeafBaseUnit;
    const uint64_t r = cq_child_ref(c, off, leaf);
    EXPECT_EQ(NodeRef::tag(r), c & 7);
    EXPECT_EQ(NodeRef::blocks(r), (c >> 3) & 31);
    const bool node = (c & 7) == kRefNode8 || (c & 7) == kRefQNode8 || (c & 7) == kRefCQNode8;
    EXPECT_EQ(NodeRef::offset(r), (node ? off : leaf) + (c >> 8)) << std::hex << c;
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
