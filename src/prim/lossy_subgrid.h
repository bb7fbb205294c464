// Lossy compressed 5x5 sub-grids: C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy
// Compressed Grid Primitives", Eurographics 2021 short papers, section 4.
//
// A sub-grid is a bilinear patch through its 4 corner vertices plus 21 displacements (the 25
// vertices minus the corners), each quantized to 3 bytes (section 4.1). Two layouts:
//   LossySubGrid        128 B  the paper's Listing 1: self-contained (corners inside)
//   LossySubGridShared   68 B  section 9 ("future work"): the corners are shared with the
//                              neighbouring sub-grids through a per-grid corner lattice, and the
//                              fields the grid implies (object id, grid position and resolution)
//                              come from the grid side table; even the grid index is implied, by
//                              the lattice corner's position in the scene's corner array
// Both decode to the same vertices for the same displacement codes.
//
// Displacement codes (24 bits, 3 little-endian bytes; the exponent sits at bits 13-18 in both):
//   encoding 1 (section 4.1, the paper's choice):  bits 0-2 octant (sign of x, y, z), 3-12 index
//     into a 1024-entry table of first-octant unit vectors, 13-18 exponent, 19-23 mantissa: the
//     length is the float 2^(exponent + bias - 127) * (1 + mantissa / 32);
//   encoding 2 (section 4.1, the alternative): bits 0-2 signs, 3-7 |x|, 8-12 |y|, 19-23 |z| as
//     5-bit fixed point of the shared scale 2^(exponent + bias - 132), 13-18 shared exponent.
//   Exponent 0 is the zero displacement. Exponent 63 is an escape: the vertex is stored exactly in
//   the scene's exact-vertex array, at (grid's first exact vertex) + the 18 other bits. slimrt uses
//   it for vertices shared with another grid or with leftover triangles, so that both sides decode
//   them to the same bits, and in a build with
//   BuildOptions::lattice_box for the vertices on the meshes' boundary edges: a chunk's cut is a
//   boundary of both chunks, built apart with different grids, and its vertices decode to the
//   input's bits in each (mesh/grids.h, find_exact_positions); a grid's own sub-grid borders need
//   no escape (see below).
//   `bias` is one per scene (from its size, or lattice_box's: the same in every chunk), so that the
//   62 binades cover any displacement.
//
// Watertightness (section 4.3): patch points are lerps (1-t)*a + t*b with per-edge
// weights w0(i) = (n-1-i)/(n-1), w1(i) = i/(n-1), exact at both ends, evaluated as
// w0(j) * (w0(i) c00 + w1(i) c10) + w1(j) * (w0(i) c01 + w1(i) c11), so a border point depends
// only on the two corners of its border; the encoder is deterministic; decoding is IEEE mul/add
// only (no fused ops) in the same order on every path. Two sub-grids sharing a border therefore
// decode its vertices to the same bits, and the watertight triangle test closes the seam.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "core/ray.h"
#include "core/simd.h"
#include "core/simd_ext.h"
#include "prim/subgrid.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

// ---- unit vector table (section 4.1) ---------------------------------------------------------

// 1024 unit vectors of the first octant, on 45 rings of an equal-area map of the octant
// (Clarberg, "Fast equal-area mapping of the (hemi)sphere using SIMD", 2008): ring r at radius
// rho = r/44 (z = 1 - rho^2), ring r holding r+1 points (one fewer on rings 4, 8, ..., 44, so that
// there are exactly 1024) evenly spaced in azimuth from the xz-plane to the yz-plane inclusive.
// The poles and octant borders are in the table, so pure axis or in-plane displacements (a
// heightfield's) are exact in direction.
struct UnitVectorTable {
  static constexpr int kRings = 45;
  static constexpr int kEntries = 1024;
  alignas(64) float x[kEntries];
  alignas(64) float y[kEntries];
  alignas(64) float z[kEntries];
  // The same vectors interleaved (x, y, z, 0): the decoder fetches one 16-byte row per code and
  // transposes 8 of them (simd::gather_xyz), instead of three 8-lane gathers, which are slow on
  // some cores (AMD Zen 4: ~20 ns more per half sub-grid in a loop over cached blocks).
  alignas(64) float xyz[kEntries][4];
  uint16_t ring_start[kRings + 1];

  UnitVectorTable();
  // Up to 9 entries around the direction d (components >= 0, |d| > 0): the 3x3 neighbourhood of
  // its ring and azimuth cell. O(1); contains the nearest entry for all but rare directions
  // (nearest() checks them all the same way).
  int candidates(const double d[3], uint32_t out[9]) const;
  // The entry with the largest dot product among candidates(d).
  uint32_t nearest(const double d[3]) const;
};
extern const UnitVectorTable kUnitVectors;

// ---- displacement codes (section 4.1) ---------------------------------------------------------

constexpr uint32_t kDisplExpShift = 13;
constexpr uint32_t kDisplEscape = 63;
constexpr uint32_t kMaxExactIndex = (1u << 18) - 1;

