// BVH2 -> BVH8 collapse and the node encodings of bvh8.h.
#include "bvh/bvh8.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <new>
#include <stdexcept>

#include "core/assert.h"

namespace slim {

// ---- AlignedBytes ---------------------------------------------------------------------------

void AlignedBytes::reserve(uint64_t n) {
  if (n <= cap_) return;
  uint64_t cap = (n + 63) & ~uint64_t(63);
  auto* p = static_cast<uint8_t*>(std::aligned_alloc(64, cap));
  if (!p) throw std::bad_alloc();
  if (size_) std::memcpy(p, data_, size_);
  std::free(data_);
  data_ = p;
  cap_ = cap;
}

uint64_t AlignedBytes::append(uint64_t n, uint64_t align) {
  uint64_t off = (size_ + align - 1) & ~(align - 1);
  if (off + n > cap_) reserve(std::max(off + n, cap_ + cap_ / 2 + 4096));
  std::memset(data_ + size_, 0, off + n - size_);
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

// ---- quantized boxes (compressed-leaf-bvh.txt section 4.1) -----------------------------------

namespace {

// The decoder's arithmetic, exactly: start + q * extent with one rounding (fma), as vfloat8 does.
SLIM_INLINE float decode_q(uint8_t q, float extent, float start) {
  return std::fma(float(q), extent, start);
}

}  // namespace

void quantize_boxes(const Box3f& parent, const Box3f* boxes, int n, QuantBoxes8& out) {
  for (int a = 0; a < 3; ++a) {
    float start = parent.lo[a];
    float hi = parent.hi[a];
    float ext = (hi - start) / 255.0f;
    // The step must be > 0 and 255 steps must reach the parent's upper bound, so that decoded
    // boxes are conservative and empty slots (lo = 255, hi = 0) decode to lo > hi.
    if (!(ext > 0.0f)) ext = std::max(std::fabs(start) * 1e-7f, 1e-30f);
    while (decode_q(255, ext, start) < hi || !(decode_q(255, ext, start) > start))
      ext = std::nextafter(ext, kInf) * (1.0f + 1e-7f);
    out.start[a] = start;
    out.extent[a] = ext;
    for (int i = 0; i < 8; ++i) {
      uint8_t qlo = 255, qhi = 0;
      if (i < n) {
        float lo = boxes[i].lo[a], up = boxes[i].hi[a];
        float fl = std::floor((lo - start) / ext);
        float fu = std::ceil((up - start) / ext);
        int ql = int(std::clamp(fl, 0.0f, 255.0f));
        int qu = int(std::clamp(fu, 0.0f, 255.0f));
        while (ql > 0 && decode_q(uint8_t(ql), ext, start) > lo) --ql;
        while (qu < 255 && decode_q(uint8_t(qu), ext, start) < up) ++qu;
        qlo = uint8_t(ql);
        qhi = uint8_t(qu);
        SLIM_ASSERT(decode_q(qlo, ext, start) <= lo && decode_q(qhi, ext, start) >= up);
      }
      out.q[2 * a][i] = qlo;
      out.q[2 * a + 1][i] = qhi;
    }
  }
}

Box3f dequantize_box(const QuantBoxes8& q, int i) {
  Box3f b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = decode_q(q.q[2 * a][i], q.extent[a], q.start[a]);
    b.hi[a] = decode_q(q.q[2 * a + 1][i], q.extent[a], q.start[a]);
  }
  return b;
}

// ---- collapse -------------------------------------------------------------------------------

namespace {

class Collapser {
 public:
  Collapser(const Bvh2& b2, NodeKind kind, const LeafEncoder& enc, Bvh8& out)
      : b2_(b2), kind_(kind), enc_(enc), out_(out) {}

  void run() {
    out_.block_bytes = enc_.block_bytes;
    if (b2_.nodes.empty()) {
      out_.root = NodeRef::make(kRefEmpty, 0);
      return;
    }
    // Subtree sizes bottom-up (children always have larger indices than their parent).
    const size_t nn = b2_.nodes.size();
    prims_.assign(nn, 0);
    leaves_.assign(nn, 0);
    for (size_t i = nn; i-- > 0;) {
      const Bvh2Node& n = b2_.nodes[i];
      if (n.is_leaf()) {
        prims_[i] = n.count;
        leaves_[i] = 1;
      } else {
        prims_[i] = prims_[n.first] + prims_[n.first + 1];
        leaves_[i] = leaves_[n.first] + leaves_[n.first + 1];
      }
    }
    out_.bounds = b2_.nodes[0].box;
    root_area_ = std::max(out_.bounds.half_area(), 1e-30f);
    // Reserve roughly: one inner node per ~4 leaves, one block per leaf.
    size_t nleaves = leaves_[0];
    out_.nodes.reserve((nleaves / 4 + 1) * (kind_ == NodeKind::QBvh8 ? 136 : 256));
    out_.leaves.reserve(uint64_t(nleaves) * enc_.block_bytes * 5 / 4 + 1024);
    out_.root = emit(0, 1);
    out_.nodes.shrink_to_fit();
    out_.leaves.shrink_to_fit();
    Bvh8Stats& s = out_.stats;
    s.sah_cost = sah_;
    s.leaf_fill = s.leaf_blocks ? double(s.prims) / double(s.leaf_blocks * enc_.block_prims) : 0;
  }

