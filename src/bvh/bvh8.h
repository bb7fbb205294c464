// 8-wide BVH: node layouts, child references, and the BVH2 -> BVH8 collapse. Compressed-leaf
// nodes: C. Benthin, I. Wald, S. Woop, A. T. Afra, "Compressed-Leaf Bounding Volume Hierarchies",
// HPG 2018 (section numbers of the authors' full version).
//
// Node formats (each size is checked by a static_assert below):
//   Node8       256 B  8 float boxes SoA + 8 child refs (Embree's BVH8 multi-node).
//   QNode8      136 B  float3 start + float3 extent + 8 boxes as 8-bit fixed point + 8 refs
//                      (Embree's QBVH8; section 4.1 "Node Compression and Decompression",
//                      Listing 1).
//   CQNode8     108 B  a QNode8 with 32-bit child refs relative to its own offset (inner nodes)
//                      and to a leaf base (leaves): the clusters' inner nodes below the top of
//                      the tree (QCompressedLeaf: Node8 over kFloatNodePrims primitives or more,
//                      wide QNode8 where an offset does not fit).
//   MultiLeaf8   72 B  start/extent + 8 quantized boxes, no refs: the leaf blocks of its (up to)
//                      8 children follow it in memory (section 4.2 "Introducing Compressed
//                      Multi-Leaf Nodes"). A leaf layout may store its multi-leaf boxes its own
//                      way instead (LeafEncoder::multileaf_boxes: the lossy clusters' 39 B).
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "bvh/build.h"
#include "slimrt/math.h"

