// Compressed triangle clusters: `cluster` (lossy, one scene-wide lattice, a step per axis) and
// `cluster-lossless` (exact floats). Format: prim/cluster.h.
//
// Clusters come from the SAH BVH2, built with leaves of up to 64 triangles (the multi-leaf limit
// of the compressed-leaf BVH, 8 x 8) whose SAH cost counts one block per leaf, so that leaves
// come out near that size: every maximal subtree of at most 64 triangles (in practice a leaf) is
// one cluster (with BuildOptions::cluster_redivide, two such sibling clusters divide their
// triangles anew where that stores fewer vertices: ClusterReshaper::redivide). The binned SAH
// splits alone leave clusters of about 50 triangles (a node of 65 to 128 triangles becomes two
// clusters, whatever its count), so nodes of at most kFullClustersBelow triangles split at the
// nearest count that needs no extra cluster (the builder's full_blocks_below): 55-64 triangles a
// cluster on the benchmark scenes (61-64 on 11 of 13), each cluster's header, anchors, boxes and
// child table shared by more triangles. A cluster's triangles are re-split by SAH into at most 8
// leaves of at most 8 triangles (left sizes multiples of 8, so that ceil(n / 8) leaves suffice),
// and the collapse turns each such subtree into one multi-leaf whose data is the cluster
// (LeafEncoder::encode_multileaf). The inner nodes above the clusters are QBVH8 nodes with 32-bit
// child refs (bvh8.h CQNode8, 108 B instead of a Node8's 256 B), but for Node8 at the top of the
// tree, over kFloatNodePrims triangles or more.
#include <algorithm>
#include <array>
#include <cmath>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <unordered_map>

#include <tbb/parallel_for.h>

#include "api/bvh_scene.h"
#include "api/registry.h"
#include "core/simd.h"
#include "core/simd_ext.h"
#include "mesh/triangulate.h"
#include "prim/cluster.h"
#include "slimrt/clusters.h"

namespace slim {

namespace {

constexpr uint32_t kClusterMax = cluster::kMaxTriangles;  // bvh8.cpp multileaf_candidate
// BVH2 nodes of at most this many triangles split at counts that need no extra cluster
// (Bvh2BuildConfig::full_blocks_below).
constexpr uint32_t kFullClustersBelow = 16 * kClusterMax;
// Sibling clusters are divided anew (ClusterReshaper::redivide) only where their boxes grow by at
// most kRedivideGrowth in surface area, into clusters of at least kRedivideMinPart triangles (a
// full leaf: no cluster of a few triangles under a multi-leaf header of its own).
constexpr float kRedivideGrowth = 0.25f;
constexpr uint32_t kRedivideMinPart = 8;

// Re-cuts the BVH2 into clusters (see the file comment). The clusters are split and encoded in
// parallel; encode_multileaf then takes each cluster's block from ClusterSource::encoded.
class ClusterReshaper {
 public:
  ClusterReshaper(const Bvh2& in, ClusterSource& src, bool redivide)
      : in_(in), src_(src), redivide_(redivide) {}

