// Binned SAH builder (top-down, parallel with TBB) producing a binary BVH over primitive boxes.
// The builder knows nothing of primitives: it sees boxes and returns a permutation of their ids
// plus a BVH2 whose leaves are ranges of that permutation (madmann91/bvh style: data apart from
// algorithms). bvh8.h collapses the result into 8-wide nodes.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "core/large_array.h"
#include "slimrt/math.h"

namespace slim {

class PhaseProgress;  // core/progress.h

struct PrimRef {
  Box3f box;
  uint32_t id;  // index of the primitive in its source
};

struct Bvh2Node {
  Box3f box;
  uint32_t first = 0;  // leaf: first index into Bvh2::prim_ids; inner: index of the left child
  uint32_t count = 0;  // leaf: number of primitives (> 0); inner: 0 (right child = first + 1)
  bool is_leaf() const { return count != 0; }
};

struct Bvh2BuildConfig {
  int bins = 32;               // SAH bins per axis (BuildOptions::sah_bins)
  uint32_t max_leaf_size = 4;  // leaves never hold more primitives than this
  uint32_t block_prims = 4;    // leaf cost counts blocks of this many primitives (SIMD width)
  float trav_cost = 1.0f;      // cost of one node visit relative to one primitive block test
  // Nonzero: nodes of at most this many primitives split where their children need no more
  // leaf blocks than they do, ceil(n / block_prims), if the SAH allows (Builder::full_blocks).
  uint32_t full_blocks_below = 0;
  int max_depth = 96;  // deeper nodes are split at the object median
  int threads = 0;     // 0 = all
  // Optional: receives 2 x count units, count as the references are made and count as the
  // primitives are placed in leaves (one add per chunk of references or per subtree, never per
  // primitive); throws slim::Cancelled out of build_bvh2 when the build is cancelled.
  PhaseProgress* progress = nullptr;
  // Optional, both or neither: exact duplicates among the primitives (the same surface twice, so
  // a hit on one is a hit on the other). duplicate_key(id) is equal for duplicates;
  // same_primitive(a, b) says whether b duplicates a. Where the references of a node larger than
  // a leaf all share one centroid (nothing left to split them by: a stack of coincident
  // triangles would otherwise become a deep subtree that every ray through it walks to the
  // bottom), the builder keeps the lowest id of each group of duplicates and leaves the others
  // out of every leaf (Bvh2::dropped). Duplicates elsewhere stay.
  std::function<uint64_t(uint32_t id)> duplicate_key;
  std::function<bool(uint32_t a, uint32_t b)> same_primitive;
  // Optional, for primitives that hold several triangles (pairs), where a primitive can be a
  // duplicate in part: called where the two above would be (a node larger than a leaf whose
  // references share one centroid) and instead of them, with the ids of that node's primitives.
  // It clears keep[i] for each primitive ids[i] to leave out (to Bvh2::dropped) and may rewrite
  // the kept ones to hold fewer triangles (their references keep their boxes, which still bound
  // them). Called from several threads at once, on disjoint sets of ids.
  std::function<void(const uint32_t* ids, uint32_t n, uint8_t* keep)> thin_stack;
};

struct Bvh2 {
  LargeArray<Bvh2Node> nodes;     // nodes[0] is the root (if any primitive)
  LargeArray<uint32_t> prim_ids;  // primitive ids in leaf order (dropped ones outside every leaf)
  int depth = 0;
  std::vector<uint32_t> dropped;  // ids left out as duplicates (duplicate_key or thin_stack)
};

// Writes the references of primitives begin..end-1 to out[0 .. end - begin). Called in parallel
// over disjoint ranges, so that no array of all references is made besides the builder's own.
using PrimRefFill = std::function<void(uint32_t begin, uint32_t end, PrimRef* out)>;

// Builds a BVH2 over the `count` primitives that `fill` describes. Empty input gives an empty
// BVH (no nodes).
Bvh2 build_bvh2(uint32_t count, const PrimRefFill& fill, const Bvh2BuildConfig& cfg);
// The same over an array of references.
Bvh2 build_bvh2(const std::vector<PrimRef>& refs, const Bvh2BuildConfig& cfg);

}  // namespace slim