SLIM_INLINE uint32_t displ_exponent(uint32_t code) { return (code >> kDisplExpShift) & 63; }
SLIM_INLINE uint32_t escape_code(uint32_t index) {
  return (index & 0x1fff) | (kDisplEscape << kDisplExpShift) | ((index >> 13) << 19);
}
SLIM_INLINE uint32_t escape_index(uint32_t code) { return (code & 0x1fff) | ((code >> 19) << 13); }

SLIM_INLINE uint32_t load_code(const uint8_t* p) {
  return uint32_t(p[0]) | (uint32_t(p[1]) << 8) | (uint32_t(p[2]) << 16);
}
SLIM_INLINE void store_code(uint8_t* p, uint32_t c) {
  p[0] = uint8_t(c);
  p[1] = uint8_t(c >> 8);
  p[2] = uint8_t(c >> 16);
}

SLIM_INLINE float float_from_bits(uint32_t b) {
  float f;
  std::memcpy(&f, &b, 4);
  return f;
}

// Scene-wide exponent bias for a scene whose box has diagonal `diag` (see the header comment).
int displacement_bias(float diag);

// The decoded vertex patch + displacement(code), exactly as the SIMD decoder computes it (not for
// escape codes). kEnc = 1 or 2.
template <int kEnc>
SLIM_INLINE Vec3f decode_vertex(const Vec3f& patch, uint32_t code, int bias) {
  const uint32_t e = displ_exponent(code);
  float c[3];
  if constexpr (kEnc == 1) {
    const uint32_t k = (code >> 3) & 1023, m = code >> 19;
    const float len = e ? float_from_bits(((e + uint32_t(bias)) << 23) | (m << 18)) : 0.0f;
    c[0] = kUnitVectors.x[k] * len;
    c[1] = kUnitVectors.y[k] * len;
    c[2] = kUnitVectors.z[k] * len;
  } else {
    const float scale = e ? float_from_bits((e + uint32_t(bias) - 5) << 23) : 0.0f;
    c[0] = float((code >> 3) & 31) * scale;
    c[1] = float((code >> 8) & 31) * scale;
    c[2] = float(code >> 19) * scale;
  }
  for (int a = 0; a < 3; ++a)
    if (code & (1u << a)) c[a] = -c[a];
  return {patch.x + c[0], patch.y + c[1], patch.z + c[2]};
}

// The code whose decoded vertex (decode_vertex) is closest to `target`: encoding 1 tries the
// table candidates around the direction with the two nearest lengths each; encoding 2 the
// smallest shared exponent that holds the largest component, each mantissa rounded both ways.
// Deterministic: the same (patch, target, bias) always gives the same code.
uint32_t encode_displacement1(const Vec3f& patch, const Vec3f& target, int bias);
uint32_t encode_displacement2(const Vec3f& patch, const Vec3f& target, int bias);
template <int kEnc>
uint32_t encode_displacement(const Vec3f& patch, const Vec3f& target, int bias) {
  return kEnc == 1 ? encode_displacement1(patch, target, bias)
                   : encode_displacement2(patch, target, bias);
}

// ---- bilinear patch (section 4) ---------------------------------------------------------------

// Lane tables of the patch weights for a sub-grid of n vertices along an axis (n = 2..5): lane
// k = 5*j + i of u0/u1 holds w0(i)/w1(i), of v0/v1 w0(j)/w1(j); positions past n repeat the last
// one (so unused lanes hold border copies), lanes 25-31 are 0.
struct PatchWeights {
  alignas(32) float u0[6][32];
  alignas(32) float u1[6][32];
  alignas(32) float v0[6][32];
  alignas(32) float v1[6][32];
  float w0[6][5], w1[6][5];  // scalar weights
  PatchWeights();
};
extern const PatchWeights kPatchWeights;

// Patch point (i, j) of a res_x x res_y sub-grid with corners c[0] = (0,0), c[1] = (res_x-1, 0),
// c[2] = (0, res_y-1), c[3] = (res_x-1, res_y-1): the scalar twin of the SIMD evaluation.
SLIM_INLINE Vec3f patch_point(const Vec3f c[4], uint32_t i, uint32_t j, uint32_t res_x,
                              uint32_t res_y) {
  const float a0 = kPatchWeights.w0[res_x][i], a1 = kPatchWeights.w1[res_x][i];
  const float b0 = kPatchWeights.w0[res_y][j], b1 = kPatchWeights.w1[res_y][j];
  Vec3f r;
  for (int a = 0; a < 3; ++a) {
    const float top = a0 * c[0][a] + a1 * c[1][a];
    const float bot = a0 * c[2][a] + a1 * c[3][a];
    r[a] = b0 * top + b1 * bot;
  }
  return r;
}

