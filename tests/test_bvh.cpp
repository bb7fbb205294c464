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

// A leaf format of one axis-aligned box per block (id, box), for the collapse tests below: 16 KiB
// blocks (kBlockBytes) make a leaf arena beyond a CQNode8's reach from a few thousand primitives;
// a tree may also take smaller blocks (its block_bytes; Block is what intersect reads).
struct BigBoxLeaf {
  struct Context {};
  static constexpr uint32_t kBlockPrims = 1;
  static constexpr uint32_t kBlockBytes = 16384;
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

// n random small boxes in the unit cube, collapsed as the clusters' kind of tree
// (QCompressedLeaf) over BigBoxLeaf blocks of block_bytes each.
struct BoxTree {
  std::vector<PrimRef> refs;
  Bvh8 bvh;
  BoxTree(Rng& rng, uint32_t n, uint32_t block_bytes) : refs(n) {
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
    enc.block_bytes = block_bytes;
    enc.encode = [&](const uint32_t* prims, uint32_t, uint8_t* out) {
      const BigBoxLeaf::Block blk{prims[0], refs[prims[0]].box};
      std::memcpy(out, &blk, sizeof blk);
    };
    bvh = collapse_bvh8(b2, NodeKind::QCompressedLeaf, enc, CollapseRule::Optimal);
  }
};

// What every clusters' tree keeps to: each node aligned for its loads (Node8 64, QNode8 8,
// CQNode8 4 bytes), no Node8 below a quantized node and no QNode8 below a CQNode8, the nodes of
// each kind as counted in the stats, every ref counted once, the padding between nodes zero (scene
// files store the arena as it is), validate_bvh8, and traversal finding the same nearest box as a
// loop over all boxes (`rays` random rays). Returns the node counts of each kind (Node8, QNode8,
// CQNode8), the Node8 that follow padding (placed on a multiple of 64 from an offset that was
// not) and the rays that hit a box.
struct BoxTreeCounts {
  uint64_t nodes[3] = {};
  uint64_t padded_floats = 0;
  int hits = 0;
};
BoxTreeCounts check_box_tree(const BoxTree& t, Rng& rng, int rays) {
  BoxTreeCounts out;
  const Bvh8& bvh = t.bvh;
  EXPECT_EQ(bvh.node_bytes, bvh.stats.node8 * sizeof(Node8) + bvh.stats.cqnode8 * sizeof(CQNode8) +
                                (bvh.stats.qnode8 - bvh.stats.cqnode8) * sizeof(QNode8));
  uint64_t floats = 0, wide = 0, compact = 0;
  std::vector<uint8_t> is_node(bvh.nodes.size(), 0);
  // below: 0 under Node8 only, 1 under a QNode8, 2 under a CQNode8. Returns the primitives under
  // ref (one a block).
  std::function<uint64_t(uint64_t, int)> walk = [&](uint64_t ref, int below) -> uint64_t {
    const uint64_t off = NodeRef::offset(ref);
    const uint32_t tag = NodeRef::tag(ref);
    if (!is_node_tag(tag)) return NodeRef::blocks(ref);
    if (tag == kRefNode8) {
      ++floats;
      EXPECT_EQ(below, 0);
      EXPECT_EQ(off % 64, 0u);
    } else if (tag == kRefQNode8) {
      ++wide;
      EXPECT_LT(below, 2);
      EXPECT_EQ(off % 8, 0u);
    } else {
      ++compact;
      EXPECT_EQ(off % 4, 0u);
    }
    EXPECT_LE(off + node_size(tag), bvh.nodes.size());
    if (off + node_size(tag) > bvh.nodes.size()) return 0;
    std::fill_n(is_node.begin() + off, node_size(tag), 1);
    uint64_t child[8];
    child_refs(ref, bvh.nodes.data() + off, child);
    uint64_t prims = 0;
    for (uint64_t c : child)
      if (c) prims += walk(c, tag == kRefNode8 ? 0 : tag == kRefQNode8 ? 1 : 2);
    // A Node8 exactly where the node spans kFloatNodePrims primitives or more.
    EXPECT_EQ(tag == kRefNode8, prims >= kFloatNodePrims) << "node at " << off << ": " << prims;
    return prims;
  };
  EXPECT_EQ(walk(bvh.root, 0), t.refs.size());
  EXPECT_EQ(floats, bvh.stats.node8);
  EXPECT_EQ(compact, bvh.stats.cqnode8);
  EXPECT_EQ(wide + compact, bvh.stats.qnode8);
  out.nodes[0] = floats;
  out.nodes[1] = wide;
  out.nodes[2] = compact;
  uint64_t padding = 0;
  for (uint64_t i = 0; i < bvh.nodes.size(); ++i) {
    if (is_node[i]) continue;
    ++padding;
    if (bvh.nodes.data()[i] != 0) {
      ADD_FAILURE() << "padding byte " << i << " is not zero";
      break;
    }
  }
  EXPECT_EQ(padding, bvh.nodes.size() - bvh.node_bytes);
  std::function<void(uint64_t)> count_padded = [&](uint64_t ref) {
    if (!is_node_tag(NodeRef::tag(ref))) return;
    const uint64_t off = NodeRef::offset(ref);
    if (NodeRef::tag(ref) == kRefNode8 && off > 0 && !is_node[off - 1]) ++out.padded_floats;
    uint64_t child[8];
    child_refs(ref, bvh.nodes.data() + off, child);
    for (uint64_t c : child)
      if (c) count_padded(c);
  };
  count_padded(bvh.root);

  std::string why;
  const LeafValidator leaf = [](const uint8_t* block, Box3f& bounds, std::string*) {
    BigBoxLeaf::Block blk;
    std::memcpy(&blk, block, sizeof blk);
    bounds = blk.box;
    return true;
  };
  EXPECT_TRUE(validate_bvh8(bvh, leaf, &why)) << why;

  const Box3f all(Vec3f(0, 0, 0), Vec3f(1, 1, 1));
  const RaySetupBounds sb(bvh.bounds);
  for (int r = 0; r < rays; ++r) {
    const Ray ray = random_ray(rng, all);
    TravRay tr;
    EXPECT_TRUE(make_trav_ray(ray, sb, tr));
    float best = kInf;
    uint32_t best_id = kInvalidID;
    for (const PrimRef& p : t.refs) {
      const float d = BigBoxLeaf::entry(p.box, tr.org, tr.rdir, tr.tnear, tr.tfar);
      if (d < best) {
        best = d;
        best_id = p.id;
      }
    }
    Hit hit;
    NoStats st;
    const bool found = traverse_bvh8<BigBoxLeaf, false>(bvh, {}, tr, hit, st);
    EXPECT_EQ(found, best_id != kInvalidID) << "ray " << r;
    if (found) {
      ++out.hits;
      EXPECT_EQ(hit.primID, best_id) << "ray " << r;
      EXPECT_EQ(hit.t, best) << "ray " << r;
    }
    TravRay any;
    EXPECT_TRUE(make_trav_ray(ray, sb, any));
    Hit ah;
    EXPECT_EQ((traverse_bvh8<BigBoxLeaf, true>(bvh, {}, any, ah, st)), found) << "ray " << r;
  }
  return out;
}

// The clusters' kind of tree over a leaf arena larger than a CQNode8 reaches (16 MiB) from fewer
// primitives than a float node spans (kFloatNodePrims): the top nodes are wide QNode8 at multiples
// of 8 bytes, everything below them CQNode8.
TEST(Bvh, CompactNodesBelowWideOnes) {
  static_assert(1500 < kFloatNodePrims);
  Rng rng(5);
  const BoxTree t(rng, 1500, BigBoxLeaf::kBlockBytes);  // 1500 x 16 KiB of leaves: 24 MB
  ASSERT_GT(t.bvh.leaves.size(), kCQOffsetLimit);
  EXPECT_EQ(NodeRef::tag(t.bvh.root), kRefQNode8);
  const BoxTreeCounts c = check_box_tree(t, rng, 3000);
  EXPECT_EQ(c.nodes[0], 0u);
  EXPECT_GT(c.nodes[1], 0u);
  EXPECT_GT(c.nodes[2], c.nodes[1]);
  EXPECT_GT(c.hits, 100);
  EXPECT_GT(t.bvh.nodes.size(), t.bvh.node_bytes);  // the wide nodes' children padded to 8
}

// Over more primitives the top nodes are Node8: the root and every node over kFloatNodePrims
// primitives or more, at multiples of 64 bytes; the nodes below them CQNode8 (the leaves, 32-byte
// blocks, within a CQNode8's reach).
TEST(Bvh, FloatNodesAtTheTop) {
  Rng rng(6);
  const uint32_t n = 8 * kFloatNodePrims + 1000;
  const BoxTree t(rng, n, 32);
  ASSERT_LT(t.bvh.leaves.size(), kCQOffsetLimit);
  EXPECT_EQ(NodeRef::tag(t.bvh.root), kRefNode8);
  const BoxTreeCounts c = check_box_tree(t, rng, 1000);
  // At least the root and, of its at most 8 children, one over n / 8 > kFloatNodePrims.
  EXPECT_GE(c.nodes[0], 2u);
  EXPECT_EQ(c.nodes[1], 0u);
  EXPECT_GT(c.nodes[2], 8 * c.nodes[0]);
  EXPECT_GT(c.padded_floats, 0u);  // a float node after a sibling's CQNode8 subtree
  EXPECT_GT(c.hits, 500);
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

// The box tests never cull a box by rounding (core/ray.h's margin): rays aimed at edges of child
// boxes (the grazing cases), from near and far, with segments of several kinds, against a
// double-precision slab test of the same boxes. The quantized test and the float test of the
// dequantized boxes both report every box the ray meets, at an entry distance no later than the
// exact one.
TEST(Bvh, BoxTestsNeverCullByRounding) {
  Rng rng(23);
  auto uniform3 = [&] {  // x, y, z drawn in this order
    const float x = rng.uniform(), y = rng.uniform(), z = rng.uniform();
    return Vec3f(x, y, z);
  };
  int grazing = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    const float scale = std::pow(10.0f, float(int(rng.next() % 10) - 4));
    const float offset = (rng.uniform() - 0.5f) * scale * float(rng.next() % 2 ? 1e4 : 1);
    Box3f boxes[8];
    Box3f parent;
    const int n = 1 + rng.next() % 8;
    for (int i = 0; i < n; ++i) {
      const Vec3f a = Vec3f(offset, offset, offset) + uniform3() * scale;
      Vec3f extent = uniform3();
      if (rng.next() % 3 == 0) extent.z = 0.0f;  // flat in z
      const Vec3f b = a + extent * (scale * 0.3f);
      boxes[i] = Box3f(min(a, b), max(a, b));
      parent.extend(boxes[i]);
    }
    QuantBoxes8 q;
    quantize_boxes(parent, boxes, n, q);
    Node8 f;
    Box3f deq[8];
    for (int i = 0; i < 8; ++i) {
      deq[i] = dequantize_box(q, i);
      for (int a = 0; a < 3; ++a) {
        f.bounds[2 * a][i] = i < n ? deq[i].lo[a] : kInf;
        f.bounds[2 * a + 1][i] = i < n ? deq[i].hi[a] : -kInf;
      }
    }
    const RaySetupBounds sb(parent);
    for (int r = 0; r < 20; ++r) {
      // A target on an edge of a child box: two coordinates on its planes, one anywhere along it.
      const Box3f& c = deq[rng.next() % n];
      Vec3f target;
      const int along = rng.next() % 3;
      for (int a = 0; a < 3; ++a)
        target[a] = a == along ? c.lo[a] + rng.uniform() * (c.hi[a] - c.lo[a])
                               : (rng.next() % 2 ? c.lo[a] : c.hi[a]);
      const float reach = scale * (rng.next() % 4 ? 2.0f : 100.0f);
      Ray ray;
      ray.org = target + (uniform3() - Vec3f(0.5f, 0.5f, 0.5f)) * (2.0f * reach);
      ray.dir = target - ray.org;
      if (rng.next() % 4 == 0) ray.dir[rng.next() % 3] = 0.0f;  // parallel to one slab
      // The target lies at t = 1: segments from 0, from behind the origin (clamped to 0), from
      // ahead of it, and ending near the target.
      const uint32_t segment = rng.next() % 4;
      ray.tnear = segment == 1 ? -rng.uniform() : segment == 2 ? rng.uniform() : 0.0f;
      ray.tfar = segment == 3 ? 0.5f + rng.uniform() : kInf;
      TravRay tr;
      if (!make_box_ray(ray, sb, tr)) continue;
      simd::vfloat8 dq, df;
      const uint32_t mq = detail::intersect_quant8(&q, tr, dq);
      const uint32_t mf = detail::intersect_node8(&f, tr, df);
      alignas(32) float tq[8], tf[8];
      dq.store(tq);
      df.store(tf);
      for (int i = 0; i < n; ++i) {
        double t0 = std::max(0.0, double(ray.tnear)), t1 = ray.tfar;
        for (int a = 0; a < 3; ++a) {
          const double o = ray.org[a], d = ray.dir[a];
          if (d == 0.0) {
            if (o < deq[i].lo[a] || o > deq[i].hi[a]) t0 = 1.0, t1 = 0.0;
            continue;
          }
          const double ta = (double(deq[i].lo[a]) - o) / d, tb = (double(deq[i].hi[a]) - o) / d;
          t0 = std::max(t0, std::min(ta, tb));
          t1 = std::min(t1, std::max(ta, tb));
        }
        if (!(t0 <= t1)) continue;
        grazing += t0 == t1;
        ASSERT_TRUE(mq >> i & 1) << "quantized box " << i << " culled, iter " << iter;
        ASSERT_TRUE(mf >> i & 1) << "float box " << i << " culled, iter " << iter;
        ASSERT_LE(tq[i], t0) << "quantized box " << i << ": entry after the exact one, iter "
                             << iter;
        ASSERT_LE(tf[i], t0) << "float box " << i << ": entry after the exact one, iter " << iter;
      }
    }
  }
  EXPECT_GT(grazing, 0) << "no ray met a box in a single point";
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
