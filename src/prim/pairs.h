// Triangle-pair leaf format: A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing",
// Imagination Technologies, "Background": a pair of triangles that share an edge is stored as 4
// vertices and tested at once, sharing the maths of the common edge.
//
//   Pair4  256 B  4 pairs = up to 8 triangles: 4 vertices per pair SoA, both input faces per pair,
//                 tested 8 triangles at once (vfloat8); the leaf of bvh8-pairs / clbvh-pairs.
//   Pair2  128 B  the same for 2 pairs, tested 4 triangles at once (vfloat4); slower in our
//                 measurement (api/scene_pairs.cpp), kept for narrower SIMD.
//
// (The text below describes Pair4; Pair2 is the same with groups of 2 lanes and 4-wide loads.)
// A pair is the 4 vertices q0 q1 q2 q3 with the shared edge q1-q2: triangle A = (q0, q1, q2),
// triangle B = (q1, q2, q3). The vertices of the 4 pairs are stored per axis as 4 groups of 4 lanes
// [q0 | q1 | q2 | q3], so the 8-wide windows at groups 0, 1 and 2 give the corners
// a = [q0|q1], b = [q1|q2], c = [q2|q3]: lanes 0-3 are the 4 A triangles, lanes 4-7 the 4 B
// triangles, and one 8-wide watertight test (core/watertight.h) covers all 8 triangles. Only a and
// c go through the ray-space transform; b is their middle halves (one lane permute per axis), so
// each stored vertex is transformed once: 2 8-wide transforms for 8 triangles, where tri4v needs
// 6 4-wide ones (callgrind, igea bvh8-pairs render 160x160: traversal 13.69 -> 13.40 M
// instructions against 3 transforms, the same image). The shared edge q1-q2 is the
// U edge of lanes 0-3 and the W edge of lanes 4-7, computed by the same instructions. The
// alternative, 2 x vfloat4 tests that transform q1, q2 once and negate the shared edge function,
// needs more instructions (4 4-wide transforms, 5 4-wide edge functions, two det/T tails) than
// this 8-wide form on AVX2, where an 8-wide op costs what a 4-wide one does.
//
// Watertightness: every vertex goes through the same ray-space arithmetic as in tri4v, and the
// edge function of a directed edge P->Q is Q.x*P.y - Q.y*P.x in every lane and every format, so a
// neighbour computes the exact negative (or the same value) on a shared edge. B is tested as
// (q1, q2, q3), which may reverse its input winding: that negates all three edge functions, det
// and T, which leaves the inside/outside decision unchanged (and t too, up to the order in which
// the three terms of det and T are summed, as for any rotation of the corners; tri4v may differ
// from it in the last bit of t). The hit record is rebuilt from each triangle's ORIGINAL corner
// order (Ng = (p1 - p0) x (p2 - p0) as in tri4v, u/v = weights of its 2nd/3rd input corner)
// through the per-triangle `order` byte.
//
// Unpaired triangles are degenerate pairs in the same leaves (B lane masked off by `valid`):
// chosen by measurement, see api/scene_pairs.cpp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "core/ray.h"
#include "core/simd.h"
#include "core/simd_ext.h"
#include "core/watertight.h"
#include "prim/triangles.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

constexpr uint32_t kLoneTriangle = 0xffffffffu;

// For a pair sharing the edge (a's corners ea, ea+1) = (b's corners eb, eb+1): true if b's corner
// eb is a's corner ea (by index, or with weld or coordinate keys by position), i.e. both triangles
// run the shared edge the same way (inconsistent windings); false if it is a's corner ea+1.
inline bool shared_edge_same_direction(const Vec3f* vertices, const uint32_t* ta, int ea,
                                       const uint32_t* tb, int eb) {
  const uint32_t b0 = tb[eb], a0 = ta[ea], a1 = ta[(ea + 1) % 3];
  return b0 == a0 || (b0 != a1 && std::memcmp(&vertices[b0], &vertices[a0], 12) == 0);
}

// One pair primitive of the build-time source: triangles a and b (b = kLoneTriangle for a triangle
// left unpaired) sharing a's corners (ea, ea+1 mod 3) = b's corners (eb, eb+1 mod 3), in either
// direction, by position.
struct PairRef {
  uint32_t a = 0, b = kLoneTriangle;
  uint8_t ea = 1, eb = 0;
};

// Triangle pairs prepared from the input meshes (mesh/pairing.h): the build-time source.
struct PairSource {
  TriangleSource tris;
  const PairRef* pairs = nullptr;
};

