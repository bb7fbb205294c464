// BVH2 -> BVH8 collapse and the node encodings of bvh8.h.
#include "bvh/bvh8.h"

#include "core/assert.h"
#include "core/progress.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <new>
#include <stdexcept>
#include <string>
#include <unordered_map>

#include <tbb/task_group.h>

#include "core/large_array.h"

namespace slim {

// ---- AlignedBytes ---------------------------------------------------------------------------

void AlignedBytes::reserve(uint64_t n) {
  if (n <= cap_ && owned_) return;
  n = std::max(n, size_);
  uint64_t cap = (n + 63) & ~uint64_t(63);
  auto* p = static_cast<uint8_t*>(large_alloc(cap, 64, /*kept=*/true));  // a scene's arena
  if (size_) std::memcpy(p, data_, size_);
  if (owned_) std::free(data_);
  data_ = p;
  cap_ = cap;
  owned_ = true;
}

uint64_t AlignedBytes::append(uint64_t n, uint64_t align, bool zero) {
  uint64_t off = (size_ + align - 1) & ~(align - 1);
  if (off + n > cap_) reserve(std::max(off + n, cap_ + cap_ / 2 + 4096));
  if (zero && off + n > size_)
    std::memset(data_ + size_, 0, off + n - size_);  // data_ may be null if 0
  size_ = off + n;
  return off;
}

void AlignedBytes::shrink_to_fit() {
  if (cap_ == ((size_ + 63) & ~uint64_t(63))) return;
  AlignedBytes t;
  t.reserve(size_);
  if (size_) std::memcpy(t.data_, data_, size_);
  t.size_ = size_;
  swap(t);
}

// ---- collapse -------------------------------------------------------------------------------

namespace {

// Statistics of one subtree of the BVH8, summed over the children in order, so that the figures
// are the same for any number of threads.
// The Bvh8Stats counts (sah_cost summed, leaf_fill unused) and the Bvh8 byte counts.
struct SubtreeStats {
  Bvh8Stats st;
  uint64_t node_bytes = 0, multileaf_bytes = 0, leaf_data_bytes = 0;
  void add(const SubtreeStats& o) {
    st.node8 += o.st.node8;
    st.qnode8 += o.st.qnode8;
    st.cqnode8 += o.st.cqnode8;
    st.multileaf += o.st.multileaf;
    st.leaves += o.st.leaves;
    st.leaf_blocks += o.st.leaf_blocks;
    st.leaves_in_multileaf += o.st.leaves_in_multileaf;
    st.prims += o.st.prims;
    st.sah_cost += o.st.sah_cost;
    st.depth = std::max(st.depth, o.st.depth);
    node_bytes += o.node_bytes;
    multileaf_bytes += o.multileaf_bytes;
    leaf_data_bytes += o.leaf_data_bytes;
  }
};

// Two passes: measure() walks the BVH8 that the collapse will produce (no leaf data is written)
// and records every subtree's byte sizes and the statistics; emit() then writes nodes and leaves
// at their precomputed offsets. Both run large subtrees as parallel tasks. The arenas are not
// cleared beforehand: emit() zeroes each node and leaf range right before it fills it, so that
// the first touch of the memory (its page faults) is spread over the threads too. The layout is
// depth-first in both arenas (a node's children follow it), identical to a serial collapse.
class Collapser {
 public:
  Collapser(const Bvh2& b2, NodeKind kind, const LeafEncoder& enc, CollapseRule rule, Bvh8& out,
            PhaseProgress* progress)
      : b2_(b2), kind_(kind), enc_(enc), rule_(rule), out_(out), progress_(progress) {}