  Bvh2 run() {
    Bvh2 out;
    if (in_.nodes.size() == 0) return out;
    count_.assign(in_.nodes.size(), 0);
    count(0);
    nodes_.push_back({});
    upper(0, 0, 0);
    if (redivide_) {
      given_.resize(roots_.size());
      tbb::parallel_for(size_t(0), pairs_.size(), [&](size_t p) { redivide(pairs_[p]); });
    }
    // Each cluster on its own: local nodes (index 0 = the cluster root) and prims.
    std::vector<Local> local(roots_.size());
    tbb::parallel_for(size_t(0), roots_.size(), [&](size_t c) {
      Local& l = local[c];
      // A thread's own, kept between clusters. The cluster's tree is split into `scratch` (room
      // for one leaf per triangle) and kept at its size: a reservation per cluster would spread
      // the clusters' few nodes over a page each.
      thread_local std::vector<uint32_t> v;
      thread_local std::vector<Item> items;
      thread_local Local scratch;
      v.clear();
      if (given_.empty() || given_[c].empty())
        collect(roots_[c].in, v);
      else
        v.swap(given_[c]);
      items.resize(v.size());
      for (size_t k = 0; k < v.size(); ++k) items[k] = item(v[k]);
      scratch.nodes.clear();
      scratch.prims.clear();
      scratch.nodes.reserve(2 * v.size());  // at most one leaf per triangle
      scratch.prims.reserve(v.size());
      scratch.nodes.push_back({});
      // A whole scene of at most 8 triangles is one leaf (no box test, as the other formats).
      const bool whole = roots_[c].depth == 0 && items.size() <= 8;
      l.depth = split(scratch, items, Orders(items), uint32_t(items.size()), -1, 0, !whole);
      l.nodes.assign(scratch.nodes.begin(), scratch.nodes.end());
      l.prims.assign(scratch.prims.begin(), scratch.prims.end());
      if (l.nodes.size() > 1) {  // a multi-leaf: its block, keyed by its first triangle
        // Children in depth-first order (the collapse's order): their prims are consecutive.
        const uint32_t* prims[8];
        uint32_t counts[8];
        int k = 0;
        for (uint32_t first = 0; first < l.prims.size(); ++k)
          for (const Bvh2Node& n : l.nodes)
            if (n.is_leaf() && n.first == first) {
              prims[k] = &l.prims[n.first];
              counts[k] = n.count;
              first += n.count;
              break;
            }
        l.block = cluster::encode(src_, prims, counts, k, false, true);
      } else if (l.prims.size() == 1 && src_.side_offsets) {  // an isolated triangle
        const uint32_t* prims = l.prims.data();
        const uint32_t one = 1;
        l.record = cluster::encode(src_, &prims, &one, 1, false);
      }
    });
    // Where each cluster's nodes (but its root, whose slot upper() left) and prims go: after the
    // nodes above the clusters and those of the clusters before it, as appending them one by one
    // would place them. Then each cluster is copied there (in parallel), and its block and prims
    // move into the source's cache.
    std::vector<uint32_t> nbase(roots_.size() + 1), pbase(roots_.size() + 1);
    nbase[0] = uint32_t(nodes_.size());
    pbase[0] = 0;
    size_t blocks = 0;
    for (size_t c = 0; c < roots_.size(); ++c) {
      const Local& l = local[c];
      nbase[c + 1] = nbase[c] + uint32_t(l.nodes.size()) - 1;
      pbase[c + 1] = pbase[c] + uint32_t(l.prims.size());
      blocks += !l.block.empty();
      depth_ = std::max(depth_, roots_[c].depth + l.depth);
    }
    out.nodes = LargeArray<Bvh2Node>(nbase.back());
    std::copy(nodes_.begin(), nodes_.end(), out.nodes.data());
    out.prim_ids = LargeArray<uint32_t>(pbase.back());
    tbb::parallel_for(size_t(0), roots_.size(), [&](size_t c) {
      const Local& l = local[c];
      const uint32_t node_base = nbase[c] - 1;  // local node k >= 1 goes to node_base + k
      for (size_t k = 0; k < l.nodes.size(); ++k) {
        Bvh2Node n = l.nodes[k];
        n.first += n.is_leaf() ? pbase[c] : node_base;
        out.nodes[k == 0 ? roots_[c].out : node_base + k] = n;
      }
      std::copy(l.prims.begin(), l.prims.end(), out.prim_ids.data() + pbase[c]);
    });
    src_.encoded->reserve(src_.encoded->size() + blocks);
    for (Local& l : local) {
      if (!l.record
               .empty()) {  // into the side arena in cluster order (ClusterSource::side_offsets)
        (*src_.side_offsets)[l.prims[0]] = src_.side->size();
        src_.side->insert(src_.side->end(), l.record.begin(), l.record.end());
      }
      if (!l.block.empty()) {
        const uint32_t key = l.prims[0];
        (*src_.encoded)[key] = {std::move(l.prims), std::move(l.block)};
      }
    }
    out.depth = depth_;
    return out;
  }

 private:
  // A triangle of a cluster: its box as two 4-wide rows (lane 3 = 0) and its center.
  struct Item {
    float lo[4], hi[4];
    float c[3];
    uint32_t prim;
  };
  // A box grown item by item: min/max with the item first, the operand order of
  // Box3f::extend's std::min/std::max (the same result for equal values, signed zeros too).
  struct Box4 {
    simd::vfloat4 lo{kInf}, hi{-kInf};
    SLIM_INLINE void extend(const Item& x) {
      lo = simd::min(simd::vfloat4::loadu(x.lo), lo);
      hi = simd::max(simd::vfloat4::loadu(x.hi), hi);
    }
    SLIM_INLINE void extend(const Box4& o) {
      lo = simd::min(o.lo, lo);
      hi = simd::max(o.hi, hi);
    }
    SLIM_INLINE Box3f box3() const {
      float l4[4], h4[4];
      lo.storeu(l4);
      hi.storeu(h4);
      return Box3f({l4[0], l4[1], l4[2]}, {h4[0], h4[1], h4[2]});
    }
  };
  struct Local {
    std::vector<Bvh2Node> nodes;
    std::vector<uint32_t> prims;
    std::vector<uint8_t> block;
    std::vector<uint8_t> record;  // an isolated triangle's side-arena record
    int depth = 0;
  };
  struct Root {
    uint32_t in, out;
    int depth;
  };
  const Bvh2& in_;
  ClusterSource& src_;
  bool redivide_;  // BuildOptions::cluster_redivide
  std::vector<uint32_t> count_;
  std::vector<Bvh2Node> nodes_;  // the nodes above the clusters
  std::vector<Root> roots_;
  // Sibling clusters (a node of 65..128 triangles whose two children are clusters): the roots_
  // index of each pair's first cluster, and (with the option) per root its triangles where
  // redivide() moved some.
  std::vector<uint32_t> pairs_;
  std::vector<std::vector<uint32_t>> given_;
  int depth_ = 0;