namespace slim {

class PhaseProgress;  // core/progress.h

// ---- child references -----------------------------------------------------------------------
// 64 bits: bits 0-2 tag, bits 3-7 leaf block count (1..31), bits 8-63 byte offset into the
// node arena (Node8, QNode8, CQNode8) or the leaf arena (Leaf, MultiLeaf).
enum RefTag : uint32_t {
  kRefEmpty = 0,
  kRefNode8 = 1,
  kRefQNode8 = 2,
  kRefLeaf = 3,
  kRefMulti = 4,
  kRefCQNode8 = 5
};
// Whether a tag names an inner node (in the node arena).
constexpr uint32_t kNodeTags = (1u << kRefNode8) | (1u << kRefQNode8) | (1u << kRefCQNode8);
SLIM_INLINE bool is_node_tag(uint32_t tag) { return (kNodeTags >> tag) & 1; }

struct NodeRef {
  static SLIM_INLINE uint64_t make(RefTag tag, uint64_t offset, uint32_t blocks = 0) {
    return (offset << 8) | (uint64_t(blocks) << 3) | tag;
  }
  static SLIM_INLINE uint32_t tag(uint64_t r) { return uint32_t(r & 7); }
  static SLIM_INLINE uint32_t blocks(uint64_t r) { return uint32_t(r >> 3) & 31; }
  static SLIM_INLINE uint64_t offset(uint64_t r) { return r >> 8; }
};
constexpr uint32_t kMaxLeafBlocks = 31;

// ---- node layouts ---------------------------------------------------------------------------
// Box planes are stored so that the plane of axis a, side s (0 = lower, 1 = upper) is array
// 2*a+s: the traversal picks near/far planes by byte offset from the ray direction signs.
struct alignas(64) Node8 {
  float bounds[6][8];  // 192 B: lo_x, hi_x, lo_y, hi_y, lo_z, hi_z; empty slot: lo=+inf, hi=-inf
  uint64_t child[8];   // 64 B: child refs (kRefEmpty for unused slots)
};
static_assert(sizeof(Node8) == 256, "BVH8 multi-node is 256 bytes");

// Quantized boxes of 8 children relative to one float box: value = start + q * extent, q in
// 0..255, rounded conservatively (floor for lower, ceil for upper) at encoding.
struct QuantBoxes8 {
  float start[3];   // 12 B
  float extent[3];  // 12 B: per-step size ((hi - start) / 255, rounded up)
  uint8_t q[6][8];  // 48 B: lo_x, hi_x, lo_y, hi_y, lo_z, hi_z; empty slot: lo=255, hi=0
};
static_assert(sizeof(QuantBoxes8) == 72, "quantized box block is 72 bytes");

struct QNode8 {
  QuantBoxes8 boxes;  // 72 B
  uint64_t child[8];  // 64 B
};
static_assert(sizeof(QNode8) == 136, "QBVH8 multi-node is 136 bytes");

// A QNode8 whose child refs take 32 bits: bits 0-7 as a NodeRef's (tag, block count), bits 8-31
// a byte offset: for an inner node, after this node's own offset (the layout is depth-first: a
// node's subtree follows it); for a leaf or multi-leaf, after the leaf base, leaf_base x
// kCQLeafBaseUnit (the subtree's first leaf byte, rounded down). So a child's 64-bit ref is its
// 32 bits plus one base shifted by 8 (cq_child_ref). A node is compact when every child's offset
// fits (cq_fits); a damaged file's offsets stay inside the arenas only after scene_file.cpp's
// walk, as every reference.
struct CQNode8 {
  QuantBoxes8 boxes;   // 72 B
  uint32_t leaf_base;  // 4 B
  uint32_t child[8];   // 32 B
};
static_assert(sizeof(CQNode8) == 108 && alignof(CQNode8) == 4, "compact QBVH8 node is 108 bytes");
static_assert(offsetof(QNode8, boxes) == 0 && offsetof(CQNode8, boxes) == 0,
              "quantized nodes start with their boxes");
constexpr uint64_t kCQLeafBaseUnit = 64;  // leaf arenas up to 256 GiB
constexpr uint64_t kCQOffsetLimit = uint64_t(1) << 24;
// Whether a CQNode8 can hold its children: node_bytes of inner nodes after it (its subtree but
// itself) and leaf_bytes of leaves below it.
inline bool cq_fits(uint64_t node_bytes, uint64_t leaf_bytes) {
  return sizeof(CQNode8) + node_bytes < kCQOffsetLimit &&
         leaf_bytes + kCQLeafBaseUnit < kCQOffsetLimit;
}
// The 64-bit ref of a non-zero child c of the CQNode8 at node offset `off` with leaf base
// `leaf_base_bytes` (its leaf_base x kCQLeafBaseUnit).
SLIM_INLINE uint64_t cq_child_ref(uint32_t c, uint64_t off, uint64_t leaf_base_bytes) {
  return uint64_t(c) + ((is_node_tag(c & 7) ? off : leaf_base_bytes) << 8);
}

// Size and alignment of the inner node a node tag names (is_node_tag).
inline uint64_t node_size(uint32_t tag) {
  return tag == kRefNode8 ? sizeof(Node8) : tag == kRefQNode8 ? sizeof(QNode8) : sizeof(CQNode8);
}
inline uint64_t node_align(uint32_t tag) {
  return tag == kRefNode8 ? alignof(Node8) : tag == kRefQNode8 ? alignof(QNode8) : alignof(CQNode8);
}
// The 8 child refs of the inner node `ref` whose node_size(tag) bytes start at p (any alignment),
// as 64-bit refs (kRefEmpty where a slot is unused): for the walks that check a BVH (validation,
// scene files, tests); the traversal reads them in place.
inline void child_refs(uint64_t ref, const uint8_t* p, uint64_t out[8]) {
  const uint32_t tag = NodeRef::tag(ref);
  if (tag == kRefCQNode8) {
    CQNode8 n;
    std::memcpy(&n, p, sizeof n);
    const uint64_t leaf_base = uint64_t(n.leaf_base) * kCQLeafBaseUnit;
    for (int c = 0; c < 8; ++c)
      out[c] = n.child[c] ? cq_child_ref(n.child[c], NodeRef::offset(ref), leaf_base) : 0;
  } else {
    std::memcpy(out, p + (tag == kRefNode8 ? offsetof(Node8, child) : offsetof(QNode8, child)),
                8 * sizeof(uint64_t));
  }
}

using MultiLeaf8 = QuantBoxes8;  // 72 B; leaf blocks of child i follow at + 72 + i * block bytes

// Quantizes 8 boxes (n used, others empty) inside `parent`. The decoded boxes contain the
// originals (checked by SLIM_ASSERT in debug builds and by validate()).
void quantize_boxes(const Box3f& parent, const Box3f* boxes, int n, QuantBoxes8& out);
// Decodes child i exactly as the traversal does (for validation and tests).
Box3f dequantize_box(const QuantBoxes8& q, int i);
// The same in a given frame (start, extent per axis) with the planes q[6][8] stored elsewhere: the
// frame must decode q = 0 at or below, and q = 255 at or above, every box's bounds (n used boxes,
// the other slots of the 8 empty).
void quantize_planes(const float* start, const float* extent, const Box3f* boxes, int n,
                     uint8_t (*q)[8]);
Box3f dequantize_planes(const uint8_t (*q)[8], const float* start, const float* extent, int i);

// ---- 64-byte aligned byte arena -------------------------------------------------------------
class AlignedBytes {
 public:
  AlignedBytes() = default;
  ~AlignedBytes() {
    if (owned_) std::free(data_);
  }
  // A view of n bytes owned elsewhere (a scene file's mapping, api/scene_file.h): never freed; a
  // later append() or reserve() copies them into memory of its own first.
  static AlignedBytes view(const uint8_t* p, uint64_t n) {
    AlignedBytes a;
    a.data_ = const_cast<uint8_t*>(p);  // read through data() const only (the mapping is read-only)
    a.size_ = a.cap_ = n;
    a.owned_ = false;
    return a;
  }
  bool owned() const { return owned_; }
  AlignedBytes(const AlignedBytes&) = delete;
  AlignedBytes& operator=(const AlignedBytes&) = delete;
  AlignedBytes(AlignedBytes&& o) noexcept { swap(o); }
  AlignedBytes& operator=(AlignedBytes&& o) noexcept {
    swap(o);
    return *this;
  }
  void swap(AlignedBytes& o) noexcept {
    std::swap(data_, o.data_);
    std::swap(size_, o.size_);
    std::swap(cap_, o.cap_);
    std::swap(owned_, o.owned_);
  }
  // Appends n zero bytes aligned to `align` (power of two <= 64); returns their offset. With
  // zero = false the bytes are left as they are (the caller writes every one of them).
  uint64_t append(uint64_t n, uint64_t align = 16, bool zero = true);
  void reserve(uint64_t n);
  void shrink_to_fit();
  uint8_t* data() { return data_; }
  const uint8_t* data() const { return data_; }
  uint64_t size() const { return size_; }
  uint64_t capacity() const { return cap_; }