  void run() {
    out_.block_bytes = enc_.block_bytes;
    if (b2_.nodes.empty()) {
      out_.root = NodeRef::make(kRefEmpty, 0);
      return;
    }
    // Subtree figures bottom-up (children always have larger indices than their parent).
    const size_t nn = b2_.nodes.size();
    // Every entry is written below (core/large_array.h: no zero fill of fresh pages).
    prims_ = LargeArray<uint32_t>(nn);
    leaves_ = LargeArray<uint32_t>(nn);
    max_leaf_ = LargeArray<uint32_t>(nn);
    for (size_t i = nn; i-- > 0;) {
      const Bvh2Node& n = b2_.nodes[i];
      if (n.is_leaf()) {
        prims_[i] = n.count;
        leaves_[i] = 1;
        max_leaf_[i] = n.count;
      } else {
        prims_[i] = prims_[n.first] + prims_[n.first + 1];
        leaves_[i] = leaves_[n.first] + leaves_[n.first + 1];
        max_leaf_[i] = std::max(max_leaf_[n.first], max_leaf_[n.first + 1]);
      }
    }
    optimal_ = rule_ == CollapseRule::Optimal;
    out_.bounds = b2_.nodes[0].box;
    root_area_ = std::max(out_.bounds.half_area(), 1e-30f);
    if (optimal_) {
      optimal_collapse();
    } else {
      // Child slots of each subtree if flattened into one wide node (a leaf or a multi-leaf
      // candidate takes one), for gather().
      slots_ = LargeArray<uint32_t>(nn);
      for (size_t i = nn; i-- > 0;) {
        const Bvh2Node& n = b2_.nodes[i];
        slots_[i] = n.is_leaf() || multileaf_candidate(uint32_t(i))
                        ? 1
                        : slots_[n.first] + slots_[n.first + 1];
      }
    }
    // Written by measure() for every node it visits, which are the only ones read (no serial
    // zero fill of 16 bytes per node: 26 MB on fg_terrain_hawaii).
    node_size_ = LargeArray<uint64_t>(nn);
    leaf_size_ = LargeArray<uint64_t>(nn);
    const SubtreeStats m = measure(0, 1);
    Bvh8Stats& s = out_.stats;
    s = m.st;
    out_.node_bytes = m.node_bytes;
    out_.multileaf_bytes = m.multileaf_bytes;
    out_.leaf_data_bytes = m.leaf_data_bytes;
    // CQNode8::leaf_base is 32 bits of kCQLeafBaseUnit bytes.
    if (kind_ == NodeKind::QCompressedLeaf &&
        leaf_size_[0] / kCQLeafBaseUnit >= (uint64_t(1) << 32))
      throw std::length_error("BVH leaf arena beyond 256 GiB");
    out_.nodes.append(node_size_[0], 64, false);
    out_.leaves.append(leaf_size_[0], 64, false);
    out_.root = emit(0, 0, 0);
    s.leaf_fill = s.leaf_blocks ? double(s.prims) / double(s.leaf_blocks * enc_.block_prims) : 0;
  }

 private:
  // Leaf and multi-leaf sizes: multiples of LeafEncoder::leaf_align (16 unless the layout reads
  // its leaves at any multiple of less: padding to 4 would cost the clusters 1.5 bytes a cluster,
  // to 16 the Costa leaves 8 bytes a leaf).
  uint64_t round_leaf(uint64_t x) const {
    return (x + enc_.leaf_align - 1) & ~uint64_t(enc_.leaf_align - 1);
  }

  // fn(c) for c = 0..k-1: as parallel tasks if the subtree of node i is large (and `parallel`).
  template <class F>
  void for_children(uint32_t i, int k, F&& fn, bool parallel = true) const {
    if (parallel && prims_[i] >= kParallelEmit) {
      tbb::task_group tg;
      for (int c = 1; c < k; ++c) tg.run([&fn, c] { fn(c); });
      fn(0);
      tg.wait();
    } else {
      for (int c = 0; c < k; ++c) fn(c);
    }
  }
  bool quantized_nodes() const {
    return kind_ == NodeKind::QBvh8 || kind_ == NodeKind::QCompressedLeaf;
  }
  // Inner node i of the clusters' trees is a Node8 when it spans kFloatNodePrims primitives or
  // more (bvh8.h).
  bool float_node(uint32_t i) const {
    return kind_ == NodeKind::QCompressedLeaf && prims_[i] >= kFloatNodePrims;
  }
  bool quantized_node(uint32_t i) const { return quantized_nodes() && !float_node(i); }
  // Whether inner node i over kids[0..k) is a CQNode8: in the clusters' trees where it is not a
  // float node and its children's offsets fit (a subtree under kFloatNodePrims clusters' triangles
  // holds far less than a CQNode8 reaches); else a QNode8 (quantized_node) or Node8.
  bool compact(uint32_t i, const uint32_t* kids, int k) const {
    if (kind_ != NodeKind::QCompressedLeaf || float_node(i)) return false;
    uint64_t nb = 0, lb = 0;
    for (int c = 0; c < k; ++c) {
      nb += node_size_[kids[c]];
      lb += leaf_size_[kids[c]];
    }
    return cq_fits(nb, lb);
  }
  uint32_t node_bytes(bool compact, uint32_t i) const {
    return compact ? sizeof(CQNode8) : quantized_node(i) ? sizeof(QNode8) : sizeof(Node8);
  }
  // The offset of the subtree of child `kid` at or after `off` (its parent compact or not): a
  // float node of the clusters' trees on a multiple of 64 (Node8's alignment: its siblings'
  // CQNode8 subtrees end on multiples of 4); a wide node's other children on multiples of 8 (a
  // QNode8's refs are 8 bytes; the CQNode8 of a subtree are multiples of 4 bytes). A Node8 tree's
  // nodes are 256 bytes each: always on multiples of 64.
  uint64_t child_node_off(uint64_t off, bool compact, uint32_t kid) const {
    if (float_node(kid) && node_size_[kid] > 0) return (off + 63) & ~uint64_t(63);
    return compact ? off : (off + 7) & ~uint64_t(7);
  }