  uint32_t count(uint32_t i) {
    const Bvh2Node& n = in_.nodes[i];
    return count_[i] = n.is_leaf() ? n.count : count(n.first) + count(n.first + 1);
  }
  void collect(uint32_t i, std::vector<uint32_t>& v) const {
    const Bvh2Node& n = in_.nodes[i];
    if (n.is_leaf()) {
      for (uint32_t k = 0; k < n.count; ++k) v.push_back(in_.prim_ids[n.first + k]);
      return;
    }
    collect(n.first, v);
    collect(n.first + 1, v);
  }
  // Triangle t as an item: its box and center.
  Item item(uint32_t t) const {
    Box3f b;
    for (int k = 0; k < 3; ++k) b.extend(src_.vertices[src_.tris[3 * size_t(t) + k]]);
    const Vec3f m = b.center();
    return {{b.lo.x, b.lo.y, b.lo.z, 0.0f}, {b.hi.x, b.hi.y, b.hi.z, 0.0f}, {m.x, m.y, m.z}, t};
  }

  // The nodes above the clusters, each cluster root remembered for the parallel pass.
  void upper(uint32_t i, uint32_t idx, int depth) {
    const Bvh2Node& n = in_.nodes[i];
    if (count_[i] <= kClusterMax) {
      roots_.push_back({i, idx, depth});
      return;
    }
    if (n.is_leaf()) throw std::logic_error("cluster: BVH2 leaf beyond the cluster size");
    const uint32_t c = uint32_t(nodes_.size());
    nodes_[idx] = {n.box, c, 0};
    nodes_.resize(c + 2);
    depth_ = std::max(depth_, depth + 1);
    if (count_[n.first] <= kClusterMax && count_[n.first + 1] <= kClusterMax)
      pairs_.push_back(uint32_t(roots_.size()));
    upper(n.first, c, depth + 1);
    upper(n.first + 1, c + 1, depth + 1);
  }