// Position (row-major k = 5*j + i) of displacement slot s (0..20): the 25 positions of the 5x5
// layout without the corners 0, 4, 20, 24.
SLIM_INLINE int displ_slot_position(int s) { return s < 3 ? s + 1 : s < 18 ? s + 2 : s + 3; }
// Slot of position k, or -1 for the 4 corners of the 5x5 layout.
SLIM_INLINE int displ_position_slot(int k) {
  if (k == 0 || k == 4 || k == 20 || k == 24) return -1;
  return k < 4 ? k - 1 : k < 20 ? k - 2 : k - 3;
}

namespace detail {

// pshufb control and source offsets that unpack the 3-byte codes of 8 consecutive positions
// (lanes of group g = positions 8g .. 8g+7) into 8 ints; corner lanes get 0.
struct CodeUnpack {
  alignas(32) uint8_t ctrl[3][32];
  uint8_t lo[3], hi[3];  // byte offsets of the two 16-byte source windows
  CodeUnpack();
};
extern const CodeUnpack kCodeUnpack;

// The same for the 8 code lanes of each quarter (prim/subgrid.h QuarterTables: lanes 0-7 are the
// quarter's vertices other than the sub-grid corner): their codes lie in up to 4 windows, so two
// shuffles are OR-ed; and the patch weights of those lanes per resolution.
struct QuarterUnpack {
  alignas(32) uint8_t ctrl[4][2][32];
  uint8_t lo[4][2], hi[4][2];
  alignas(32) float u0[6][4][8];  // [res_x][quarter][lane]
  alignas(32) float u1[6][4][8];
  alignas(32) float v0[6][4][8];  // [res_y][quarter][lane]
  alignas(32) float v1[6][4][8];
  QuarterUnpack();
};
extern const QuarterUnpack kQuarterUnpack;

// Section 4.3 for 8 lanes: the patch at weights (u0, u1, v0, v1) from the broadcast corners c
// plus the decoded displacement `code`, stored to x, y, z. Returns the lanes with escape codes.
template <int kEnc>
SLIM_INLINE uint32_t decode_lanes(simd::vint8 code, simd::vfloat8 u0, simd::vfloat8 u1,
                                  simd::vfloat8 v0, simd::vfloat8 v1, const simd::vfloat8 (*c)[4],
                                  int bias, float* x, float* y, float* z) {
  using namespace simd;
  vfloat8 d[3];
  const vint8 e = iand(shr<kDisplExpShift>(code), vint8(63));
  const vbool8 zero = ieq(e, vint8(0));
  const uint32_t esc = ieq(e, vint8(int(kDisplEscape))).mask();
  if constexpr (kEnc == 1) {
    const vint8 k = iand(shr<3>(code), vint8(1023));
    const vint8 m = shr<19>(code);
    const vfloat8 len =
        select(zero, vfloat8(0.0f), as_float(ior(shl<23>(e + vint8(bias)), shl<18>(m))));
    gather_xyz(kUnitVectors.xyz, k, d[0], d[1], d[2]);
    d[0] = d[0] * len;
    d[1] = d[1] * len;
    d[2] = d[2] * len;
  } else {
    const vfloat8 scale = select(zero, vfloat8(0.0f), as_float(shl<23>(e + vint8(bias - 5))));
    d[0] = to_float(iand(shr<3>(code), vint8(31))) * scale;
    d[1] = to_float(iand(shr<8>(code), vint8(31))) * scale;
    d[2] = to_float(shr<19>(code)) * scale;
  }
  d[0] = d[0] ^ as_float(shl<31>(code));
  d[1] = d[1] ^ as_float(shl<31>(shr<1>(code)));
  d[2] = d[2] ^ as_float(shl<31>(shr<2>(code)));
  float* out[3] = {x, y, z};
  for (int a = 0; a < 3; ++a) {
    const vfloat8 top = u0 * c[a][0] + u1 * c[a][1];
    const vfloat8 bot = u0 * c[a][2] + u1 * c[a][3];
    (v0 * top + v1 * bot + d[a]).store(out[a]);
  }
  return esc;
}

SLIM_INLINE void broadcast_corners(const Vec3f corner[4], simd::vfloat8 (*c)[4]) {
  for (int q = 0; q < 4; ++q) {
    c[0][q] = simd::vfloat8(corner[q].x);
    c[1][q] = simd::vfloat8(corner[q].y);
    c[2][q] = simd::vfloat8(corner[q].z);
  }
}

}  // namespace detail