  bool multileaf_candidate(uint32_t i) const {
    if (kind_ != NodeKind::CompressedLeaf && kind_ != NodeKind::QCompressedLeaf) return false;
    if (b2_.nodes[i].is_leaf()) return false;
    // Benthin et al. 2018, section 4.3 "Builder Modifications": subtrees of fewer than N x M
    // primitives; each of their (at most 8) leaves must fit one block so that child blocks are
    // addressed implicitly.
    // The clusters (QCompressedLeaf) take 8 full leaves too: 64 triangles, 8 x 8 in the
    // clusters' 8-wide tests.
    const uint64_t most = 8 * enc_.block_prims - (kind_ == NodeKind::QCompressedLeaf ? 0 : 1);
    return prims_[i] <= most && leaves_[i] * enc_.parts_per_block <= 8 &&
           max_leaf_[i] <= enc_.block_prims;
  }

  // Up to 8 BVH2 nodes below node i. Opening the largest-area inner child until there are 8
  // (the usual greedy collapse) leaves the slack at the bottom: a balanced BVH2 of 2^19 leaves
  // becomes 2^18 wide nodes of 2 leaves each. So the slots are spent where the tree needs them:
  // with S = slots_[i] and cap = the largest power of 8 below S (the children of a complete
  // 8-wide tree of the smallest height that holds S), first every child with more than cap slots
  // is opened (largest area first); then, with slots left, children whose whole subtree fits the
  // slots left are flattened into this node, largest area first. Bottom nodes are then full, and
  // the slack sits in the few nodes at the top.
  int gather(uint32_t i, uint32_t* kids) const {
    const Bvh2Node& n = b2_.nodes[i];
    int k = 0;
    if (optimal_) {
      expand(n.first, wide_[i][0], kids, k);
      expand(n.first + 1, wide_[i][1], kids, k);
      return k;
    }
    kids[k++] = n.first;
    kids[k++] = n.first + 1;
    uint64_t cap = 1;
    while (cap * 8 < slots_[i]) cap *= 8;
    auto openable = [&](uint32_t c) { return !b2_.nodes[c].is_leaf() && !multileaf_candidate(c); };
    auto open_best = [&](auto&& eligible) {
      int best = -1;
      float best_area = -1.0f;
      for (int c = 0; c < k; ++c) {
        if (!openable(kids[c]) || !eligible(kids[c])) continue;
        const float a = b2_.nodes[kids[c]].box.half_area();
        if (a > best_area) {
          best_area = a;
          best = c;
        }
      }
      if (best < 0) return false;
      const uint32_t open = kids[best];
      kids[best] = b2_.nodes[open].first;
      kids[k++] = b2_.nodes[open].first + 1;
      return true;
    };
    while (k < 8 && open_best([&](uint32_t c) { return slots_[c] > cap; })) {
    }
    while (k < 8 && open_best([&](uint32_t c) { return slots_[c] <= uint32_t(8 - k + 1); })) {
    }
    return k;
  }