// Block of W pairs (W = 4: 8-wide, W = 2: 4-wide). Byte budgets: Pair4 256 B, Pair2 128 B.
template <int W>
struct PairBlock {
  float v[3][4 * W];  // 12W floats per axis: [axis][W * vertex + lane], vertex groups q0 q1 q2 q3
  uint32_t prim[2 * W];  // input face of triangle A of pair l (lane l), of B (lane W + l)
  uint32_t geom[W];      // input mesh of pair l (pairs never span two meshes)
  uint8_t order[2 * W];  // per triangle lane, bits 2k..2k+1 = test-order corner (0..2) of the
                         // triangle's input corner k (test order: A = q0 q1 q2, B = q1 q2 q3)
  uint8_t valid;         // lanes holding real triangles (bit l: A of pair l, bit W + l: B)
  uint8_t pair_mask;     // bit l set if pair l holds two triangles (hit kind Pair)
  uint8_t pad[W == 4 ? 6 : 2];  // to 256 / 128 B
};
// Pair4: 192 B vertices + 32 B faces + 16 B meshes + 8 B orders + 2 B masks + 6 B padding.
static_assert(sizeof(PairBlock<4>) == 256, "Pair4 block is 256 bytes");
// Pair2: 96 B vertices + 16 B faces + 8 B meshes + 4 B orders + 2 B masks + 2 B padding.
static_assert(sizeof(PairBlock<2>) == 128, "Pair2 block is 128 bytes");

namespace detail {

// Ray-space transform of the vertices stored SoA at p[axis] (the arithmetic of to_ray_space4).
template <class VF>
SLIM_INLINE RayVertex<VF> to_ray_space_soa(const WatertightRay& r, const float* px, const float* py,
                                           const float* pz) {
  using namespace simd;
  const float* p[3] = {px, py, pz};
  VF ax = VF::loadu(p[r.kx]) - VF(r.ox);
  VF ay = VF::loadu(p[r.ky]) - VF(r.oy);
  VF az = VF::loadu(p[r.kz]) - VF(r.oz);
  return {fnmadd(VF(r.Sx), az, ax), fnmadd(VF(r.Sy), az, ay), VF(r.Sz) * az};
}

SLIM_INLINE uint64_t pair_key(uint64_t ka, uint64_t kb) {
  return ((ka * 0xD6E8FEB86659FD93ULL) ^ (kb + 0x9E3779B97F4A7C15ULL + (ka >> 7))) | 1;
}

}  // namespace detail

// Leaf format: W triangle pairs tested 2W triangles at once.
template <int W>
struct PairLeaf {
  using Block = PairBlock<W>;
  using VF = std::conditional_t<W == 4, simd::vfloat8, simd::vfloat4>;
  struct Context {};
  static constexpr uint32_t kBlockPrims = W;
  static constexpr uint32_t kBlockBytes = sizeof(Block);

  // Scene files' structure check: a block refers to nothing outside itself; its order fields
  // (test-order corners 0..2) keep corner() inside the vertex array.
  static const char* check_block(const Context&, const uint8_t* p) {
    uint8_t order[2 * W];
    std::memcpy(order, p + offsetof(Block, order), sizeof order);
    for (uint8_t o : order)
      for (int k = 0; k < 3; ++k)
        if (((o >> (2 * k)) & 3) > 2) return "pair corner order beyond the triangle's 3 corners";
    return nullptr;
  }

  // Input corner k of the triangle in lane i (0..2W-1) of a block.
  static SLIM_INLINE Vec3f corner(const Block* b, int i, int k) {
    int g = (i >= W) + ((b->order[i] >> (2 * k)) & 3);  // vertex group: A starts at q0, B at q1
    int j = W * g + (i % W);
    return {b->v[0][j], b->v[1][j], b->v[2][j]};
  }

  // ---- build side ----
  static const Vec3f& src_corner(const TriangleSource& s, uint32_t t, int k) {
    return s.vertices[s.tris[3 * size_t(t) + k]];
  }
  static Box3f source_bounds(const PairSource& s, uint32_t i) {
    const PairRef& p = s.pairs[i];
    Box3f box;
    for (int k = 0; k < 3; ++k) box.extend(src_corner(s.tris, p.a, k));
    if (p.b != kLoneTriangle)
      for (int k = 0; k < 3; ++k) box.extend(src_corner(s.tris, p.b, k));
    return box;
  }
  static uint64_t tri_key(const TriangleSource& s, uint32_t t) {
    return triangle_key(src_corner(s, t, 0), src_corner(s, t, 1), src_corner(s, t, 2),
                        s.geom_ids[t], s.prim_ids[t]);
  }
  static uint64_t source_key(const PairSource& s, uint32_t i) {
    const PairRef& p = s.pairs[i];
    uint64_t ka = tri_key(s.tris, p.a);
    return p.b == kLoneTriangle ? ka : detail::pair_key(ka, tri_key(s.tris, p.b));
  }