// Decompression (section 4.3), 8 positions at a time: patch + decoded displacement for the 25
// vertices. `corner` = the 4 patch corners (c00, c10, c01, c11), `displ` = the 63 code bytes
// (the 16-byte windows read at most up to the res byte after them). Escape codes are left for the
// caller: the return value has bit k set for each position k with an escape code, whose code is
// then in codes[k]. Only the position groups g0 .. g1-1 are decoded (positions 8*g0 .. 8*g1-1, and
// 24 if g1 = 3): a half sub-grid needs groups 0-1 (vertex rows 0-2) or 1-2 (rows 2-4).
template <int kEnc>
SLIM_INLINE uint32_t decode_subgrid(const Vec3f corner[4], const uint8_t* displ, uint32_t res_x,
                                    uint32_t res_y, int bias, SubGridVerts& w, uint32_t* codes,
                                    int g0 = 0, int g1 = 3) {
  using namespace simd;
  const PatchWeights& pw = kPatchWeights;
  const detail::CodeUnpack& cu = detail::kCodeUnpack;
  uint32_t escapes = 0;
  vfloat8 c[3][4];
  detail::broadcast_corners(corner, c);
  for (int g = g0; g < g1; ++g) {
    const vint8 code = load_shuffle_2x16(displ + cu.lo[g], displ + cu.hi[g], cu.ctrl[g]);
    const uint32_t esc = detail::decode_lanes<kEnc>(
        code, vfloat8::load(&pw.u0[res_x][8 * g]), vfloat8::load(&pw.u1[res_x][8 * g]),
        vfloat8::load(&pw.v0[res_y][8 * g]), vfloat8::load(&pw.v1[res_y][8 * g]), c, bias,
        &w.p[0][8 * g], &w.p[1][8 * g], &w.p[2][8 * g]);
    if (esc) {
      escapes |= esc << (8 * g);
      code.storeu(reinterpret_cast<int32_t*>(codes + 8 * g));
    }
  }
  // Position 24 is the patch corner (4,4), or unused in a partial sub-grid (where its clamped
  // weights give the same): the patch evaluates it to c11 exactly, plus a zero displacement.
  if (g1 < 3) return escapes;
  for (int a = 0; a < 3; ++a) {
    alignas(32) float last[8] = {corner[3][a] + 0.0f, 0, 0, 0, 0, 0, 0, 0};
    vfloat8::load(last).store(&w.p[a][24]);
  }
  return escapes;
}

// Decompression of quarter q (prim/subgrid.h): lanes 0-7 of w as decode_subgrid computes those
// positions, lane 8 the sub-grid corner of the quarter (c00, c10, c01, c11 for q = 0..3; the
// patch evaluates a corner to itself plus a zero displacement, see above; in a partial sub-grid
// whose quarter does not reach that corner, the lane is unused). Returns the lanes with escape
// codes, whose codes are then in codes[0..7].
template <int kEnc>
SLIM_INLINE uint32_t decode_quarter(const Vec3f corner[4], const uint8_t* displ, uint32_t res_x,
                                    uint32_t res_y, int bias, uint32_t q, QuarterVerts& w,
                                    uint32_t* codes) {
  using namespace simd;
  const detail::QuarterUnpack& qu = detail::kQuarterUnpack;
  vfloat8 c[3][4];
  detail::broadcast_corners(corner, c);
  const vint8 code =
      ior(load_shuffle_2x16(displ + qu.lo[q][0], displ + qu.hi[q][0], qu.ctrl[q][0]),
          load_shuffle_2x16(displ + qu.lo[q][1], displ + qu.hi[q][1], qu.ctrl[q][1]));
  const uint32_t esc =
      detail::decode_lanes<kEnc>(code, vfloat8::load(qu.u0[res_x][q]),
                                 vfloat8::load(qu.u1[res_x][q]), vfloat8::load(qu.v0[res_y][q]),
                                 vfloat8::load(qu.v1[res_y][q]), c, bias, w.p[0], w.p[1], w.p[2]);
  if (esc) code.storeu(reinterpret_cast<int32_t*>(codes));
  const Vec3f& cq = corner[q];
  w.p[0][8] = cq.x + 0.0f;
  w.p[1][8] = cq.y + 0.0f;
  w.p[2][8] = cq.z + 0.0f;
  return esc;
}

// Replaces the escaped positions (or quarter lanes) by their exact vertices.
template <class Verts>
SLIM_INLINE void apply_escapes(uint32_t escapes, const uint32_t* codes, const Vec3f* exact,
                               Verts& w) {
  while (escapes) {
    const int k = simd::pop_lowest(escapes);
    const Vec3f& p = exact[escape_index(codes[k])];
    w.p[0][k] = p.x;
    w.p[1][k] = p.y;
    w.p[2][k] = p.z;
  }
}

// ---- Listing 1: the self-contained 128-byte sub-grid -----------------------------------------

struct LossySubGrid {
  Vec3f corner[4];          // 48 B: bilinearPatchVtx: sub-grid vertices (0,0), (res_x-1,0),
                            //       (0,res_y-1), (res_x-1,res_y-1), exact floats
  uint8_t displ[63];        // 63 B: 21 displacement codes, slots in row-major position order
  uint8_t res;              //  1 B: resX (bits 0-3), resY (bits 4-7): 2..5 vertices
  uint32_t object_id;       //  4 B: input mesh (Hit::geomID)
  uint32_t primitive_id;    //  4 B: grid (GridInfo index: input faces, exact vertices)
  uint16_t grid_x, grid_y;  //  4 B: position of vertex (0,0) in the grid
  uint16_t grid_res_x, grid_res_y;  // 4 B: the grid's resolution (per-grid u,v, section 5)
};
static_assert(sizeof(LossySubGrid) == 128, "Listing 1: the lossy 5x5 sub-grid is 128 bytes");
static_assert(offsetof(LossySubGrid, displ) == 48 && offsetof(LossySubGrid, res) == 111 &&
                  offsetof(LossySubGrid, object_id) == 112,
              "Listing 1 field order");