  // SAH-optimal wide nodes for the given BVH2 (H. Ylitie, T. Karras, S. Laine, "Efficient
  // Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", HPG 2017, section 4.1), with
  // the BVH2's leaves and multi-leaf candidates as the terminals (their contents are fixed).
  // cost(n, j) = the least SAH cost of covering subtree n by at most j roots: one root is n
  // itself (a leaf, a multi-leaf, or a wide node over the best 8-root cover of its children),
  // more roots split j between the two children. Costs as sah_cost counts them: node or
  // multi-leaf visit = 1, leaf block test = 1, areas relative to the root, and a wide node's
  // memory node_cost_ (0 but for the clusters: kClusterNodeCost). choice_[n][j-1] = the roots
  // (left, right) of that cover, (0, 0) for n itself; wide_[n] = those of the 8-root cover of n's
  // children when n is a wide node. Used instead of the slot rule of gather() by the rule
  // CollapseRule::Optimal (see run()).
  void optimal_collapse() {
    // Written for the inner nodes only (expand() stops at terminals without reading them): no
    // zero fill of 18 bytes per node.
    const size_t nn = b2_.nodes.size();
    choice_ = LargeArray<std::array<std::array<uint8_t, 2>, 8>>(nn);
    wide_ = LargeArray<std::array<uint8_t, 2>>(nn);
    if (kind_ == NodeKind::QCompressedLeaf) node_cost_ = kClusterNodeCost * mean_terminal_area();
    optimal_dp(0);
  }

  bool terminal(uint32_t i) const { return b2_.nodes[i].is_leaf() || multileaf_candidate(i); }

  // The mean area of the terminals (the collapse's leaves and multi-leaves), relative to the root.
  float mean_terminal_area() const {
    double sum = 0;
    uint64_t count = 0;
    std::vector<uint32_t> stack{0};
    while (!stack.empty()) {
      const uint32_t i = stack.back();
      stack.pop_back();
      if (terminal(i)) {
        sum += double(b2_.nodes[i].box.half_area()) / root_area_;
        ++count;
      } else {
        stack.push_back(b2_.nodes[i].first);
        stack.push_back(b2_.nodes[i].first + 1);
      }
    }
    return count ? float(sum / double(count)) : 0.0f;
  }

  struct Cover {
    std::array<float, 8> cost;  // cost(n, j), j = 1..8
    float leaf_area;            // sum over the BVH2 leaves below n of area x blocks
  };

  // Bottom-up over the subtree of BVH2 node i; large subtrees as parallel tasks (the figures of a
  // subtree depend on it alone, so the result is the same for any number of threads).
  Cover optimal_dp(uint32_t i) {
    const Bvh2Node& n = b2_.nodes[i];
    const float a = n.box.half_area() / root_area_;
    Cover out;
    if (n.is_leaf()) {
      out.leaf_area = a * float(leaf_blocks(i));
      out.cost.fill(out.leaf_area);
      return out;
    }
    Cover kid[2];
    for_children(i, 2, [&](int c) { kid[c] = optimal_dp(n.first + uint32_t(c)); });
    const Cover &L = kid[0], &R = kid[1];
    out.leaf_area = L.leaf_area + R.leaf_area;
    if (multileaf_candidate(i)) {
      out.cost.fill(a + out.leaf_area);  // the multi-leaf node, then one block per child
      return out;
    }
    float D[9];
    uint8_t K[9];
    for (int j = 2; j <= 8; ++j) {
      D[j] = kInf;
      K[j] = 1;
      for (int k = 1; k < j; ++k) {
        const float c = L.cost[k - 1] + R.cost[j - k - 1];
        if (c < D[j]) {
          D[j] = c;
          K[j] = uint8_t(k);
        }
      }
    }
    std::array<float, 8>& C = out.cost;
    std::array<std::array<uint8_t, 2>, 8>& ch = choice_[i];
    C[0] = a + node_cost_ + D[8];
    ch[0] = {0, 0};
    wide_[i] = {K[8], uint8_t(8 - K[8])};
    for (int j = 2; j <= 8; ++j) {
      if (D[j] < C[j - 2]) {
        C[j - 1] = D[j];
        ch[j - 1] = {K[j], uint8_t(j - K[j])};
      } else {
        C[j - 1] = C[j - 2];
        ch[j - 1] = ch[j - 2];
      }
    }
    return out;
  }

  // The roots of the best cover of subtree m by at most j roots (optimal_collapse).
  void expand(uint32_t m, uint32_t j, uint32_t* kids, int& k) const {
    if (terminal(m)) {
      kids[k++] = m;
      return;
    }
    const std::array<uint8_t, 2> c = choice_[m][j - 1];
    if (c[0] == 0) {
      kids[k++] = m;
      return;
    }
    expand(b2_.nodes[m].first, c[0], kids, k);
    expand(b2_.nodes[m].first + 1, c[1], kids, k);
  }