  // Sibling clusters r and r + 1 divided anew where that stores fewer vertices. The SAH cuts space
  // by planes, so where a surface folds or thin parts lie side by side a cluster takes pieces that
  // share no edge, and the vertices on each piece's border are stored in both clusters that hold
  // its neighbours (ogre: 61% of the clusters hold two pieces or more). The pair's vertices (its
  // distinct codes, as the encoder counts them) are fixed; a division stores again those the two
  // clusters share. Here a growth over the surface orders the pair's triangles: from the triangle
  // lowest along the pair's widest axis, each step takes the triangle with the fewest vertices not
  // yet taken, then the lowest along the axis. The first s triangles become the first cluster and
  // the rest the second, s the cut (both parts kRedivideMinPart..kClusterMax triangles) that
  // shares the fewest vertices, if it shares fewer than the SAH's division and the two clusters'
  // boxes grow by at most kRedivideGrowth in surface area (their union, the parent's box, stays
  // the same).
  void redivide(uint32_t r) {
    constexpr uint32_t kMax = 2 * kClusterMax, kWords = kMax / 64;
    thread_local std::vector<uint32_t> t;
    t.clear();
    collect(roots_[r].in, t);
    const uint32_t na = uint32_t(t.size());
    collect(roots_[r + 1].in, t);
    const uint32_t n = uint32_t(t.size());
    // A pair's parent holds more than kClusterMax triangles, each child at most kClusterMax.
    if (n <= kClusterMax || n > kMax)
      throw std::logic_error("cluster: sibling pair of n triangles");
    const uint32_t lo = std::max(kRedivideMinPart, n - kClusterMax);
    const uint32_t hi = std::min(kClusterMax, n - kRedivideMinPart);
    // The pair's vertices numbered 0..m-1 by their codes in order of first sight, as the encoder
    // numbers a cluster's: vert[3i + k] triangle i's corner k.
    static_assert(3 * kMax <= cluster::CodeNumbering::kMaxVertices, "at most one vertex a corner");
    cluster::CodeNumbering numbering;
    uint16_t vert[3 * kMax];
    for (uint32_t i = 0; i < n; ++i)
      for (uint32_t k = 0; k < 3; ++k)
        vert[3 * i + k] =
            uint16_t(numbering.number(&src_.codes[3 * size_t(src_.tris[3 * size_t(t[i]) + k])]));
    const uint32_t m = numbering.size();
    // Per vertex its triangles, tri_of[first[v]..first[v + 1]) (a triangle once per corner).
    uint16_t first[3 * kMax + 1], tri_of[3 * kMax];
    std::fill(first, first + m + 1, uint16_t(0));
    for (uint32_t j = 0; j < 3 * n; ++j) ++first[vert[j] + 1];
    for (uint32_t v = 0; v < m; ++v) first[v + 1] = uint16_t(first[v + 1] + first[v]);
    {
      uint16_t at[3 * kMax];
      std::copy(first, first + m, at);
      for (uint32_t i = 0; i < n; ++i)
        for (uint32_t k = 0; k < 3; ++k) tri_of[at[vert[3 * i + k]]++] = uint16_t(i);
    }
    // The SAH's division shares the vertices of the second cluster that the first has.
    uint32_t fewest = 0;
    {
      bool in_first[3 * kMax];
      std::fill(in_first, in_first + m, false);
      for (uint32_t j = 0; j < 3 * na; ++j) in_first[vert[j]] = true;
      for (uint32_t j = 3 * na; j < 3 * n; ++j) fewest += std::exchange(in_first[vert[j]], false);
    }
    // The triangles as items (boxes, centers) and the SAH division's box areas.
    Item it[kMax];
    Box4 all, part[2];
    for (uint32_t i = 0; i < n; ++i) {
      it[i] = item(t[i]);
      all.extend(it[i]);
      part[i < na ? 0 : 1].extend(it[i]);
    }
    const float bound =
        (1.0f + kRedivideGrowth) * (part[0].box3().half_area() + part[1].box3().half_area());
    // The triangles by their centers on the pair's widest axis, ties by place: rank k is triangle
    // byc[k], triangle i has rank[i].
    const int axis = max_dim(all.box3().size());
    uint16_t byc[kMax], rank[kMax];
    sort_places([&](uint32_t i) { return it[i].c[axis]; }, n, byc);
    for (uint32_t k = 0; k < n; ++k) rank[byc[k]] = uint16_t(k);
    // The growth, hi steps. open[j]: bit k set while the triangle of rank k is not taken and has j
    // corners whose vertex is not taken (left[i]); rest[v]: vertex v's corners in triangles not
    // taken. After s steps the taken triangles share with the others the vertices taken less those
    // whose triangles are all taken: shared[s] = ntaken - nclosed.
    uint64_t open[4][kWords] = {};
    for (uint32_t k = 0; k < n; ++k) open[3][k / 64] |= uint64_t(1) << (k % 64);
    uint8_t left[kMax];
    std::fill(left, left + n, uint8_t(3));
    uint16_t rest[3 * kMax];
    for (uint32_t v = 0; v < m; ++v) rest[v] = uint16_t(first[v + 1] - first[v]);
    bool taken[3 * kMax], tri_taken[kMax] = {};
    std::fill(taken, taken + m, false);
    uint16_t order[kMax];  // the growth's triangles, then (from hi) the others in place order
    uint32_t ntaken = 0, nclosed = 0, shared[kMax + 1];
    for (uint32_t s = 0; s < hi; ++s) {
      uint32_t k = kMax;
      for (uint32_t j = 0; j < 4 && k == kMax; ++j)
        for (uint32_t w = 0; w < kWords; ++w)
          if (open[j][w]) {
            k = 64 * w + uint32_t(__builtin_ctzll(open[j][w]));
            break;
          }
      const uint32_t next = byc[k];
      open[left[next]][k / 64] &= ~(uint64_t(1) << (k % 64));
      order[s] = uint16_t(next);
      tri_taken[next] = true;
      for (uint32_t q = 0; q < 3; ++q) {
        const uint32_t v = vert[3 * next + q];
        nclosed += --rest[v] == 0;
        if (std::exchange(taken[v], true)) continue;
        ++ntaken;
        for (uint32_t j = first[v]; j < first[v + 1]; ++j) {
          const uint32_t i = tri_of[j], rk = rank[i];
          const uint64_t bit = uint64_t(1) << (rk % 64);
          if (!(open[left[i]][rk / 64] & bit)) continue;  // taken (next among them)
          open[left[i]][rk / 64] &= ~bit;
          open[--left[i]][rk / 64] |= bit;
        }
      }
      shared[s + 1] = ntaken - nclosed;
    }
    for (uint32_t i = 0, s = hi; i < n; ++i)
      if (!tri_taken[i]) order[s++] = uint16_t(i);
    // The cut: the fewest shared vertices (the first such) of the cuts whose boxes stay within the
    // bound. area[s]: the surface area of order[s, n)'s box, to which the second loop adds
    // order[0, s)'s.
    float area[kMax + 1];
    Box4 b;
    for (uint32_t s = n; s-- > lo;) {
      b.extend(it[order[s]]);
      area[s] = b.box3().half_area();
    }
    b = Box4();
    uint32_t best = 0;
    for (uint32_t s = 0; s < hi; ++s) {
      b.extend(it[order[s]]);
      if (s + 1 >= lo && shared[s + 1] < fewest && area[s + 1] + b.box3().half_area() <= bound) {
        fewest = shared[s + 1];
        best = s + 1;
      }
    }
    if (!best) return;
    for (uint32_t s = 0; s < n; ++s) given_[r + (s < best ? 0 : 1)].push_back(t[order[s]]);
  }