// ---- section 9: corners shared through the grid's corner lattice, 68 bytes -------------------

// The corner lattice of a grid (GridHot::lattice_first / lattice_row): the vertices at x in
// {0, 4, 8, ..., res_x-1} and y in {0, 4, ..., res_y-1}, row-major, in the scene's corner array.
// Each corner is stored once for the up to 4 sub-grids around it. The lattices lie in grid order,
// so the corner index also names the grid (LossySharedLeaf::grid): no grid field in the block.
struct LossySubGridShared {
  uint8_t displ[63];  // 63 B: as in Listing 1
  uint8_t res;        //  1 B: resX (bits 0-3), resY (bits 4-7)
  uint32_t corner;    //  4 B: lattice corner of vertex (0,0) in the scene's corner array; the
                      //       others are corner+1, corner+row, corner+row+1
};
static_assert(sizeof(LossySubGridShared) == 68, "shared-corner lossy sub-grid is 68 bytes");

// The grid of a lattice corner: LossyContext::corner_grid[c >> kCornerChunkShift] is the grid
// whose lattice holds corner (c >> kCornerChunkShift) << kCornerChunkShift; the grids whose
// lattices start later in the chunk follow it. A lattice has at least 2 x 2 corners, so at most 4
// start inside a chunk of 16: the look-up is one table read and at most 4 steps.
constexpr uint32_t kCornerChunkShift = 4;

// ---- leaf formats ---------------------------------------------------------------------------

// Build-time source for both lossy leaves: encoded blocks and their (decoded) bounds; with
// parts > 1 (2 or 4 boxes per block: its halves or quarters, prim/subgrid.h, in part_bounds) the
// compressed-leaf BVH gives each sub-grid of a multi-leaf that many child boxes.
struct LossySource {
  const uint8_t* blocks = nullptr;
  uint32_t block_bytes = 0;
  const Box3f* bounds = nullptr;
  uint32_t parts = 1;
  const Box3f* part_bounds = nullptr;  // parts per block
};

struct LossyContext {
  const GridInfo* grids = nullptr;
  const GridHot* hot = nullptr;
  const uint32_t* faces = nullptr;        // face table
  const uint16_t* flips = nullptr;        // flip masks
  const Vec3f* exact = nullptr;           // exact vertices (escape codes)
  const Vec3f* corners = nullptr;         // shared layout: corner lattices
  const uint32_t* corner_grid = nullptr;  // shared layout: per 16 corners (kCornerChunkShift)
  uint32_t grid_count = 0;                // shared layout: grids (entries of hot)
  int bias = 0;
  uint32_t parts = 1;    // multi-leaf children per sub-grid: 1, 2 (halves) or 4 (quarters)
  GridTableSizes sizes;  // scene files' structure check
};

// What both lossy leaves share: decoding, the build-side hooks, the whole, half and quarter
// sub-grid tests, the multi-leaf layout and validation. Leaf provides
//   static uint32_t grid(ctx, block)                   // the block's grid (GridInfo index)
//   static void corners(ctx, block, grid, Vec3f c[4])  // patch corners c00, c10, c01, c11
//   static uint32_t flips(ctx, block, grid)
//   static void record(ctx, block, grid, SubGridHit, HitRecord&)
template <class Leaf, class Block, int kEnc>
struct LossyLeafBase {
  using Context = LossyContext;
  static constexpr uint32_t kBlockPrims = 1;
  static constexpr uint32_t kBlockBytes = sizeof(Block);
  static constexpr bool kMultiLeafLayout = true;
  using Source = LossySource;

  static Box3f source_bounds(const Source& s, uint32_t i) { return s.bounds[i]; }
  static uint64_t source_key(const Source& s, uint32_t i) {
    return subgrid_key(s.blocks + uint64_t(i) * kBlockBytes, kBlockBytes);
  }
  static void encode(const Source& s, const uint32_t* prims, uint32_t, uint8_t* out) {
    std::memcpy(out, s.blocks + uint64_t(prims[0]) * kBlockBytes, kBlockBytes);
  }
  // Multi-leaf children per block (LeafEncoder::parts_per_block) and their boxes.
  static uint32_t multileaf_parts(const Source& s) { return s.parts; }
  static void part_bounds(const Source& s, uint32_t i, Box3f* out) {
    for (uint32_t k = 0; k < s.parts; ++k) out[k] = s.part_bounds[uint64_t(s.parts) * i + k];
  }
  // Multi-leaf child i is the first part of its block (validate() counts each block once).
  static bool primary_part(const Context& ctx, uint32_t i) { return i % ctx.parts == 0; }