  static void encode(const PairSource& src, const uint32_t* prims, uint32_t n, uint8_t* out) {
    auto* b = reinterpret_cast<Block*>(out);
    const TriangleSource& s = src.tris;
    b->valid = 0;
    b->pair_mask = 0;
    for (uint32_t l = 0; l < uint32_t(W); ++l) {
      const bool real = l < n;
      const PairRef& p = src.pairs[prims[real ? l : n - 1]];  // empty lanes copy the last pair
      const uint32_t* ta = &s.tris[3 * size_t(p.a)];
      const int ea = p.ea;
      Vec3f q[4];
      q[0] = s.vertices[ta[(ea + 2) % 3]];
      q[1] = s.vertices[ta[ea]];
      q[2] = s.vertices[ta[(ea + 1) % 3]];
      // A's input corner k sits at test position (k - ea + 1) mod 3.
      uint8_t order_a = 0;
      for (int k = 0; k < 3; ++k) order_a |= uint8_t(((k - ea + 4) % 3) << (2 * k));
      uint8_t order_b = 0 | (1 << 2) | (2 << 4);
      uint32_t prim_b = s.prim_ids[p.a];
      if (p.b != kLoneTriangle) {
        const uint32_t* tb = &s.tris[3 * size_t(p.b)];
        const int eb = p.eb;
        q[3] = s.vertices[tb[(eb + 2) % 3]];
        // Does B's edge run q1 -> q2 (same direction as A's, an inconsistent winding) or back?
        const bool same_dir = shared_edge_same_direction(s.vertices, ta, ea, tb, eb);
        const int pos_b0 = same_dir ? 0 : 1, pos_b1 = same_dir ? 1 : 0;
        order_b = uint8_t((pos_b0 << (2 * eb)) | (pos_b1 << (2 * ((eb + 1) % 3))) |
                          (2 << (2 * ((eb + 2) % 3))));
        prim_b = s.prim_ids[p.b];
        if (real) {
          b->valid |= uint8_t((1u | (1u << W)) << l);
          b->pair_mask |= uint8_t(1u << l);
        }
      } else {
        q[3] = q[2];  // masked-off lane: a copy keeps the arithmetic finite
        if (real) b->valid |= uint8_t(1u << l);
      }
      for (int g = 0; g < 4; ++g)
        for (int a = 0; a < 3; ++a) b->v[a][W * g + l] = q[g][a];
      b->prim[l] = s.prim_ids[p.a];
      b->prim[W + l] = prim_b;
      b->geom[l] = s.geom_ids[p.a];
      b->order[l] = order_a;
      b->order[W + l] = order_b;
    }
  }

  // ---- traversal side ----
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context&, const uint8_t* p, TravRay& ray, HitRecord& hit,
                                    Stats& st) {
    using namespace simd;
    const auto* b = reinterpret_cast<const Block*>(p);
    const uint32_t valid = b->valid;
    // Triangles tested, and primitive records: the pairs and lone triangles (lanes 0..W-1).
    if constexpr (!std::is_same_v<Stats, NoStats>)
      st.prims(popcount(valid), popcount(valid & ((1u << W) - 1)));
    // Windows a = [q0|q1], c = [q2|q3] transformed; the overlapping b = [q1|q2] is their middle
    // halves (a lane permute instead of a third transform of q1 and q2: the same bits).
    const float *x = b->v[0], *y = b->v[1], *z = b->v[2];
    const RayVertex<VF> A = detail::to_ray_space_soa<VF>(ray.wt, x, y, z);
    const RayVertex<VF> C = detail::to_ray_space_soa<VF>(ray.wt, x + 2 * W, y + 2 * W, z + 2 * W);
    const RayVertex<VF> B = {mid_halves(A.x, C.x), mid_halves(A.y, C.y), mid_halves(A.z, C.z)};
    VF t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, valid, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    alignas(32) float tt[2 * W], uu[2 * W], vv[2 * W];
    t.storeu(tt);
    int i = pop_lowest(m);
    while (m) {
      int j = pop_lowest(m);
      if (tt[j] < tt[i]) i = j;
    }
    u.storeu(uu);
    v.storeu(vv);
    // Weights of the test-order corners, then of the input corners 1 and 2.
    const float w[3] = {1.0f - uu[i] - vv[i], uu[i], vv[i]};
    const Vec3f p0 = corner(b, i, 0), p1 = corner(b, i, 1), p2 = corner(b, i, 2);
    const int l = i % W;
    detail::record_hit(tt[i], w[(b->order[i] >> 2) & 3], w[(b->order[i] >> 4) & 3], p0, p1, p2,
                       b->geom[l], b->prim[i], ray, hit);
    hit.kind = (b->pair_mask >> l) & 1 ? PrimKind::Pair : PrimKind::Triangle;
    return true;
  }

  // Bounds and key of each pair of a block (validation).
  template <class F>
  static void visit(const Context&, const uint8_t* p, F&& fn) {
    const auto* b = reinterpret_cast<const Block*>(p);
    for (int l = 0; l < W; ++l) {
      if (!((b->valid >> l) & 1)) continue;
      uint64_t key = 0;
      Box3f box;
      for (int h = 0; h < 2; ++h) {
        const int i = W * h + l;
        if (!((b->valid >> i) & 1)) continue;
        Vec3f c[3];
        for (int k = 0; k < 3; ++k) {
          c[k] = corner(b, i, k);
          box.extend(c[k]);
        }
        uint64_t kt = triangle_key(c[0], c[1], c[2], b->geom[l], b->prim[i]);
        key = h == 0 ? kt : detail::pair_key(key, kt);
      }
      fn(box, key);
    }
  }
};

using Pair4 = PairLeaf<4>;  // 256 B: 4 pairs, one 8-wide test
using Pair2 = PairLeaf<2>;  // 128 B: 2 pairs, one 4-wide test
using Pair4Block = PairBlock<4>;
using Pair2Block = PairBlock<2>;

}  // namespace slim