  // The ranks (below) of the places of G groups of 8 from group g0, into ranks[0, 8G): each place
  // j of the cluster's n is compared once with the G rows, whose counts stay in registers.
  template <int G>
  static SLIM_INLINE void count_ranks(const float* w, uint32_t n, uint32_t g0, float* ranks) {
    using simd::vfloat8;
    const vfloat8 one(1.0f);
    vfloat8 c[G], r[G];
    for (int q = 0; q < G; ++q) {
      c[q] = vfloat8::load(w + 8 * (g0 + q));
      r[q] = vfloat8(0.0f);
    }
    const uint32_t b = 8 * g0, e = std::min(n, b + 8 * G);
    // Places before the groups count a center at or below theirs, places after them one below.
    for (uint32_t j = 0; j < b; ++j) {
      const vfloat8 x(w[j]);
      for (int q = 0; q < G; ++q) r[q] = r[q] + simd::mask_zero(x <= c[q], one);
    }
    for (uint32_t j = e; j < n; ++j) {
      const vfloat8 x(w[j]);
      for (int q = 0; q < G; ++q) r[q] = r[q] + simd::mask_zero(x < c[q], one);
    }
    // Places among them: for the groups after j's one at or below, for those before it one below,
    // and in j's own group at or below in the lanes after j's, below in the others.
    for (uint32_t j = b; j < e; ++j) {
      const vfloat8 x(w[j]);
      const int qj = int((j - b) / 8);
      const simd::vbool8 after = simd::lanes_from_bits(0xfeu << ((j - b) % 8));
      for (int q = 0; q < G; ++q) {
        if (q < qj)
          r[q] = r[q] + simd::mask_zero(x < c[q], one);
        else if (q > qj)
          r[q] = r[q] + simd::mask_zero(x <= c[q], one);
        else
          r[q] = r[q] + simd::mask_zero((x < c[q]) | ((x == c[q]) & after), one);
      }
    }
    for (int q = 0; q < G; ++q) r[q].storeu(ranks + 8 * q);
  }

  // places[0, n) = the places 0..n-1 (n <= 2 kClusterMax) in the order of the values value(place),
  // ties by place: a sort of keys that order any float (cluster::float_key, NaN too; + 0.0f: -0
  // ties with +0, as float comparisons have it), independent of the standard library's sort.
  template <class Value, class Place>
  static void sort_places(const Value& value, uint32_t n, Place* places) {
    uint64_t key[2 * kClusterMax];
    for (uint32_t k = 0; k < n; ++k)
      key[k] = uint64_t(cluster::float_key(value(k) + 0.0f)) << 32 | k;
    std::sort(key, key + n);
    for (uint32_t k = 0; k < n; ++k) places[k] = Place(key[k]);
  }

  // Sorts `order` (indices of a cluster's n <= kClusterMax items) stably by `centers` (the items'
  // centers on one axis, by index): place k goes to its rank, the centers below its own plus
  // the equal ones at places before it, counted for up to 32 places a pass (count_ranks). Equal
  // centers (neighbouring triangles often share one) keep their order, so the clusters do not
  // depend on the standard library's sort. Counts up to 64 are exact in floats. Where the ranks
  // are not 0..n-1 once each (a NaN center), sort_places orders them instead.
  static void stable_order(const float* centers, uint8_t* order, uint32_t n) {
    constexpr uint32_t kPad = (kClusterMax + 7) / 8 * 8;
    static_assert(kPad <= 64, "ranks are bits of a 64-bit mask");
    alignas(32) float w[kPad];  // the centers in `order`'s order
    for (uint32_t k = 0; k < n; ++k) w[k] = centers[order[k]];
    const uint32_t groups = (n + 7) / 8;
    // The last group's lanes past n: loaded as count_ranks' rows (their ranks go unread), never
    // counted as places (j < n only).
    std::fill(w + n, w + 8 * groups, kInf);
    float ranks[kPad];
    for (uint32_t g0 = 0; g0 < groups;) {
      const uint32_t left = groups - g0;
      if (left >= 4) {
        count_ranks<4>(w, n, g0, ranks + 8 * g0);
        g0 += 4;
      } else if (left >= 2) {
        count_ranks<2>(w, n, g0, ranks + 8 * g0);
        g0 += 2;
      } else {
        count_ranks<1>(w, n, g0, ranks + 8 * g0);
        g0 += 1;
      }
    }
    uint64_t seen = 0;
    for (uint32_t k = 0; k < n; ++k)
      if (const uint32_t r = uint32_t(ranks[k]); r < n) seen |= uint64_t(1) << r;
    uint8_t out[kPad];
    if (seen == (n == 64 ? ~uint64_t(0) : (uint64_t(1) << n) - 1)) {
      for (uint32_t k = 0; k < n; ++k) out[uint32_t(ranks[k])] = order[k];
    } else {
      uint8_t place[2 * kClusterMax];  // sort_places' bound
      sort_places([&](uint32_t k) { return w[k]; }, n, place);
      for (uint32_t k = 0; k < n; ++k) out[k] = order[place[k]];
    }
    std::copy(out, out + n, order);
  }

  // A cluster's items (their indices) in the order of their centers on each axis: axis 0's ties
  // by index, axis 1's by axis 0's order, axis 2's by axis 1's.
  struct Orders {
    uint8_t by[3][kClusterMax];
    explicit Orders(const std::vector<Item>& it) {
      const uint32_t n = uint32_t(it.size());
      std::iota(by[0], by[0] + n, uint8_t(0));
      for (int a = 0; a < 3; ++a) {
        float centers[kClusterMax];
        for (uint32_t k = 0; k < n; ++k) centers[k] = it[k].c[a];
        if (a > 0) std::copy(by[a - 1], by[a - 1] + n, by[a]);
        stable_order(centers, by[a], n);
      }
    }
    Orders() = default;
  };