  // Scene files' structure check (OpenOptions::check_structure): the block's resolution and its
  // grid's table entries (Leaf::check_block), then what both layouts read through the grid: the
  // exact vertices of escape codes, the flip mask (entry `flip_index` when the grid has flips)
  // and the face table entries of its cells at grid position (gx, gy).
  static const char* check_grid_refs(const Context& ctx, const Block& b, uint32_t grid,
                                     uint32_t flip_index, uint32_t gx, uint32_t gy) {
    const GridHot& h = ctx.hot[grid];
    for (int s = 0; s < 21; ++s) {
      const uint32_t code = load_code(b.displ + 3 * s);
      if (displ_exponent(code) == kDisplEscape &&
          uint64_t(h.exact) + escape_index(code) >= ctx.sizes.exact)
        return "escape code beyond the exact vertices (grid.exact)";
    }
    if (h.flips != kNoFlips && flip_index >= ctx.sizes.flips)
      return "flip mask index beyond the flip table (grid.flips)";
    return check_grid_faces(ctx.grids[grid], ctx.sizes.faces, gx, gy, b.res & 15, b.res >> 4);
  }
  // A multi-leaf's blocks: child i reads block i / parts (intersect_in_multileaf).
  static const char* check_multileaf(const Context& ctx, const uint8_t* data, uint32_t k,
                                     uint64_t avail) {
    if (ctx.parts != 1 && ctx.parts != 2 && ctx.parts != 4)
      return "sub-grid parts other than 1, 2 or 4 (grid.params)";
    const uint64_t blocks = (k - 1) / ctx.parts + 1;
    if (blocks * kBlockBytes > avail) return "multi-leaf blocks beyond the leaf arena";
    for (uint64_t i = 0; i < blocks; ++i)
      if (const char* e = Leaf::check_block(ctx, data + i * kBlockBytes)) return e;
    return nullptr;
  }

  // Code groups g0 .. g1-1 of the block, escapes applied.
  static SLIM_INLINE void decode(const Context& ctx, const Block& b, SubGridVerts& w, int g0 = 0,
                                 int g1 = 3) {
    decode(ctx, b, Leaf::grid(ctx, b), w, g0, g1);
  }
  static SLIM_INLINE void decode(const Context& ctx, const Block& b, uint32_t grid, SubGridVerts& w,
                                 int g0 = 0, int g1 = 3) {
    Vec3f c[4];
    Leaf::corners(ctx, b, grid, c);
    alignas(32) uint32_t codes[32];
    const uint32_t esc =
        decode_subgrid<kEnc>(c, b.displ, b.res & 15, b.res >> 4, ctx.bias, w, codes, g0, g1);
    if (esc) apply_escapes(esc, codes, exact(ctx, grid), w);
  }
  // The grid's exact vertices (escape codes).
  static SLIM_INLINE const Vec3f* exact(const Context& ctx, uint32_t grid) {
    return ctx.exact + ctx.hot[grid].exact;
  }