  void collect_leaves(uint32_t i, uint32_t* kids, int& k) const {
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) {
      kids[k++] = i;
      return;
    }
    collect_leaves(n.first, kids, k);
    collect_leaves(n.first + 1, kids, k);
  }

  uint32_t leaf_blocks(uint32_t i) const {
    return (b2_.nodes[i].count + enc_.block_prims - 1) / enc_.block_prims;
  }

  void count_leaf(uint32_t i, SubtreeStats& s) const {
    uint32_t blocks = leaf_blocks(i);
    s.st.leaves++;
    s.st.leaf_blocks += blocks;
    s.st.prims += b2_.nodes[i].count;
    s.st.sah_cost += double(b2_.nodes[i].box.half_area()) / root_area_ * blocks;
  }

  // Multi-leaf data written by LeafEncoder::encode_multileaf (clbvh-compact), encoded during
  // measure() because its size depends on the content.
  std::vector<uint8_t> encode_multi(uint32_t i) const {
    uint32_t kids[8];
    int k = 0;
    collect_leaves(i, kids, k);
    const uint32_t* prims[8];
    uint32_t counts[8];
    for (int c = 0; c < k; ++c) {
      prims[c] = &b2_.prim_ids[b2_.nodes[kids[c]].first];
      counts[c] = b2_.nodes[kids[c]].count;
    }
    return enc_.encode_multileaf(prims, counts, k);
  }

  // Pass 1: sizes of the subtree rooted at BVH2 node i, and its statistics.
  SubtreeStats measure(uint32_t i, int depth) {
    SubtreeStats s;
    s.st.depth = depth;
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) {
      uint32_t blocks = leaf_blocks(i);
      if (blocks > kMaxLeafBlocks) throw std::logic_error("BVH leaf too large");
      node_size_[i] = 0;
      leaf_size_[i] = round_leaf(uint64_t(blocks) * enc_.block_bytes);
      s.leaf_data_bytes += uint64_t(blocks) * enc_.block_bytes;
      count_leaf(i, s);
      return s;
    }
    if (multileaf_candidate(i)) {
      uint32_t kids[8];
      int k = 0;
      collect_leaves(i, kids, k);
      uint64_t data;
      if (enc_.encode_multileaf) {
        std::vector<uint8_t> d = encode_multi(i);
        data = d.size();
        multi_cache_.emplace(i, std::move(d));
      } else {
        data = uint64_t(k) * enc_.block_bytes;
      }
      node_size_[i] = 0;
      leaf_size_[i] = round_leaf(enc_.multileaf_header_bytes + data);
      s.leaf_data_bytes += data;
      s.multileaf_bytes += enc_.multileaf_header_bytes;
      s.st.multileaf++;
      s.st.leaves_in_multileaf += k;
      s.st.sah_cost += double(n.box.half_area()) / root_area_;
      for (int c = 0; c < k; ++c) {
        s.st.leaves++;
        s.st.leaf_blocks++;
        s.st.prims += b2_.nodes[kids[c]].count;
        s.st.sah_cost += double(b2_.nodes[kids[c]].box.half_area()) / root_area_;
      }
      return s;
    }
    uint32_t kids[8];
    int k = gather(i, kids);
    s.st.sah_cost += double(n.box.half_area()) / root_area_;
    SubtreeStats sub[8];
    // The multi-leaf cache (clbvh-compact) is a map: filled serially.
    for_children(
        i, k, [&](int c) { sub[c] = measure(kids[c], depth + 1); }, !enc_.encode_multileaf);
    report_small_children(i, kids, k);
    const bool cq = compact(i, kids, k);
    if (cq) s.st.cqnode8++;
    if (quantized_node(i))
      s.st.qnode8++;
    else
      s.st.node8++;
    s.node_bytes += node_bytes(cq, i);
    uint64_t nb = node_bytes(cq, i), lb = 0;
    for (int c = 0; c < k; ++c) {
      s.add(sub[c]);
      nb = child_node_off(nb, cq, kids[c]) + node_size_[kids[c]];
      lb += leaf_size_[kids[c]];
    }
    node_size_[i] = nb;
    leaf_size_[i] = lb;
    return s;
  }