 private:
  bool multileaf_candidate(uint32_t i) const {
    if (kind_ != NodeKind::CompressedLeaf) return false;
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) return false;
    // compressed-leaf-bvh.txt section 4.3: subtrees of fewer than N x M primitives; each of
    // their (at most 8) leaves must fit one block so that child blocks are addressed implicitly.
    return prims_[i] < 8 * enc_.block_prims && leaves_[i] <= 8 && max_leaf(i) <= enc_.block_prims;
  }

  uint32_t max_leaf(uint32_t i) const {
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) return n.count;
    return std::max(max_leaf(n.first), max_leaf(n.first + 1));
  }

  // Up to 8 BVH2 nodes below node i, opening the largest-area inner child first.
  int gather(uint32_t i, uint32_t* kids) const {
    const Bvh2Node& n = b2_.nodes[i];
    int k = 0;
    kids[k++] = n.first;
    kids[k++] = n.first + 1;
    while (k < 8) {
      int best = -1;
      float best_area = -1.0f;
      for (int c = 0; c < k; ++c) {
        const Bvh2Node& cn = b2_.nodes[kids[c]];
        if (cn.is_leaf() || multileaf_candidate(kids[c])) continue;
        float a = cn.box.half_area();
        if (a > best_area) {
          best_area = a;
          best = c;
        }
      }
      if (best < 0) break;
      uint32_t open = kids[best];
      kids[best] = b2_.nodes[open].first;
      kids[k++] = b2_.nodes[open].first + 1;
    }
    return k;
  }

  uint64_t write_leaf_blocks(uint32_t i, uint8_t* dst) {
    const Bvh2Node& n = b2_.nodes[i];
    uint32_t blocks = (n.count + enc_.block_prims - 1) / enc_.block_prims;
    for (uint32_t b = 0; b < blocks; ++b) {
      uint32_t first = n.first + b * enc_.block_prims;
      uint32_t cnt = std::min(enc_.block_prims, n.first + n.count - first);
      enc_.encode(&b2_.prim_ids[first], cnt, dst + uint64_t(b) * enc_.block_bytes);
    }
    Bvh8Stats& s = out_.stats;
    s.leaves++;
    s.leaf_blocks += blocks;
    s.prims += n.count;
    out_.leaf_data_bytes += uint64_t(blocks) * enc_.block_bytes;
    sah_ += double(n.box.half_area()) / root_area_ * blocks;
    return blocks;
  }

  uint64_t emit_leaf(uint32_t i) {
    const Bvh2Node& n = b2_.nodes[i];
    uint32_t blocks = (n.count + enc_.block_prims - 1) / enc_.block_prims;
    if (blocks > kMaxLeafBlocks) throw std::logic_error("BVH leaf too large");
    uint64_t off = out_.leaves.append(uint64_t(blocks) * enc_.block_bytes, 16);
    write_leaf_blocks(i, out_.leaves.data() + off);
    return NodeRef::make(kRefLeaf, off, blocks);
  }

