// Single-ray BVH8 traversal: one template over (leaf format, closest/any hit, statistics).
// Node formats (Node8, QNode8, CQNode8, MultiLeaf8) are told apart by the tag of the child
// reference, so one loop serves BVH8, QBVH8 and the compressed-leaf BVH. The leaf format is a
// parameter that satisfies the LeafFormat concept below (the leaf contract, written once).
#pragma once

#include <concepts>
#include <cstdint>

#include "bvh/bvh8.h"
#include "core/ray.h"
#include "core/simd.h"
#include "slimrt/ray.h"

namespace slim {

// The leaf contract. A leaf format L provides
//   L::Context             scene data the leaves refer to (may be empty), passed to every call;
//   L::kBlockPrims         primitives per leaf block (the builder's unit);
//   L::kBlockBytes         bytes per block (a leaf is up to kMaxLeafBlocks blocks back to back);
//   L::intersect<kAny>(ctx, block, ray, hit, stats) -> bool
//                          tests one block. Closest hit (kAny = false): lowers ray.tfar and fills
//                          the hit record when it finds a closer hit, and returns true then. Any
//                          hit (kAny = true): returns true on the first hit. It reports the tests
//                          it makes to `stats` (NoStats or CountStats, core/ray.h).
// The optional multi-leaf layouts are the HasMultiLeaf* concepts below.
template <class L>
concept LeafFormat = requires(const typename L::Context& ctx, const uint8_t* block, TravRay& ray,
                              HitRecord& hit, NoStats& none, CountStats& counted) {
  { L::kBlockPrims } -> std::convertible_to<uint32_t>;
  { L::kBlockBytes } -> std::convertible_to<uint32_t>;
  { L::template intersect<false>(ctx, block, ray, hit, none) } -> std::same_as<bool>;
  { L::template intersect<true>(ctx, block, ray, hit, none) } -> std::same_as<bool>;
  { L::template intersect<false>(ctx, block, ray, hit, counted) } -> std::same_as<bool>;
};

namespace detail {

// 8 float boxes (Node8): returns the hit mask and the entry distances.
SLIM_INLINE uint32_t intersect_node8(const Node8* n, const TravRay& r, simd::vfloat8& dist) {
  using namespace simd;
  const float* b = &n->bounds[0][0];
  const uint32_t nx = r.near_plane[0], ny = r.near_plane[1], nz = r.near_plane[2];
  vfloat8 tnx = fmsub(vfloat8::load(b + nx * 8), vfloat8(r.rdir.x), vfloat8(r.c_near[0]));
  vfloat8 tny = fmsub(vfloat8::load(b + ny * 8), vfloat8(r.rdir.y), vfloat8(r.c_near[1]));
  vfloat8 tnz = fmsub(vfloat8::load(b + nz * 8), vfloat8(r.rdir.z), vfloat8(r.c_near[2]));
  vfloat8 tfx = fmsub(vfloat8::load(b + (nx ^ 1) * 8), vfloat8(r.rdir.x), vfloat8(r.c_far[0]));
  vfloat8 tfy = fmsub(vfloat8::load(b + (ny ^ 1) * 8), vfloat8(r.rdir.y), vfloat8(r.c_far[1]));
  vfloat8 tfz = fmsub(vfloat8::load(b + (nz ^ 1) * 8), vfloat8(r.rdir.z), vfloat8(r.c_far[2]));
  vfloat8 tn = max(max(tnx, tny), max(tnz, vfloat8(r.tnear)));
  vfloat8 tf = min(min(tfx, tfy), min(tfz, vfloat8(r.tfar)));
  dist = tn;
  return (tn <= tf).mask();
}

// 8 quantized boxes: planes (plane_q(p): plane p's 8 values as ints, p = 0..5 as the rows of
// QuantBoxes8::q) decoded as start + q * extent, then the same slab test.
template <class PlaneQ>
SLIM_INLINE uint32_t intersect_planes(const PlaneQ& plane_q, const float* start,
                                      const float* extent, const TravRay& r, simd::vfloat8& dist) {
  using namespace simd;
  auto plane = [&](uint32_t p, int a) {
    return fmadd(to_float(plane_q(p)), vfloat8(extent[a]), vfloat8(start[a]));
  };
  const uint32_t nx = r.near_plane[0], ny = r.near_plane[1], nz = r.near_plane[2];
  vfloat8 tnx = fmsub(plane(nx, 0), vfloat8(r.rdir.x), vfloat8(r.c_near[0]));
  vfloat8 tny = fmsub(plane(ny, 1), vfloat8(r.rdir.y), vfloat8(r.c_near[1]));
  vfloat8 tnz = fmsub(plane(nz, 2), vfloat8(r.rdir.z), vfloat8(r.c_near[2]));
  vfloat8 tfx = fmsub(plane(nx ^ 1, 0), vfloat8(r.rdir.x), vfloat8(r.c_far[0]));
  vfloat8 tfy = fmsub(plane(ny ^ 1, 1), vfloat8(r.rdir.y), vfloat8(r.c_far[1]));
  vfloat8 tfz = fmsub(plane(nz ^ 1, 2), vfloat8(r.rdir.z), vfloat8(r.c_far[2]));
  vfloat8 tn = max(max(tnx, tny), max(tnz, vfloat8(r.tnear)));
  vfloat8 tf = min(min(tfx, tfy), min(tfz, vfloat8(r.tfar)));
  dist = tn;
  return (tn <= tf).mask();
}
// ... planes q[6][8] (as QuantBoxes8::q).
SLIM_INLINE uint32_t intersect_quant_planes(const uint8_t (*q)[8], const float* start,
                                            const float* extent, const TravRay& r,
                                            simd::vfloat8& dist) {
  return intersect_planes([q](uint32_t p) { return simd::vint8::load_u8(q[p]); }, start, extent, r,
                          dist);
}

// 8 quantized boxes (QNode8, MultiLeaf8).
SLIM_INLINE uint32_t intersect_quant8(const QuantBoxes8* q, const TravRay& r, simd::vfloat8& dist) {
  return intersect_quant_planes(q->q, q->start, q->extent, r, dist);
}

}  // namespace detail

// Stack depth bound: the BVH2 builder limits depth to 64 SAH levels + 32 median levels, and a
// BVH8 node pushes at most 7 entries per level.
constexpr int kTraversalStackSize = 7 * 96 + 8;

template <LeafFormat Leaf, bool kAny, class Stats>
SLIM_INLINE bool intersect_leaf_blocks(const typename Leaf::Context& ctx, const uint8_t* p,
                                       uint32_t blocks, uint32_t block_bytes, TravRay& ray,
                                       HitRecord& hit, Stats& st) {
  bool found = false;
  for (uint32_t b = 0; b < blocks; ++b) {
    if (Leaf::template intersect<kAny>(ctx, p + uint64_t(b) * block_bytes, ray, hit, st)) {
      found = true;
      if constexpr (kAny) return true;
    }
  }
  return found;
}

// A leaf format may store the children of a multi-leaf differently from isolated leaves
// (clbvh-compact: 8-bit indices into a per-multi-leaf dictionary; C. Benthin, I. Wald, S. Woop,
// A. T. Afra, "Compressed-Leaf Bounding Volume Hierarchies", HPG 2018, section 4.5 "Compressing
// Leaf Data"). It then provides
//   template <bool kAny, class Stats> static bool intersect_in_multileaf(const Context&,
//       const uint8_t* data, uint32_t children, int i, TravRay&, HitRecord&, Stats&);
// where data points right behind the 72-byte multi-leaf header.
template <class L>
concept HasMultiLeafLayout = requires {
  L::kMultiLeafLayout;
};
// A multi-leaf layout whose children share data to read first (the cluster formats: a header, a
// stream layout and anchors) may read it once per multi-leaf visit instead of once per child:
// then it provides
//   L::MultiLeafView       what the children share;
//   static MultiLeafView multileaf_view(const Context&, const uint8_t* data, uint32_t children);
//   template <bool kAny, class Stats> static bool intersect_in_view(const Context&,
//       const MultiLeafView&, int i, TravRay&, HitRecord&, Stats&);
// and intersect_multileaf makes the view once, when the ray enters at least one child. It may also
// provide
//   static void prefetch_in_view(const MultiLeafView&, uint32_t mask);
// which starts loading what the children in `mask` (those the ray enters) will read, called before
// the first of them is tested.
template <class L>
concept HasMultiLeafView = HasMultiLeafLayout<L> && requires {
  typename L::MultiLeafView;
};
// A multi-leaf layout may store its child boxes its own way, ahead of its data (the lossy
// clusters: the float start and extent of a MultiLeaf8 follow from data the cluster holds anyway):
// then it provides
//   L::kMultiLeafBoxes = true, L::kMultiLeafHeaderBytes  the boxes' bytes (the data follows);
//   static void multileaf_frame(const Context&, const uint8_t* p, float start[4],
//       float extent[4]);   the frame of the multi-leaf at p, whose 8-bit planes q[6][8] (as
//                            QuantBoxes8::q) decode as start + q * extent (one fma, as QNode8);
//   static void multileaf_planes(const uint8_t* p, vint8 q[6]): the planes of the 8 children
//       (the layout stores them its own way: the lossy clusters' 6-bit planes);
//   static void multileaf_planes8(const uint8_t* p, uint8_t (*q)[8]): all six (the structure
//       check's);
// and, for the builder (bvh_scene.h), write_multileaf_boxes(source, data, k, boxes, header): the
// frame and planes of a multi-leaf of k children in boxes[0..k), written into its header.
template <class L>
concept HasMultiLeafBoxes = HasMultiLeafView<L> && requires {
  requires L::kMultiLeafBoxes;
};
// Bytes ahead of a multi-leaf's data (the quantized child boxes).
template <class L>
constexpr uint32_t multileaf_header_bytes() {
  if constexpr (HasMultiLeafBoxes<L>)
    return L::kMultiLeafHeaderBytes;
  else
    return sizeof(MultiLeaf8);
}
// The alignment its leaves and multi-leaves need (LeafEncoder::leaf_align): L::kLeafAlign (the
// clusters 1: unaligned loads and memcpy only; the Costa leaves 8), else 16.
template <class L>
constexpr uint32_t leaf_align() {
  if constexpr (requires { L::kLeafAlign; }) {
    static_assert(L::kLeafAlign && (L::kLeafAlign & (L::kLeafAlign - 1)) == 0,
                  "the collapse rounds leaf sizes to a power of two");
    return L::kLeafAlign;
  } else {
    return 16;
  }
}
// Its multi-leaf data is written by L::encode_multileaf (clbvh-compact's vertex dictionary).
template <class L>
concept HasMultiLeafEncoder = requires {
  &L::encode_multileaf;
};
// Its blocks may each take several child boxes of a multi-leaf (sub-grid halves or quarters): then
// it provides multileaf_parts(source), part_bounds(source, prim, boxes) and primary_part(ctx, i)
// (child i is its block's first part), and intersect_in_multileaf maps children to blocks.
template <class L>
concept HasMultiLeafParts = requires(const typename L::Source& s) {
  L::multileaf_parts(s);
};

// Multi-leaf (Benthin et al. 2018, section 4.4 "Traversal"): test the 8 quantized boxes, then the
// blocks of the children hit. The paper tests them in any order; closest-hit rays here take them
// near to far and stop at the first whose entry distance lies beyond the closest hit so far (with
// up to 8 sub-grid halves or quarters per multi-leaf, a ray often enters several children that a
// hit then hides).
template <LeafFormat Leaf, bool kAny, class Stats>
SLIM_INLINE bool intersect_multileaf(const typename Leaf::Context& ctx, const uint8_t* p,
                                     uint32_t children, uint32_t block_bytes, TravRay& ray,
                                     bool& watertight_set, HitRecord& hit, Stats& st) {
  simd::vfloat8 dist;
  uint32_t mask;
  if constexpr (HasMultiLeafBoxes<Leaf>) {
    alignas(16) float start[4], extent[4];
    Leaf::multileaf_frame(ctx, p, start, extent);
    simd::vint8 q[6];
    Leaf::multileaf_planes(p, q);
    mask = detail::intersect_planes([&](uint32_t i) { return q[i]; }, start, extent, ray, dist);
  } else {
    mask = detail::intersect_quant8(reinterpret_cast<const MultiLeaf8*>(p), ray, dist);
  }
  mask &= (1u << children) - 1;
  st.node(children);
  bool found = false;
  const uint8_t* blocks = p + multileaf_header_bytes<Leaf>();
  alignas(32) float d[8];
  if constexpr (!kAny) dist.store(d);
  if (!mask) return false;  // the view and the watertight constants: for a ray that enters a child
  set_watertight_once(ray, watertight_set);
  [[maybe_unused]] const auto view = [&] {
    struct NoView {};
    if constexpr (HasMultiLeafView<Leaf>)
      return Leaf::multileaf_view(ctx, blocks, children);
    else
      return NoView{};
  }();
  if constexpr (requires { Leaf::prefetch_in_view(view, mask); })
    Leaf::prefetch_in_view(view, mask);
  while (mask) {
    int i;
    if constexpr (kAny) {
      i = simd::pop_lowest(mask);
    } else {
      i = simd::ctz(mask);  // the nearest child left (the lowest index among equals)
      for (uint32_t m = mask & (mask - 1); m;) {
        const int k = simd::pop_lowest(m);
        if (d[k] < d[i]) i = k;
      }
      mask &= ~(1u << i);
      if (d[i] > ray.tfar) break;  // so are all others
    }
    bool h;
    if constexpr (HasMultiLeafView<Leaf>)
      h = Leaf::template intersect_in_view<kAny>(ctx, view, i, ray, hit, st);
    else if constexpr (HasMultiLeafLayout<Leaf>)
      h = Leaf::template intersect_in_multileaf<kAny>(ctx, blocks, children, i, ray, hit, st);
    else
      h = Leaf::template intersect<kAny>(ctx, blocks + uint64_t(i) * block_bytes, ray, hit, st);
    if (h) {
      found = true;
      if constexpr (kAny) return true;
    }
  }
  return found;
}

// Starts loading the node or leaf a pushed stack entry refers to (its first 256 bytes: a whole
// Node8, or a multi-leaf header and its first blocks), so that a later pop finds it in cache.
SLIM_INLINE void prefetch_ref(const uint8_t* nodes, const uint8_t* leaves, uint64_t ref) {
  const uint32_t tag = NodeRef::tag(ref);
  const uint8_t* p = (is_node_tag(tag) ? nodes : leaves) + NodeRef::offset(ref);
  for (int l = 0; l < 4; ++l) simd::prefetch(p + 64 * l);
}

// Traverses the BVH from bvh.root. Closest hit: returns true if `hit` was filled (ray.tfar = t).
// Any hit: returns true as soon as one primitive is hit.
template <LeafFormat Leaf, bool kAny, class Stats>
bool traverse_bvh8(const Bvh8& bvh, const typename Leaf::Context& ctx, TravRay& ray, HitRecord& hit,
                   Stats& st) {
  struct Entry {
    uint64_t ref;
    float dist;
  };
  Entry stack[kTraversalStackSize];
  int sp = 0;
  const uint8_t* nodes = bvh.nodes.data();
  const uint8_t* leaves = bvh.leaves.data();
  const uint32_t block_bytes = bvh.block_bytes;
  bool found = false;
  uint64_t cur = bvh.root;
  // The ray's watertight constants (TravRay::wt) are set at its first leaf: the rays that meet
  // only boxes (most misses) skip them.
  bool watertight_set = false;

  for (;;) {
    // Descend through inner nodes, nearest child first.
    for (;;) {
      const uint32_t tag = NodeRef::tag(cur);
      if (!is_node_tag(tag)) break;
      simd::vfloat8 dist;
      uint32_t mask;
      const uint64_t* child = nullptr;
      const CQNode8* compact = nullptr;
      const uint8_t* np = nodes + NodeRef::offset(cur);
      if (tag == kRefCQNode8) {
        compact = reinterpret_cast<const CQNode8*>(np);
        mask = detail::intersect_quant8(&compact->boxes, ray, dist);
        if (mask) mask &= ~simd::zero_mask8(compact->child);  // as for QNode8 below
      } else if (tag == kRefNode8) {
        const auto* n = reinterpret_cast<const Node8*>(np);
        simd::prefetch(n->child);  // read once the box test is done
        mask = detail::intersect_node8(n, ray, dist);
        child = n->child;
      } else {
        const auto* n = reinterpret_cast<const QNode8*>(np);
        mask = detail::intersect_quant8(&n->boxes, ray, dist);
        child = n->child;
        // Rounding padding can let an empty slot (lo > hi) through; drop those (all 8 slots'
        // references compared at once).
        if (mask) mask &= ~simd::zero_mask8(child);
      }
      st.node(8);
      if (mask == 0) goto pop;
      // The 64-bit ref of child i, read once per child the ray enters (a CQNode8's expanded).
      const uint64_t node_off = NodeRef::offset(cur);
      auto ref = [&](int i) {
        return compact ? cq_child_ref(compact->child[i], node_off,
                                      uint64_t(compact->leaf_base) * kCQLeafBaseUnit)
                       : child[i];
      };
      alignas(32) float d[8];
      dist.store(d);
      int i0 = simd::pop_lowest(mask);
      if (mask == 0) {  // one child hit: descend
        cur = ref(i0);
        continue;
      }
      int i1 = simd::pop_lowest(mask);
      if (mask == 0) {  // two: push the far one
        if (d[i0] <= d[i1]) {
          stack[sp++] = {ref(i1), d[i1]};
          cur = ref(i0);
        } else {
          stack[sp++] = {ref(i0), d[i0]};
          cur = ref(i1);
        }
        prefetch_ref(nodes, leaves, stack[sp - 1].ref);
        continue;
      }
      // Three or more: push all, sort the pushed entries far to near, pop the nearest.
      int base = sp;
      stack[sp++] = {ref(i0), d[i0]};
      stack[sp++] = {ref(i1), d[i1]};
      while (mask) {
        int i = simd::pop_lowest(mask);
        stack[sp++] = {ref(i), d[i]};
      }
      for (int k = base + 1; k < sp; ++k) {
        Entry e = stack[k];
        int j = k;
        while (j > base && stack[j - 1].dist < e.dist) {
          stack[j] = stack[j - 1];
          --j;
        }
        stack[j] = e;
      }
      cur = stack[--sp].ref;
      for (int k = base; k < sp; ++k) prefetch_ref(nodes, leaves, stack[k].ref);
    }

    // Leaf.
    {
      const uint32_t tag = NodeRef::tag(cur);
      if (tag == kRefLeaf) {
        set_watertight_once(ray, watertight_set);
        if (intersect_leaf_blocks<Leaf, kAny>(ctx, leaves + NodeRef::offset(cur),
                                              NodeRef::blocks(cur), block_bytes, ray, hit, st)) {
          found = true;
          if constexpr (kAny) return true;
        }
      } else if (tag == kRefMulti) {
        if (intersect_multileaf<Leaf, kAny>(ctx, leaves + NodeRef::offset(cur),
                                            NodeRef::blocks(cur), block_bytes, ray, watertight_set,
                                            hit, st)) {
          found = true;
          if constexpr (kAny) return true;
        }
      }
    }

  pop:
    for (;;) {
      if (sp == 0) return found;
      const Entry& e = stack[--sp];
      if (!kAny && e.dist > ray.tfar) continue;  // farther than the closest hit so far
      cur = e.ref;
      break;
    }
  }
}

}  // namespace slim