  void write_leaf_blocks(uint32_t i, uint8_t* dst) const {
    const Bvh2Node& n = b2_.nodes[i];
    uint32_t blocks = leaf_blocks(i);
    for (uint32_t b = 0; b < blocks; ++b) {
      uint32_t first = n.first + b * enc_.block_prims;
      uint32_t cnt = std::min(enc_.block_prims, n.first + n.count - first);
      enc_.encode(&b2_.prim_ids[first], cnt, dst + uint64_t(b) * enc_.block_bytes);
    }
  }

  // Pass 2: writes the subtree of BVH2 node i with its node at node_off and its first leaf at
  // leaf_off; returns its reference.
  uint64_t emit(uint32_t i, uint64_t node_off, uint64_t leaf_off) const {
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) {
      std::memset(out_.leaves.data() + leaf_off, 0, leaf_size_[i]);
      write_leaf_blocks(i, out_.leaves.data() + leaf_off);
      return NodeRef::make(kRefLeaf, leaf_off, leaf_blocks(i));
    }
    if (multileaf_candidate(i)) {
      uint32_t kids[8];
      int k = 0;
      collect_leaves(i, kids, k);
      uint8_t* base = out_.leaves.data() + leaf_off;
      std::memset(base, 0, leaf_size_[i]);
      uint8_t* data = base + enc_.multileaf_header_bytes;
      if (enc_.encode_multileaf) {
        const std::vector<uint8_t>& d = multi_cache_.at(i);
        std::memcpy(data, d.data(), d.size());
      } else {
        for (int c = 0; c < k; ++c)
          write_leaf_blocks(kids[c], data + uint64_t(c) * enc_.block_bytes);
      }
      Box3f boxes[8];
      const uint32_t parts = enc_.parts_per_block;
      if (parts > 1) {
        for (int c = 0; c < k; ++c)
          enc_.part_bounds(b2_.prim_ids[b2_.nodes[kids[c]].first], &boxes[parts * c]);
      } else {
        for (int c = 0; c < k; ++c) boxes[c] = b2_.nodes[kids[c]].box;
      }
      if (enc_.multileaf_boxes)
        enc_.multileaf_boxes(data, k, boxes, base);
      else
        quantize_boxes(n.box, boxes, int(parts) * k, *reinterpret_cast<MultiLeaf8*>(base));
      // The block count field of a multi-leaf ref holds its number of children.
      return NodeRef::make(kRefMulti, leaf_off, parts * uint32_t(k));
    }
    uint32_t kids[8];
    int k = gather(i, kids);
    const bool cq = compact(i, kids, k);
    std::memset(out_.nodes.data() + node_off, 0, node_bytes(cq, i));
    uint64_t refs[8] = {};
    uint64_t noff[8], loff[8];
    uint64_t no = node_off + node_bytes(cq, i), lo = leaf_off;
    for (int c = 0; c < k; ++c) {
      const uint64_t at = child_node_off(no, cq, kids[c]);
      std::memset(out_.nodes.data() + no, 0, at - no);  // the padding ahead of a wide node's child
      noff[c] = no = at;
      loff[c] = lo;
      no += node_size_[kids[c]];
      lo += leaf_size_[kids[c]];
    }
    // The subtree takes the bytes measure() gave it (its float children's padding depends on
    // node_off: a float node starts on a multiple of 64, as the root and every Node8's float
    // children do).
    SLIM_ASSERT(no == node_off + node_size_[i]);
    for_children(i, k, [&](int c) { refs[c] = emit(kids[c], noff[c], loff[c]); });
    report_small_children(i, kids, k);
    if (cq) {
      auto* q = reinterpret_cast<CQNode8*>(out_.nodes.data() + node_off);
      Box3f boxes[8];
      for (int c = 0; c < k; ++c) boxes[c] = b2_.nodes[kids[c]].box;
      quantize_boxes(n.box, boxes, k, q->boxes);
      q->leaf_base = uint32_t(leaf_off / kCQLeafBaseUnit);
      const uint64_t leaf_base = uint64_t(q->leaf_base) * kCQLeafBaseUnit;
      for (int c = 0; c < k; ++c) {
        const uint64_t r = refs[c];
        const uint64_t d =
            NodeRef::offset(r) - (is_node_tag(NodeRef::tag(r)) ? node_off : leaf_base);
        q->child[c] = uint32_t(d << 8) | uint32_t(r & 255);
        SLIM_ASSERT(d < kCQOffsetLimit && cq_child_ref(q->child[c], node_off, leaf_base) == r);
      }
      return NodeRef::make(kRefCQNode8, node_off);
    }
    if (quantized_node(i)) {
      auto* q = reinterpret_cast<QNode8*>(out_.nodes.data() + node_off);
      Box3f boxes[8];
      for (int c = 0; c < k; ++c) boxes[c] = b2_.nodes[kids[c]].box;
      quantize_boxes(n.box, boxes, k, q->boxes);
      std::memcpy(q->child, refs, sizeof(refs));
      return NodeRef::make(kRefQNode8, node_off);
    }
    auto* nd = reinterpret_cast<Node8*>(out_.nodes.data() + node_off);
    for (int c = 0; c < 8; ++c) {
      Box3f b = c < k ? b2_.nodes[kids[c]].box : Box3f();
      for (int a = 0; a < 3; ++a) {
        nd->bounds[2 * a][c] = b.lo[a];
        nd->bounds[2 * a + 1][c] = b.hi[a];
      }
      nd->child[c] = refs[c];
    }
    return NodeRef::make(kRefNode8, node_off);
  }

  static constexpr uint32_t kParallelEmit = 1u << 14;  // primitives per subtree to emit as tasks

  // Progress: the primitives of the children of a large node (>= kParallelEmit) that are small
  // subtrees, once they are done. Each primitive lies in exactly one such child (or, for a small
  // root, in none: the phase's finish() reports it).
  void report_small_children(uint32_t i, const uint32_t* kids, int k) const {
    if (!progress_ || prims_[i] < kParallelEmit) return;
    uint64_t n = 0;
    for (int c = 0; c < k; ++c)
      if (prims_[kids[c]] < kParallelEmit) n += prims_[kids[c]];
    if (n) progress_->add(n);
  }

  const Bvh2& b2_;
  NodeKind kind_;
  const LeafEncoder& enc_;
  CollapseRule rule_;
  Bvh8& out_;
  LargeArray<uint32_t> prims_, leaves_, max_leaf_, slots_;
  bool optimal_ = true;
  LargeArray<std::array<std::array<uint8_t, 2>, 8>> choice_;  // optimal_collapse()
  LargeArray<std::array<uint8_t, 2>> wide_;
  LargeArray<uint64_t> node_size_, leaf_size_;
  std::unordered_map<uint32_t, std::vector<uint8_t>> multi_cache_;
  double root_area_ = 1;
  float node_cost_ = 0;  // optimal_dp's cost of a wide node beyond its visit (kClusterNodeCost)
  PhaseProgress* progress_ = nullptr;
};

}  // namespace