  // The node of the n items `o` into local node idx; returns the subtree depth. The cluster
  // root's orders are sorted (Orders), each child's are its parent's without the other child's
  // items, which keeps them sorted: no sort below the root. A leaf holds its items in the order of
  // `axis`, its parent's split axis (-1: at the cluster root, in the cluster's own order).
  int split(Local& l, const std::vector<Item>& it, const Orders& o, uint32_t n, int axis,
            uint32_t idx, bool root) const {
    static_assert(kClusterMax <= 64, "a node's items are bits of a 64-bit mask");
    Box4 grown;
    for (uint32_t k = 0; k < n; ++k) grown.extend(it[o.by[0][k]]);
    const Box3f box = grown.box3();
    if (n == 1 || (n <= 8 && !root)) {
      l.nodes[idx] = {box, uint32_t(l.prims.size()), n};
      for (uint32_t k = 0; k < n; ++k) l.prims.push_back(it[axis < 0 ? k : o.by[axis][k]].prim);
      return 0;
    }
    // SAH over the left sizes allowed: any when n <= 8 (the cluster root must be an inner node to
    // become a multi-leaf), else multiples of 8.
    const uint32_t unit = n <= 8 ? 1 : 8;
    float best = kInf;
    int best_axis = 0;
    uint32_t best_left = unit;
    // right[nl / unit]: the box of the sorted items nl..n-1, for the left sizes nl allowed.
    Box3f right[9];
    for (int a = 0; a < 3; ++a) {
      const uint8_t* by = o.by[a];
      auto consider = [&](uint32_t nl, const Box3f& left) {
        const float cost = left.half_area() * float((nl + 7) / 8) +
                           right[nl / unit].half_area() * float((n - nl + 7) / 8);
        if (cost < best) {
          best = cost;
          best_axis = a;
          best_left = nl;
        }
      };
      if (unit == 8) {
        // The left parts and right rests are unions of the boxes of the sorted items by 8s:
        // min and max do not depend on the order they meet the items in, so these are the
        // boxes of sweeps item by item (up to the sign of a zero, which no cost compares).
        const uint32_t nb = (n + 7) / 8;
        Box4 part[8];
        for (uint32_t k = 0; k < n; ++k) part[k / 8].extend(it[by[k]]);
        Box4 r;
        for (uint32_t j = nb; j-- > 1;) {
          r.extend(part[j]);
          right[j] = r.box3();
        }
        Box4 grown_left;
        for (uint32_t j = 0; j + 1 < nb; ++j) {
          grown_left.extend(part[j]);
          consider(8 * (j + 1), grown_left.box3());
        }
        continue;
      }
      Box4 r;
      for (uint32_t k = n; k-- > 1;) {
        r.extend(it[by[k]]);
        right[k] = r.box3();
      }
      Box4 grown_left;
      for (uint32_t k = 0; k + 1 < n; ++k) {
        grown_left.extend(it[by[k]]);
        consider(k + 1, grown_left.box3());
      }
    }
    // The children's orders: each axis's order split by side, kept in order.
    uint64_t in_left = 0;
    for (uint32_t k = 0; k < best_left; ++k) in_left |= uint64_t(1) << o.by[best_axis][k];
    Orders lo, ro;
    for (int a = 0; a < 3; ++a)
      for (uint32_t k = 0, nl = 0, nr = 0; k < n; ++k) {
        const uint8_t x = o.by[a][k];
        if ((in_left >> x) & 1)
          lo.by[a][nl++] = x;
        else
          ro.by[a][nr++] = x;
      }
    const uint32_t c = uint32_t(l.nodes.size());
    l.nodes[idx] = {box, c, 0};
    l.nodes.resize(c + 2);
    const int d0 = split(l, it, lo, best_left, best_axis, c, false);
    const int d1 = split(l, it, ro, n - best_left, best_axis, c + 1, false);
    return 1 + std::max(d0, d1);
  }
};

// A cluster scene: decodes its triangles from its clusters (built or opened from a file alike).
template <bool kLossless>
class ClusterScene : public BvhScene<ClusterLeaf<kLossless>> {
 public:
  using Leaf = ClusterLeaf<kLossless>;
  // Every open: the lattice fields the decoders take as given (anchor widths, steps), then the BVH.
  void check_opened(bool deep) const override {
    if (!kLossless) {
      size_t at = 0;
      const std::string bad = cluster::check_lattice(this->ctx.lattice, &at);
      if (!bad.empty()) throw SectionFault{"cluster.lattice", at, bad};
    }
    this->check_bvh("", deep);
  }
  // Every cluster's triangles, decoded as the traversal decodes them, in leaf order.
  std::optional<DecodedTriangles> decoded_triangles() const override {
    const typename Leaf::Context& c = this->ctx;
    DecodedTriangles out;
    auto append = [&](const uint8_t* data, uint32_t k, uint32_t i) {
      cluster::Decoded8 d;
      const cluster::View v = cluster::view<kLossless>(c.lattice, data, k);
      cluster::decode_child<kLossless>(c.lattice, v, int(i), d);
      for (int l = 0; l < d.n; ++l) {
        uint32_t geom, prim;
        cluster::decode_ids(v, uint32_t(d.first + l), geom, prim);
        for (int q = 0; q < 3; ++q)
          out.vertices.emplace_back(d.v[q][0][l], d.v[q][1][l], d.v[q][2][l]);
        out.geom.push_back(geom);
        out.face.push_back(prim);
      }
    };
    // The walk of validate(): the boxes are filled in as it expects them.
    auto leaf = [&](const uint8_t* block, Box3f& bounds, std::string*) {
      Leaf::visit(c, block, [&](const Box3f& box, uint64_t) { bounds.extend(box); });
      uint64_t off;
      std::memcpy(&off, block, 8);
      append(c.side + off, 1, 0);
      return true;
    };
    MultiLeafValidator multi = [&](const uint8_t* data, uint32_t k, uint32_t i, Box3f& bounds,
                                   std::string*) {
      Leaf::visit_in_multileaf(c, data, k, int(i),
                               [&](const Box3f& box, uint64_t) { bounds.extend(box); });
      append(data, k, i);
      return true;
    };
    std::string why;
    if (!validate_bvh8(this->bvh, leaf, &why, multi, this->multileaf_box_decoder()))
      throw Error("cluster scene: its leaves do not decode: " + why);
    return out;
  }
};

template <bool kLossless>
std::unique_ptr<Scene::Impl> build_with(TriangleMesh& tm, const BuildOptions& opt,
                                        const Box3f& lattice_box) {
  using Leaf = ClusterLeaf<kLossless>;
  auto s = std::make_unique<ClusterScene<kLossless>>();
  auto z = std::make_shared<cluster::Quantized>(
      cluster::quantize(tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                        opt.cluster_error, kLossless, lattice_box));
  const ClusterLattice& lat = z->lattice;
  auto side = std::make_shared<std::vector<uint8_t>>();
  std::mutex side_mutex;
  cluster::EncodeStats est;
  ClusterSource src;
  src.vertices = z->decoded.data();
  src.codes = z->codes.data();
  src.tris = tm.tris.data();
  src.geom_ids = tm.geom_ids.data();
  src.prim_ids = tm.prim_ids.data();
  src.lossless = kLossless;
  src.lattice = lat;
  src.side = side.get();
  src.side_mutex = &side_mutex;
  src.stats = &est;
  std::unordered_map<uint32_t, std::pair<std::vector<uint32_t>, std::vector<uint8_t>>> encoded;
  src.encoded = &encoded;
  std::unordered_map<uint32_t, uint64_t> side_offsets;
  src.side_offsets = &side_offsets;
  BuildOptions o = opt;
  o.nodes = Nodes::CompressedLeaf;
  o.max_leaf_size = 8;
  // The BVH2's leaves are the clusters: the SAH leaf cost counts whole clusters of up to 64
  // triangles, so leaves come out near that size; reshape then splits each into its children.
  typename BvhScene<Leaf>::Bvh2Hooks hooks;
  hooks.max_leaf_size = hooks.block_prims = kClusterMax;
  hooks.full_blocks_below = kFullClustersBelow;
  hooks.quantized_inner = true;
  hooks.reshape = [&](Bvh2& b2) {
    std::vector<uint32_t> dropped = std::move(b2.dropped);  // duplicates outside every cluster
    b2 = ClusterReshaper(b2, src, opt.cluster_redivide).run();
    b2.dropped = std::move(dropped);
  };
  s->build(src, uint32_t(tm.tri_count()), o, hooks);
  // The decoders' 64-bit loads may read up to kClusterReadSlack bytes past a cluster's data.
  s->bvh.leaves.append(kClusterReadSlack, 1);
  s->mem.geometry_bytes += kClusterReadSlack;
  side->resize(side->size() + kClusterReadSlack, 0);
  side->shrink_to_fit();
  s->ctx.lattice = lat;
  s->ctx.frame = cluster::lattice_frame(lat);
  s->ctx.side = side->data();
  s->ctx.side_bytes = side->size();
  s->ctx.cache_tag = cluster::next_cache_tag();  // the arenas no longer move
  s->keepalive = side;
  s->mem.geometry_bytes += side->size();
  s->error_bound = z->max_error;  // Scene::error_bound(); 0 for cluster-lossless

  const double tris = double(std::max<uint64_t>(est.triangles, 1));
  const double in_tris = double(std::max<uint64_t>(tm.input_triangles, 1));
  auto& d = s->stats.details;
  d.emplace_back("clusters", double(est.clusters));
  d.emplace_back("avg_triangles_per_cluster", est.clusters ? tris / double(est.clusters) : 0);
  d.emplace_back("vertices_per_triangle", double(est.vertices) / tris);
  d.emplace_back("geometry_bytes_per_triangle", double(s->mem.geometry_bytes) / in_tris);
  d.emplace_back("bvh_bytes_per_triangle", double(s->mem.bvh_bytes) / in_tris);
  d.emplace_back("position_bits_avg",
                 est.vertices ? double(est.position_bits) / (3.0 * double(est.vertices)) : 0);
  d.emplace_back("position_bits_per_triangle", double(est.position_bits) / tris);
  d.emplace_back("topology_bits_per_triangle", double(est.topology_bits) / tris);
  d.emplace_back("id_bits_per_triangle", double(est.id_bits) / tris);
  d.emplace_back("header_bits_per_triangle", double(est.header_bits) / tris);
  if (kLossless)  // clusters whose coordinates are decimals q x 10^-k (cluster.h, coordinate mode)
    d.emplace_back("decimal_cluster_fraction",
                   est.clusters ? double(est.decimal_clusters) / double(est.clusters) : 0.0);
  if (!kLossless)  // multi-leaves whose boxes take 8-bit planes (cluster.h, LatticeBoxes8)
    d.emplace_back(
        "fine_plane_fraction",
        est.plane_clusters ? double(est.fine_plane_clusters) / double(est.plane_clusters) : 0.0);
  for (int a = 0; a < 3; ++a)
    d.emplace_back(std::string("lattice_step_") + "xyz"[a], kLossless ? 0.0 : double(lat.step[a]));
  d.emplace_back("lattice_coarsened", z->coarsened ? 1.0 : 0.0);
  // Bits of a cluster's anchors (cluster.h: lossy, the lattice's per-axis widths; lossless, the
  // start floats the anchors are derived from).
  d.emplace_back(
      "anchor_bits",
      kLossless ? 96.0 : double(lat.anchor_bits[0] + lat.anchor_bits[1] + lat.anchor_bits[2]));
  d.emplace_back("max_error", z->max_error);
  d.emplace_back("max_error_diag_pct", z->diag > 0 ? 100.0 * z->max_error / z->diag : 0.0);
  d.emplace_back("rms_error", z->rms_error);
  // The lossy grids' names for the same figures (bench's error columns).
  d.emplace_back("diag_avg_pct", z->diag > 0 ? 100.0 * z->mean_error / z->diag : 0.0);
  d.emplace_back("diag_max_pct", z->diag > 0 ? 100.0 * z->max_error / z->diag : 0.0);
  return s;
}

}  // namespace

ClusterTriangles cluster_triangles(const std::vector<const PolyMesh*>& meshes,
                                   const BuildOptions& opt) {
  for (const PolyMesh* m : meshes) check_mesh(*m);
  if (opt.leaf != Leaf::Clusters && opt.leaf != Leaf::LosslessClusters)
    throw Error("cluster_triangles: " + opt.config_name() + " is not a cluster configuration");
  const Box3f lattice_box = opt.leaf == Leaf::Clusters ? lattice_box_of(meshes, opt) : Box3f();
  TriangleMesh tm = triangulate_fan(meshes);
  const cluster::Quantized z =
      cluster::quantize(tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
                        opt.cluster_error, opt.leaf == Leaf::LosslessClusters, lattice_box);
  ClusterTriangles t;
  t.vertices.reserve(3 * tm.tri_count());
  for (size_t i = 0; i < tm.tri_count(); ++i) {
    for (int k = 0; k < 3; ++k) t.vertices.push_back(z.decoded[tm.tris[3 * i + k]]);
    t.geom.push_back(tm.geom_ids[i]);
    t.face.push_back(tm.prim_ids[i]);
  }
  t.max_error = z.max_error;
  return t;
}

std::vector<uint32_t> cluster_face_order(const MeshView& mesh, const BuildOptions& opt) {
  if (opt.leaf != Leaf::Clusters && opt.leaf != Leaf::LosslessClusters)
    throw Error("cluster_face_order: " + opt.config_name() + " is not a cluster configuration");
  const Scene scene = Scene::build(mesh, opt);
  // The scene's own decode (Scene::decoded_triangles gives none for cluster-lossless, which
  // intersects the input's triangles).
  const std::optional<DecodedTriangles> t = scene.impl_->decoded_triangles();
  if (!t) throw Error("cluster_face_order: the scene does not decode its triangles");
  const size_t nf = mesh.face_count();
  std::vector<uint32_t> order;
  order.reserve(nf);
  std::vector<bool> seen(nf);
  for (const uint32_t f : t->face) {
    if (f >= nf) throw Error("cluster_face_order: the scene decodes face " + std::to_string(f));
    if (!seen[f]) order.push_back(f);
    seen[f] = true;
  }
  for (uint32_t f = 0; f < nf; ++f)
    if (!seen[f]) order.push_back(f);
  return order;
}

std::vector<uint32_t> cluster_face_order(const PolyMesh& mesh, const BuildOptions& opt) {
  return cluster_face_order(MeshView(mesh), opt);
}

std::unique_ptr<Scene::Impl> empty_cluster_scene(const BuildOptions& opt) {
  if (opt.leaf == Leaf::LosslessClusters) return std::make_unique<ClusterScene<true>>();
  return std::make_unique<ClusterScene<false>>();
}

std::unique_ptr<Scene::Impl> build_cluster_scene(const MeshList& meshes, const BuildOptions& opt) {
  const Box3f lattice_box = opt.leaf == Leaf::Clusters ? lattice_box_of(meshes, opt) : Box3f();
  TriangleMesh tm = triangulate_fan(meshes);
  std::unique_ptr<Scene::Impl> s = opt.leaf == Leaf::LosslessClusters
                                       ? build_with<true>(tm, opt, Box3f())
                                       : build_with<false>(tm, opt, lattice_box);
  s->set_input(tm.input_faces, tm.input_triangles, tm.skipped_faces);
  return s;
}

}  // namespace slim