  // One MultiLeaf8 with the blocks of the subtree's (<= 8) leaves right behind it.
  uint64_t emit_multileaf(uint32_t i) {
    uint32_t kids[8];
    int k = 0;
    collect_leaves(i, kids, k);
    Box3f boxes[8];
    for (int c = 0; c < k; ++c) boxes[c] = b2_.nodes[kids[c]].box;
    uint64_t off;
    if (enc_.encode_multileaf) {
      const uint32_t* prims[8];
      uint32_t counts[8];
      for (int c = 0; c < k; ++c) {
        const Bvh2Node& n = b2_.nodes[kids[c]];
        prims[c] = &b2_.prim_ids[n.first];
        counts[c] = n.count;
        Bvh8Stats& s = out_.stats;
        s.leaves++;
        s.leaf_blocks++;
        s.prims += n.count;
        sah_ += double(n.box.half_area()) / root_area_;
      }
      std::vector<uint8_t> data = enc_.encode_multileaf(prims, counts, k);
      off = out_.leaves.append(sizeof(MultiLeaf8) + data.size(), 16);
      std::memcpy(out_.leaves.data() + off + sizeof(MultiLeaf8), data.data(), data.size());
      out_.leaf_data_bytes += data.size();
    } else {
      off = out_.leaves.append(sizeof(MultiLeaf8) + uint64_t(k) * enc_.block_bytes, 16);
      uint8_t* blocks = out_.leaves.data() + off + sizeof(MultiLeaf8);
      for (int c = 0; c < k; ++c)
        write_leaf_blocks(kids[c], blocks + uint64_t(c) * enc_.block_bytes);
    }
    auto* ml = reinterpret_cast<MultiLeaf8*>(out_.leaves.data() + off);
    quantize_boxes(b2_.nodes[i].box, boxes, k, *ml);
    out_.multileaf_bytes += sizeof(MultiLeaf8);
    out_.stats.multileaf++;
    out_.stats.leaves_in_multileaf += k;
    sah_ += double(b2_.nodes[i].box.half_area()) / root_area_;
    // The block count field of a multi-leaf ref holds its number of children.
    return NodeRef::make(kRefMulti, off, uint32_t(k));
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

  uint64_t emit(uint32_t i, int depth) {
    out_.stats.depth = std::max(out_.stats.depth, depth);
    const Bvh2Node& n = b2_.nodes[i];
    if (n.is_leaf()) return emit_leaf(i);
    if (multileaf_candidate(i)) return emit_multileaf(i);

    uint32_t kids[8];
    int k = gather(i, kids);
    sah_ += double(n.box.half_area()) / root_area_;
    if (kind_ == NodeKind::QBvh8) {
      uint64_t off = out_.nodes.append(sizeof(QNode8), 8);
      out_.node_bytes += sizeof(QNode8);
      out_.stats.qnode8++;
      Box3f boxes[8];
      uint64_t refs[8] = {};
      for (int c = 0; c < k; ++c) {
        boxes[c] = b2_.nodes[kids[c]].box;
        refs[c] = emit(kids[c], depth + 1);
      }
      auto* q = reinterpret_cast<QNode8*>(out_.nodes.data() + off);
      quantize_boxes(n.box, boxes, k, q->boxes);
      std::memcpy(q->child, refs, sizeof(refs));
      return NodeRef::make(kRefQNode8, off);
    }
    uint64_t off = out_.nodes.append(sizeof(Node8), 64);
    out_.node_bytes += sizeof(Node8);
    out_.stats.node8++;
    uint64_t refs[8] = {};
    for (int c = 0; c < k; ++c) refs[c] = emit(kids[c], depth + 1);
    auto* nd = reinterpret_cast<Node8*>(out_.nodes.data() + off);
    for (int c = 0; c < 8; ++c) {
      Box3f b = c < k ? b2_.nodes[kids[c]].box : Box3f();
      for (int a = 0; a < 3; ++a) {
        nd->bounds[2 * a][c] = b.lo[a];
        nd->bounds[2 * a + 1][c] = b.hi[a];
      }
      nd->child[c] = refs[c];
    }
    return NodeRef::make(kRefNode8, off);
  }

  const Bvh2& b2_;
  NodeKind kind_;
  const LeafEncoder& enc_;
  Bvh8& out_;
  std::vector<uint32_t> prims_, leaves_;
  double sah_ = 0;
  double root_area_ = 1;
};

}  // namespace

Bvh8 collapse_bvh8(const Bvh2& bvh2, NodeKind kind, const LeafEncoder& enc) {
  Bvh8 out;
  Collapser(bvh2, kind, enc, out).run();
  return out;
}

// ---- validation -----------------------------------------------------------------------------

namespace {

struct Validator {
  const Bvh8& bvh;
  const LeafValidator& leaf;
  const MultiLeafValidator& multi;
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
        if (!multi && off + sizeof(MultiLeaf8) + uint64_t(k) * bvh.block_bytes > bvh.leaves.size())
          return fail("multi-leaf outside the leaf arena");
        const auto* ml = reinterpret_cast<const MultiLeaf8*>(bvh.leaves.data() + off);
        for (uint32_t c = 0; c < k; ++c) {
          const uint8_t* data = bvh.leaves.data() + off + sizeof(MultiLeaf8);
          Box3f g;
          if (multi) {
            Box3f cb = dequantize_box(*ml, c);
            if (!multi(data, k, c, g, why)) return false;
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
      case kRefQNode8: {
        uint64_t off = NodeRef::offset(ref);
        if (off + sizeof(QNode8) > bvh.nodes.size()) return fail("node outside the node arena");
        const auto* n = reinterpret_cast<const QNode8*>(bvh.nodes.data() + off);
        bool any = false;
        for (int c = 0; c < 8; ++c) {
          if (n->child[c] == 0) continue;
          any = true;
          Box3f g;
          if (!visit(n->child[c], dequantize_box(n->boxes, c), depth + 1, g)) return false;
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
                   const MultiLeafValidator& multi) {
  Validator v{bvh, leaf, multi, why};
  Box3f geom;
  if (!v.visit(bvh.root, bvh.bounds, 0, geom)) return false;
  if (!geom.empty() && !bvh.bounds.contains(geom)) return v.fail("primitives outside the root box");
  return true;
}

}  // namespace slim