Bvh8 collapse_bvh8(const Bvh2& bvh2, NodeKind kind, const LeafEncoder& enc, CollapseRule rule,
                   PhaseProgress* progress) {
  Bvh8 out;
  Collapser(bvh2, kind, enc, rule, out, progress).run();
  return out;
}

// ---- validation -----------------------------------------------------------------------------

namespace {

struct Validator {
  const Bvh8& bvh;
  const LeafValidator& leaf;
  const MultiLeafValidator& multi;
  const MultiLeafBoxDecoder& boxes;
  std::string* why;

  bool fail(const std::string& msg) {
    if (why && why->empty()) *why = msg;
    return false;
  }

  bool check_leaf_block(const uint8_t* blk, const Box3f& box, Box3f& geom) {
    Box3f b;
    if (!leaf(blk, b, why)) return false;
    if (!box.contains(b)) return fail("primitive outside the box of its leaf");
    geom.extend(b);
    return true;
  }

  // Returns in `geom` the bounds of all primitives below ref, checking that every box on the way
  // (decoded exactly as the traversal decodes it) contains the primitives below it.
  bool visit(uint64_t ref, const Box3f& box, int depth, Box3f& geom) {
    if (depth > 256) return fail("BVH deeper than 256 levels (cycle?)");
    switch (NodeRef::tag(ref)) {
      case kRefEmpty:
        return true;
      case kRefLeaf: {
        uint64_t off = NodeRef::offset(ref);
        uint32_t nb = NodeRef::blocks(ref);
        if (nb == 0) return fail("leaf with zero blocks");
        if (off + uint64_t(nb) * bvh.block_bytes > bvh.leaves.size())
          return fail("leaf outside the leaf arena");
        for (uint32_t b = 0; b < nb; ++b)
          if (!check_leaf_block(bvh.leaves.data() + off + uint64_t(b) * bvh.block_bytes, box, geom))
            return false;
        return true;
      }
      case kRefMulti: {
        uint64_t off = NodeRef::offset(ref);
        uint32_t k = NodeRef::blocks(ref);
        if (k == 0 || k > 8) return fail("multi-leaf with a bad child count");
        const uint64_t hb = boxes.header_bytes;
        if (off + hb > bvh.leaves.size() ||
            (!multi && off + hb + uint64_t(k) * bvh.block_bytes > bvh.leaves.size()))
          return fail("multi-leaf outside the leaf arena");
        const uint8_t* p = bvh.leaves.data() + off;
        const auto* ml = reinterpret_cast<const MultiLeaf8*>(p);
        for (uint32_t c = 0; c < k; ++c) {
          const uint8_t* data = p + hb;
          Box3f g;
          if (multi) {
            if (!multi(data, k, c, g, why)) return false;
            Box3f cb;
            if (boxes.frame) {
              float start[4], extent[4];
              uint8_t q[6][8];
              boxes.frame(p, start, extent);
              if (boxes.planes)
                boxes.planes(p, q);
              else if (hb >= sizeof(q))
                std::memcpy(q, p, sizeof(q));  // 8-bit planes first (as QuantBoxes8::q)
              else
                throw std::logic_error("validate_bvh8: multi-leaf boxes without their planes");
              cb = dequantize_planes(q, start, extent, c);
            } else {
              cb = dequantize_box(*ml, c);
            }
            if (!cb.contains(g)) return fail("primitive outside the box of its leaf");
          } else if (!check_leaf_block(data + c * bvh.block_bytes, dequantize_box(*ml, c), g)) {
            return false;
          }
          if (!box.contains(g)) return fail("multi-leaf primitives outside the parent box");
          geom.extend(g);
        }
        return true;
      }
      case kRefNode8: {
        uint64_t off = NodeRef::offset(ref);
        if (off + sizeof(Node8) > bvh.nodes.size()) return fail("node outside the node arena");
        const auto* n = reinterpret_cast<const Node8*>(bvh.nodes.data() + off);
        bool any = false;
        for (int c = 0; c < 8; ++c) {
          Box3f cb({n->bounds[0][c], n->bounds[2][c], n->bounds[4][c]},
                   {n->bounds[1][c], n->bounds[3][c], n->bounds[5][c]});
          if (n->child[c] == 0) {
            if (!cb.empty()) return fail("empty child slot with a non-empty box");
            continue;
          }
          any = true;
          Box3f g;
          if (!visit(n->child[c], cb, depth + 1, g)) return false;
          if (!box.contains(cb)) return fail("child box outside its parent box");
          geom.extend(g);
        }
        return any ? true : fail("node without children");
      }
      case kRefQNode8:
      case kRefCQNode8: {  // both start with their QuantBoxes8
        const uint64_t off = NodeRef::offset(ref);
        if (off + node_size(NodeRef::tag(ref)) > bvh.nodes.size())
          return fail("node outside the node arena");
        QuantBoxes8 q;
        std::memcpy(&q, bvh.nodes.data() + off, sizeof q);
        uint64_t child[8];
        child_refs(ref, bvh.nodes.data() + off, child);
        bool any = false;
        for (int c = 0; c < 8; ++c) {
          if (child[c] == 0) continue;
          any = true;
          Box3f g;
          if (!visit(child[c], dequantize_box(q, c), depth + 1, g)) return false;
          if (!box.contains(g)) return fail("quantized node: primitives outside the parent box");
          geom.extend(g);
        }
        return any ? true : fail("node without children");
      }
    }
    return fail("unknown node reference tag");
  }
};

}  // namespace

bool validate_bvh8(const Bvh8& bvh, const LeafValidator& leaf, std::string* why,
                   const MultiLeafValidator& multi, const MultiLeafBoxDecoder& boxes) {
  Validator v{bvh, leaf, multi, boxes, why};
  Box3f geom;
  if (!v.visit(bvh.root, bvh.bounds, 0, geom)) return false;
  if (!geom.empty() && !bvh.bounds.contains(geom)) return v.fail("primitives outside the root box");
  return true;
}

}  // namespace slim