  // The whole sub-grid: every code group, ray-space group and row.
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context& ctx, const uint8_t* p, TravRay& ray,
                                    HitRecord& hit, Stats& st) {
    const auto& b = *reinterpret_cast<const Block*>(p);
    return intersect_rows<kAny>(ctx, b, 0, 3, 0, 4, 0, (b.res >> 4) - 1u, ray, hit, st);
  }

  // Half `half` of the sub-grid: code groups half, half+1; ray-space groups 0-1 or 1-3.
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_half(const Context& ctx, const uint8_t* p, uint32_t half,
                                         TravRay& ray, HitRecord& hit, Stats& st) {
    const auto& b = *reinterpret_cast<const Block*>(p);
    uint32_t j0, j1;
    subgrid_half_rows(half, b.res >> 4, j0, j1);
    if (j0 >= j1) return false;
    const int h = int(half);
    return intersect_rows<kAny>(ctx, b, h, h + 2, h, h == 0 ? 2 : 4, j0, j1, ray, hit, st);
  }

  // Quarter q of the sub-grid: one 8-lane decode, one 8-wide test.
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_quarter(const Context& ctx, const uint8_t* p, uint32_t q,
                                            TravRay& ray, HitRecord& hit, Stats& st) {
    const auto& b = *reinterpret_cast<const Block*>(p);
    const uint32_t res_x = b.res & 15, res_y = b.res >> 4;
    uint32_t i0, i1, j0, j1;
    subgrid_part_cells(4, q, res_x, res_y, i0, i1, j0, j1);
    if (i0 >= i1 || j0 >= j1) return false;  // no cell
    simd::prefetch(reinterpret_cast<const uint8_t*>(&b) + 64);
    const uint32_t grid = Leaf::grid(ctx, b);
    Vec3f c[4];
    Leaf::corners(ctx, b, grid, c);
    QuarterVerts w;
    alignas(32) uint32_t codes[8];
    const uint32_t esc = decode_quarter<kEnc>(c, b.displ, res_x, res_y, ctx.bias, q, w, codes);
    if (esc) apply_escapes(esc, codes, exact(ctx, grid), w);
    SubGridHit h;
    if (!intersect_subgrid_quarter<kAny>(w, q, i0, i1, j0, j1, Leaf::flips(ctx, b, grid), ray, h,
                                         st))
      return false;
    if constexpr (!kAny) Leaf::record(ctx, b, grid, h, hit);
    return true;
  }

  // Decodes code groups [cg0, cg1), moves ray-space groups [rg0, rg1) and tests cell rows
  // [j0, j1).
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_rows(const Context& ctx, const Block& b, int cg0, int cg1,
                                         int rg0, int rg1, uint32_t j0, uint32_t j1, TravRay& ray,
                                         HitRecord& hit, Stats& st) {
    // The codes' cache line, fetched alongside the first one.
    simd::prefetch(reinterpret_cast<const uint8_t*>(&b) + 64);
    const uint32_t grid = Leaf::grid(ctx, b);
    SubGridVerts w;
    decode(ctx, b, grid, w, cg0, cg1);
    alignas(32) float r[3][32];
    subgrid_to_ray_space(ray.wt, w, r, rg0, rg1);
    SubGridHit h;
    if (!intersect_subgrid_rows<kAny>(w, r, b.res & 15, j0, j1, Leaf::flips(ctx, b, grid), ray, h,
                                      st))
      return false;
    if constexpr (!kAny) Leaf::record(ctx, b, grid, h, hit);
    return true;
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_in_multileaf(const Context& ctx, const uint8_t* data, uint32_t,
                                                 int i, TravRay& ray, HitRecord& hit, Stats& st) {
    if (ctx.parts == 4)
      return intersect_quarter<kAny>(ctx, data + uint64_t(i >> 2) * kBlockBytes, uint32_t(i & 3),
                                     ray, hit, st);
    if (ctx.parts == 2)
      return intersect_half<kAny>(ctx, data + uint64_t(i >> 1) * kBlockBytes, uint32_t(i & 1), ray,
                                  hit, st);
    return intersect<kAny>(ctx, data + uint64_t(i) * kBlockBytes, ray, hit, st);
  }

  template <class F>
  static void visit(const Context& ctx, const uint8_t* p, F&& fn) {
    const auto& b = *reinterpret_cast<const Block*>(p);
    SubGridVerts w;
    decode(ctx, b, w);
    fn(subgrid_bounds(w, b.res & 15, b.res >> 4), subgrid_key(p, kBlockBytes));
  }
  template <class F>
  static void visit_in_multileaf(const Context& ctx, const uint8_t* data, uint32_t, int i, F&& fn) {
    const uint8_t* p = data + uint64_t(i / ctx.parts) * kBlockBytes;
    const auto& b = *reinterpret_cast<const Block*>(p);
    SubGridVerts w;
    decode(ctx, b, w);
    fn(subgrid_part_bounds(w, b.res & 15, b.res >> 4, ctx.parts, uint32_t(i) % ctx.parts),
       subgrid_key(p, kBlockBytes));
  }
};

// Leaf format: one LossySubGrid (Listing 1) per block.
template <int kEnc>
struct LossyGridLeaf : LossyLeafBase<LossyGridLeaf<kEnc>, LossySubGrid, kEnc> {
  using Context = LossyContext;

  static SLIM_INLINE uint32_t grid(const Context&, const LossySubGrid& b) { return b.primitive_id; }
  static SLIM_INLINE uint32_t flip_index(const Context& ctx, const LossySubGrid& b, uint32_t grid) {
    return subgrid_flip_index(ctx.hot[grid], b.grid_x / kSubGridCells, b.grid_y / kSubGridCells,
                              (b.grid_res_x + kSubGridCells - 2) / kSubGridCells);
  }
  static const char* check_block(const Context& ctx, const uint8_t* p) {
    LossySubGrid b;
    std::memcpy(&b, p, sizeof b);
    if (!subgrid_res_ok(b.res & 15, b.res >> 4)) return "sub-grid resolution outside 2..5";
    const uint32_t g = grid(ctx, b);
    if (g >= ctx.sizes.grids || g >= ctx.sizes.hot)
      return "grid index beyond the grid tables (grid.table, grid.hot)";
    return LossyGridLeaf::check_grid_refs(ctx, b, g, flip_index(ctx, b, g), b.grid_x, b.grid_y);
  }
  static SLIM_INLINE void corners(const Context&, const LossySubGrid& b, uint32_t, Vec3f c[4]) {
    for (int k = 0; k < 4; ++k) c[k] = b.corner[k];
  }
  static SLIM_INLINE uint32_t flips(const Context& ctx, const LossySubGrid& b, uint32_t grid) {
    return ctx.hot[grid].flips == kNoFlips ? 0u : ctx.flips[flip_index(ctx, b, grid)];
  }
  static SLIM_INLINE void record(const Context& ctx, const LossySubGrid& b, uint32_t grid,
                                 const SubGridHit& h, HitRecord& hit) {
    record_grid_hit(h, ctx.grids[grid], ctx.faces, b.grid_x, b.grid_y, hit);
  }
};