 private:
  uint8_t* data_ = nullptr;
  uint64_t size_ = 0, cap_ = 0;
  bool owned_ = true;
};

// ---- the BVH8 -------------------------------------------------------------------------------
enum class NodeKind : uint8_t {
  Bvh8,            // Node8 everywhere
  QBvh8,           // QNode8 everywhere
  CompressedLeaf,  // Node8 inner nodes, MultiLeaf8 for small subtrees (Benthin et al. 2018)
  // QNode8 inner nodes (CQNode8 where the offsets fit, Node8 over kFloatNodePrims primitives
  // or more), MultiLeaf8 for small subtrees: the cluster formats, whose inner nodes are the
  // largest part of the BVH (108 B per node instead of 256 B).
  QCompressedLeaf,
};

// How the collapse writes leaves: blocks of up to block_prims primitives, block_bytes each.
struct LeafEncoder {
  uint32_t block_prims = 4;
  uint32_t block_bytes = 0;
  // Writes the block of primitives prims[0..n) (1 <= n <= block_prims) to out (zeroed).
  std::function<void(const uint32_t* prims, uint32_t n, uint8_t* out)> encode;
  // Optional: the leaf data of a whole multi-leaf (written right behind its 72-byte header) from
  // its k children's primitives (prims[i][0..counts[i])). Used by layouts that share data among
  // the children (clbvh-compact). Without it, children are blocks written by `encode`.
  std::function<std::vector<uint8_t>(const uint32_t* const* prims, const uint32_t* counts, int k)>
      encode_multileaf;
  // Optional (block_prims = 1): each block of a multi-leaf takes parts_per_block child boxes (its
  // parts, e.g. the halves or quarters of a sub-grid), part_bounds(prim, boxes) gives them (an
  // empty box for an empty part). The multi-leaf then holds at most 8 / parts_per_block blocks, its
  // child count is blocks x parts_per_block, and the leaf format maps child i to its block.
  uint32_t parts_per_block = 1;
  std::function<void(uint32_t prim, Box3f* boxes)> part_bounds;
  // Optional (with encode_multileaf): the layout stores a multi-leaf's child boxes itself, in
  // multileaf_header_bytes bytes ahead of its data, instead of a MultiLeaf8 (the lossy clusters:
  // 6-bit boxes on the scene's lattice, prim/cluster.h). multileaf_boxes(data, k, boxes, header)
  // writes them from the encoded data and the k child boxes; each decoded box must contain its
  // child's box.
  uint32_t multileaf_header_bytes = sizeof(MultiLeaf8);
  std::function<void(const uint8_t* data, int k, const Box3f* boxes, uint8_t* header)>
      multileaf_boxes;
  // Leaves and multi-leaves start at multiples of this (a power of two): the collapse pads each to
  // it. 16 unless the layout reads them at any multiple of less (traverse.h leaf_align: the
  // clusters 1, the Costa leaves 8).
  uint32_t leaf_align = 16;
};

struct Bvh8Stats {
  uint64_t node8 = 0, qnode8 = 0, multileaf = 0, leaves = 0, leaf_blocks = 0;
  uint64_t leaves_in_multileaf = 0;  // leaves stored inside multi-leaf nodes
  uint64_t prims = 0;
  double sah_cost = 0;   // SAH cost of the BVH8 (node visit = 1, block test = 1)
  double leaf_fill = 0;  // average primitives per leaf block / block_prims
  int depth = 0;
  uint32_t cqnode8 = 0;  // of the qnode8, those stored as CQNode8 (scene files store this struct)
};

struct Bvh8 {
  AlignedBytes nodes;   // Node8 / QNode8 / CQNode8 (inner nodes)
  AlignedBytes leaves;  // leaf blocks; multi-leaf nodes with their blocks
  uint64_t root = 0;    // NodeRef of the root (kRefEmpty for an empty scene)
  Box3f bounds;
  uint32_t block_bytes = 0;
  uint64_t node_bytes = 0;       // inner node bytes (nodes.size() adds the padding between them)
  uint64_t multileaf_bytes = 0;  // MultiLeaf8 headers inside `leaves` (BVH memory)
  uint64_t leaf_data_bytes = 0;  // leaf blocks (geometry memory)
  Bvh8Stats stats;
  // The memory the BVH keeps, as the scenes count it: the node arena and the multi-leaf headers,
  // and the leaf arena less those headers (the leaf data with the padding between leaves).
  uint64_t kept_bvh_bytes() const { return nodes.size() + multileaf_bytes; }
  uint64_t kept_leaf_bytes() const { return leaves.size() - multileaf_bytes; }
};

// How a node takes its up to 8 children from the BVH2 below it.
enum class CollapseRule : uint8_t {
  // The SAH-optimal set of descendants (fewer box tests per ray on BVH8 and QBVH8: torus:1024 W1
  // 34.1 against 38.8, canyon:1024 47.3 against 53.3, ogre 20.9 against 26.1). For the clusters
  // (QCompressedLeaf) a wide node also costs its memory, kClusterNodeCost below.
  Optimal,
  // Open the largest-area child until 8 slots are taken: spends fewer inner nodes around the
  // compressed-leaf BVH's multi-leaves (node memory 0.59x the BVH8's on terrain:128 against
  // 0.61x, the same speed).
  Slots,
};

// The clusters' optimal collapse: a wide node costs, beyond its SAH visit, this many times the
// mean area of the collapse's terminals (the clusters and the rare isolated leaves, relative to
// the root's), which trades a little SAH for fuller nodes (nearly all CQNode8, 108 B each) where
// the two are close. On canyon:1024 6861 inner nodes (Slots, SAH cost 20.5) become 6052 (18.7);
// without the memory term 6752 (18.5).
constexpr float kClusterNodeCost = 16;

// In the clusters' trees (QCompressedLeaf), the inner nodes over at least this many primitives
// are Node8 (float boxes), the others CQNode8 (or QNode8). Every ray crosses the top of the tree;
// a float box test skips the quantized planes' conversion and product (fewer instructions on the
// traversal's chain from a node to the next), and its exact boxes let rays into fewer children.
// The top nodes are few (one per some thousands of primitives), so their 148 bytes more each and
// their padding to 64 bytes add a few hundredths of a byte a primitive (docs/results.md, "Float
// nodes at the top of the clusters' trees").
constexpr uint32_t kFloatNodePrims = 4096;

// The rule each node kind is best served by (the figures above).
inline CollapseRule default_collapse_rule(NodeKind kind) {
  return kind == NodeKind::CompressedLeaf ? CollapseRule::Slots : CollapseRule::Optimal;
}

// Collapses a BVH2 into 8-wide nodes of the given kind by the given rule (CollapseRule above),
// writing leaves through the encoder. For CompressedLeaf, every subtree with fewer
// than 8 x block_prims primitives that can be packed into at most 8 blocks becomes one multi-leaf
// (Benthin et al. 2018, section 4.3 "Builder Modifications").
// `progress` (optional) receives 2 x the primitive count: once as subtrees are measured, once as
// they are written (one add per subtree of a few thousand primitives).
Bvh8 collapse_bvh8(const Bvh2& bvh2, NodeKind kind, const LeafEncoder& enc, CollapseRule rule,
                   PhaseProgress* progress = nullptr);

// Checks a leaf block and returns the bounds of its primitives in `bounds`.
using LeafValidator = std::function<bool(const uint8_t* block, Box3f& bounds, std::string* why)>;
// For layouts with LeafEncoder::encode_multileaf: checks child i of the k children of a
// multi-leaf whose data starts at `data` (right behind the header).
using MultiLeafValidator = std::function<bool(const uint8_t* data, uint32_t k, uint32_t i,
                                              Box3f& bounds, std::string* why)>;

// Checks the node invariants: every box the traversal tests (quantized boxes decoded exactly as
// the traversal decodes them) contains all primitives below it, Node8 child boxes lie inside their
// parent box, offsets stay inside the arenas, and every leaf block passes `leaf`. Returns false
// and sets `why` on the first violation.
// The multi-leaf boxes of a layout that stores them itself (LeafEncoder::multileaf_boxes): the
// header's size, frame(multileaf, start, extent) (4 floats each, the 4th unused), the frame its
// 8-bit planes are decoded in, and planes(multileaf, q) those planes q[6][8] (traverse.h,
// HasMultiLeafBoxes). Both run after the multi-leaf's validator accepted its data. Default: a
// MultiLeaf8.
struct MultiLeafBoxDecoder {
  uint32_t header_bytes = sizeof(MultiLeaf8);
  std::function<void(const uint8_t* multileaf, float* start, float* extent)> frame;
  std::function<void(const uint8_t* multileaf, uint8_t (*q)[8])> planes;
};

bool validate_bvh8(const Bvh8& bvh, const LeafValidator& leaf, std::string* why,
                   const MultiLeafValidator& multi = nullptr,
                   const MultiLeafBoxDecoder& boxes = {});

}  // namespace slim