// Leaf format: one LossySubGridShared per block.
template <int kEnc>
struct LossySharedLeaf : LossyLeafBase<LossySharedLeaf<kEnc>, LossySubGridShared, kEnc> {
  using Context = LossyContext;

  // The grid whose lattice holds b.corner (see kCornerChunkShift).
  static SLIM_INLINE uint32_t grid(const Context& ctx, const LossySubGridShared& b) {
    uint32_t g = ctx.corner_grid[b.corner >> kCornerChunkShift];
    while (g + 1 < ctx.grid_count && ctx.hot[g + 1].lattice_first <= b.corner) ++g;
    return g;
  }
  static SLIM_INLINE void corners(const Context& ctx, const LossySubGridShared& b, uint32_t grid,
                                  Vec3f c[4]) {
    const uint32_t row = ctx.hot[grid].lattice_row;
    c[0] = ctx.corners[b.corner];
    c[1] = ctx.corners[b.corner + 1];
    c[2] = ctx.corners[b.corner + row];
    c[3] = ctx.corners[b.corner + row + 1];
  }
  // Sub-grid position (sx, sy) in its grid, from its lattice corner.
  static SLIM_INLINE void position(const GridHot& g, const LossySubGridShared& b, uint32_t& sx,
                                   uint32_t& sy) {
    const uint32_t c = b.corner - g.lattice_first;
    sx = c % g.lattice_row;
    sy = c / g.lattice_row;
  }
  static SLIM_INLINE uint32_t flips(const Context& ctx, const LossySubGridShared& b,
                                    uint32_t grid) {
    const GridHot& g = ctx.hot[grid];
    if (g.flips == kNoFlips) return 0;
    uint32_t sx, sy;
    position(g, b, sx, sy);
    return subgrid_flips(g, ctx.flips, sx, sy, g.lattice_row - 1);
  }
  // Scene files' structure check: the corner chunk table and the grid it names (found in at most
  // kMaxGridSteps steps, as in a file the builder wrote), the four lattice corners, then the
  // references both layouts share.
  static constexpr uint32_t kMaxGridSteps = 16;
  static const char* check_block(const Context& ctx, const uint8_t* p) {
    LossySubGridShared b;
    std::memcpy(&b, p, sizeof b);
    if (!subgrid_res_ok(b.res & 15, b.res >> 4)) return "sub-grid resolution outside 2..5";
    if ((b.corner >> kCornerChunkShift) >= ctx.sizes.corner_grid)
      return "lattice corner beyond the corner chunk table (grid.corner_grid)";
    if (ctx.grid_count > ctx.sizes.hot || ctx.grid_count > ctx.sizes.grids)
      return "grid count beyond the grid tables (grid.params)";
    // grid(), counting its steps.
    uint32_t g = ctx.corner_grid[b.corner >> kCornerChunkShift];
    for (uint32_t steps = 0; g + 1 < ctx.grid_count && ctx.hot[g + 1].lattice_first <= b.corner;
         ++steps) {
      if (steps == kMaxGridSteps)
        return "corner chunk table entry far before the corner's grid (grid.corner_grid)";
      ++g;
    }
    if (g >= ctx.grid_count) return "corner chunk table entry beyond the grids (grid.corner_grid)";
    const GridHot& h = ctx.hot[g];
    if (h.lattice_row == 0) return "grid lattice of zero corners per row (grid.hot)";
    const uint32_t row = h.lattice_row;
    for (uint32_t c : {b.corner, b.corner + 1, b.corner + row, b.corner + row + 1})
      if (c >= ctx.sizes.corners) return "lattice corner beyond the corner array (grid.corners)";
    uint32_t sx, sy;
    position(h, b, sx, sy);
    return LossySharedLeaf::check_grid_refs(ctx, b, g, subgrid_flip_index(h, sx, sy, row - 1),
                                            kSubGridCells * sx, kSubGridCells * sy);
  }
  static SLIM_INLINE void record(const Context& ctx, const LossySubGridShared& b, uint32_t grid,
                                 const SubGridHit& h, HitRecord& hit) {
    uint32_t sx, sy;
    position(ctx.hot[grid], b, sx, sy);
    record_grid_hit(h, ctx.grids[grid], ctx.faces, kSubGridCells * sx, kSubGridCells * sy, hit);
  }
};

// ---- encoder --------------------------------------------------------------------------------

// One sub-grid to encode: its res_x x res_y vertices v[5*j + i] (the original floats) and, per
// position, kNotExact or the index in its grid's exact-vertex list.
constexpr uint32_t kNotExact = 0xffffffffu;
struct SubGridInput {
  Vec3f v[25];
  uint32_t exact[25];
  uint32_t res_x = 5, res_y = 5;
};

// Encodes the 21 displacement codes of the sub-grid (corners = v at the 4 patch corners) into
// displ[63]; positions outside res_x x res_y and the patch corners get code 0.
template <int kEnc>
void encode_subgrid(const SubGridInput& in, int bias, uint8_t displ[63]);

}  // namespace slim
