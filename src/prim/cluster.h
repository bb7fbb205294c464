// Compressed triangle clusters (configurations `cluster` and `cluster-lossless`), after AMD's Dense
// Geometry Format (DGF, HPG 2024): positions on one scene-wide integer lattice with a step of at
// most 4 significant bits per axis, each cluster an anchor plus per-axis bit widths and bit-packed
// offsets, topology as generalized triangle strips (DGF's control bits and implicit new-vertex
// indices), and primIDs as runs (Elias-Fano coded run starts, a run index and an offset per
// triangle).
//
// A cluster is one multi-leaf of the compressed-leaf BVH (bvh8.h; QBVH8 inner nodes above the
// multi-leaves, NodeKind::QCompressedLeaf): its header holds the quantized boxes of up to 8
// children of up to 8 triangles each (one 8-wide watertight test per child): 39 bytes lossy (a
// LatticeBoxes8, below: 6-bit planes, the boxes' frame from the cluster's anchors), 54 bytes
// lossless (an ExactBoxes8: 8-bit planes, the frame from the stream's start floats and three
// bfloat16 extents). The cluster data follows it:
//   ClusterHeader (15 B, packed)
//   lossy, with the fine-planes bit (bit 6 of the header's ob): kPlaneLowBytes bytes, the low
//     bits of the boxes' 8-bit planes (below, "the lossy clusters' multi-leaf boxes")
//   bit stream, LSB first from the byte after these:
//     anchors:  aw0 + aw1 + aw2 bits, the per-axis minimum codes (lossy: aw the scene's
//               ClusterLattice::anchor_bits, the bits of the largest lattice code on the axis:
//               16 on canyon:1024, at most 24); lossless: aw = 32, the per-axis minimum
//               coordinates as floats, whose codes are the anchors (lossless_anchor)
//     bases:    prim_base (bb bits), geom_base (hb bits)
//     children: for children 1..k-1, the child's topology offset (tb bits) and its first new
//               vertex (vbw bits), each a residual of a linear prediction (below)
//     vertices: per vertex bx + by + bz bits (offsets from the anchor); lossy clusters of 2..8
//               children with the ranges bit: per vertex its first child's three range fields
//               (offsets in ranges the multi-leaf's child boxes give: "per-child vertex ranges")
//     run lows: for runs 1..nruns-1 (nruns = run_count(h)), the low pb bits of the run's e
//     repeats:  if the header's repeat bit (top bit of ob) is set, ntris bits: bit t set if
//               triangle t has triangle t - 1's ids (never triangle 0's; without step bits);
//               with the step bit too (top bit of nruns), ntris more bits, the step bits (below);
//               the step bit without the repeat bit: three planes of ntris bits (the signs and
//               repeats, the single steps, the double steps: below)
//     topology: topology_bits(h) bits, each child a generalized strip (below)
//     ids:      in triangle order, an entry per triangle whose flag bits are all clear (every
//               triangle without flag planes): rb = bit_width(nruns - 1) bits run index, ob
//               (the low 6 bits of the header's ob) bits offset in the run (primID = prim_base +
//               start + offset), gb bits geomID - geom_base
//     run highs: for runs 1..nruns-1 in order, e >> pb in unary (that many 0 bits, then a 1);
//               the stream ends after their nruns-1 one bits (at most kMaxRunHighBits bits)
// Child c holds 1 + sizes[c] triangles (3 bits each); k, the child count, is the multi-leaf's, and
// the cluster's triangle count ntris = tri_count(h, k) is the k children's sizes (the header
// stores no count: every reader has k).
// Children with fewer than 8 triangles repeat their last triangle in the padding lanes (the
// duplicate gives the same hit).
//
// The child table: child c starts after T = child_first(c) triangles, and its fields are
// residuals of predictions proportional to T, with the slopes (kInvTris[n] = 2^16 / n, integer:
// a product, no division)
//   ts = (topology_bits(h) x kInvTris[ntris]) >> 4,   vs = (nverts x kInvTris[ntris]) >> 4:
//   the topology offset (from the topology start) = ((T x ts) >> 12) + x - 2^(tb - 1),
//   the first new vertex                          = ((T x vs) >> 12) + y - 2^(vbw - 1),
// x and y the entry's tb-bit and vbw-bit fields. The widths come from the top 5 bits of the
// header's tbits: 3 bits to, tb = to + 5 (5..12: 12 bits hold any offset residual, at most
// topology_bits(h) <= 1854 either way), and 2 bits vo, vbw = vo + 3 (3..5); vo = 3 stores the
// plain first new vertex instead (slope and bias 0, vbw = bit_width(nverts)), for clusters whose
// residuals need more bits.
//
// Topology (DGF section 3.2, with the corners kept in the input order, which u, v and the
// watertight test's rounding depend on): vertices are numbered in order of first use (children in
// order, triangles in strip order), so a vertex reference is 1 bit "new" (the next number) or 0
// followed by ib bits d (the vertex cnt - 1 - d, cnt being the count of vertices numbered so far).
// A child's first triangle is three references (corners 0, 1, 2). Every later triangle starts
// with 2 bits p: 3 restarts (three references); otherwise the edge e of the previous triangle
// follows, and the triangle is that edge (the previous triangle's corners e and e + 1, mod 3)
// reversed, at corners p + 2 and p + 1, with one reference at corner p: the strip step of a
// consistently oriented mesh. After a child's first triangle or a restart e takes 2 bits (0..2);
// after a strip step with p = q it takes 1 bit b, e = q + 2b (mod 3): a step's edge q + 1 is the
// one it was entered by, so the next step shares edge q or q + 2.
//
// The primID runs: input faces are not stored in a cluster's order (they are the user's), but
// neighbouring faces often have nearby numbers (scan rows, quads split in two, terrain rows), so a
// cluster's sorted ids fall into few runs of width 2^ob; on meshes in random order the encoder
// picks ob = 0 and one run per triangle. prim_base is the smallest id; a run starts at the first
// sorted id 2^ob or more past the current run's start. So run 0 starts at prim_base (nothing
// stored) and run i's start s_i (i >= 1, from prim_base) is at least i x 2^ob: the code stores
// e_i = s_i - i x 2^ob, which never decreases with i, as an Elias-Fano sequence: its low pb bits
// at a fixed place (random access) and its high part e_i >> pb as the run highs, in which run i's
// one bit lies at bit (e_i >> pb) + i - 1. The decoder finds that bit (the (i-1)-th one: a
// popcount per 64-bit word, then a select in the word) and gets e_i's high part as its position
// less i - 1. The encoder takes, for each ob, the pb with the fewest bits ((nruns - 1) x (pb + 1)
// + (e_max >> pb), where the highs fit kMaxRunHighBits), and the ob with the fewest id bits.
// The repeats: a face split into triangles (a quad into two) gives them one primID, and they are
// often neighbours in the strip; with the repeat bits, triangle t's ids are those of the entry
// t - (repeat bits 1..t set), one popcount away. The encoder sets the repeat bit in the header
// when the bits save more than their ntris bits cost.
// The step bits: scans and strip-ordered meshes number neighbouring faces one apart, so in strip
// order a triangle's primID is often its predecessor's plus or minus one. With the step bit
// (nruns' top bit) the pair (repeat bit, step bit) of triangle t says (0, 0) an entry, (1, 0)
// triangle t - 1's ids, (0, 1) its primID + 1, (1, 1) its primID - 1 (the same geomID); triangle
// t's ids are those of the last triangle p <= t with an entry (entry p less the triangles with no
// entry before it: popcounts) plus the +1 and -1 steps of triangles p + 1..t (popcounts), and the
// runs are those of the entries' ids alone (prim_base their smallest). The encoder takes them
// where they save more than their 2 ntris bits cost (igea: about 2 bits a triangle).
// Three planes (the step bit without the repeat bit): meshes whose faces were numbered in two
// interleaved passes or along rows of quads (ogre: 28% of the triangles in strip order two or three
// from their predecessor) take steps of up to 3. Triangle t's bits (r, s, d) say (0, 0, 0) an
// entry, else a step of r ? -(s + 2d) : s + 2d from its predecessor's primID ((1, 0, 0): the same
// ids), summed as above by popcounts (the d plane's counted twice).
//
// Lossy (`cluster`): a vertex's code is its lattice integer q = round((x - origin) / step) per
// axis, decoded as origin + float(q) * step (per axis (8 + m) 2^e / 8 with m < 8: the three of
// largest product that keep the error bound, or powers of two: quantize). Every cluster decodes a
// vertex with the same float operations from the same integer (the product is exact: q < 2^24
// with a power of two, q < 2^20 with m > 0, check_lattice), so a vertex shared by clusters
// decodes bit-identically in all of them and the watertight test (core/watertight.h) sees one
// closed surface.
// Lossless (`cluster-lossless`): per cluster one of two codes (the mode in the top 4 bits of the
// header's ib byte, whose low 4 bits hold ib <= 8):
//   mode 0, float keys: the float's bit pattern mapped to an order-preserving unsigned integer, so
//     the per-cluster offsets are the low bits below the shared high bits (about 21-22 bits per
//     coordinate on scans);
//   mode 1 + k (k <= 9), decimal: the coordinate is the 32-bit signed integer q with
//     decimal_coord(q, k_a) = float(double(q) x 10^-k_a) equal to it bit for bit, the anchor the
//     per-axis minimum q (two's complement); axis a has k_a = k - d_a digits, d_a <= 3 in the top
//     2 bits of the header's bits[a]. Meshes stored as text with few decimals (OBJ files printed
//     with %f: `v -0.777853 2.740647 3.930020`, or with %g: x near 100 with 4 decimals, z near 5
//     with 5) hold the floats nearest to such q x 10^-k with small q, which take 3-10 bits fewer
//     per coordinate than their keys. The encoder takes per axis the smallest k_a for which
//     q = round(f x 10^k_a) decodes to every coordinate f of the axis in the cluster (verified
//     with decimal_coord itself; k_a at least k - 3), and this mode only when it takes fewer
//     vertex bits than the keys; the decoders (scalar and AVX2) compute decimal_coord's
//     operations (an exact int-to-double conversion, one correctly rounded product, one rounding
//     to float), so both give the encoder's bits. The mode lives in spare header bits (the top 4
//     of ib, the top 2 of each bits[a]).
//
// An isolated BVH leaf (a one-triangle cluster, or a whole scene of at most 8 triangles) is an
// 8-byte block holding the offset of a one-child cluster record in the scene's side arena
// (Context::side).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <iterator>
#include <mutex>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "core/ray.h"
#include "core/simd.h"
#include "core/watertight.h"
#include "prim/triangles.h"
#include "slimrt/error.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

// The scene-wide lattice of the lossy variant.
struct ClusterLattice {
  float origin[3] = {0, 0, 0};
  float step[3] = {1.0f, 1.0f, 1.0f};  // per axis (8 + m) 2^e / 8, m < 8 (quantize)
  // Bits of a lossy cluster's anchor per axis (<= 24; <= 20 with a step of m > 0, check_lattice):
  // bit_width of the largest lattice code a vertex of the scene can take on the axis (quantize:
  // from the lattice's box, which a chunked build shares with the other chunks). The anchors of
  // canyon:1024 take 16 bits.
  uint8_t anchor_bits[3] = {24, 24, 24};
  uint8_t pad = 0;
};
static_assert(sizeof(ClusterLattice) == 28 && offsetof(ClusterLattice, step) == 12,
              "origin[3], step[3], the anchor widths");

#pragma pack(push, 1)
struct ClusterHeader {
  uint8_t nverts;    // distinct vertices (codes) in the cluster, 1..255
  uint8_t bits[3];   // per-axis offset widths (low 6 bits: lossy <= 24, lossless <= 32); decimal
                     // mode: the top 2 bits are the axis's digits below the cluster's k; lossy:
                     // bit 7 of bits[0] is the ranges bit (per-child vertex ranges, below)
  uint8_t ib;        // low 4 bits: bits of a reused vertex's distance back (<= 8); high 4 bits:
                     // lossless coordinate mode (0 float keys, 1 + k decimal q x 10^-k, k <= 9)
  uint8_t idw[3];    // 4 x 6 bits from bit 0 (each <= 32): pb, bits per primID run start's low
                     // part (Elias-Fano); gb, per geomID offset; bb and hb, of prim_base and
                     // geom_base in the stream (run_low_bits(), geom_bits(), prim_base_bits(),
                     // geom_base_bits() below)
  uint8_t nruns;     // low 7 bits: primID runs, 1..the cluster's triangles; top bit: step bits
  uint8_t ob;        // low 6 bits: bits per primID offset in its run (<= 32); bit 6: fine planes
                     // (lossy multi-leaves, has_fine_planes); top bit: repeats
  uint8_t sizes[3];  // child c holds 1 + (the 3 bits at 3c) triangles
  uint16_t tbits;    // low 11 bits: bits of the topology stream (<= 1854: 27 + 63 x 29); top 5
                     // bits: the child table's widths (3 bits to, 2 bits vo; see above)
};
#pragma pack(pop)
static_assert(sizeof(ClusterHeader) == 15, "cluster header is 15 bytes");

// Bytes a decoder may read past the end of a cluster's data (64-bit bit-stream loads).
constexpr uint32_t kClusterReadSlack = 8;
// Bytes of a cluster's stream at least (the encoder pads a shorter one with zeros, check() rejects
// a shorter one): the multi-leaf frames read 16 bytes from the stream's start (box_start,
// exact_box_start), inside these and the read slack however narrow the anchors.
constexpr uint32_t kMinStreamBytes = 16 - kClusterReadSlack;
// Bits of the primID run starts' high parts at most (the encoder keeps to it, check() enforces it,
// and the decoder scans no further): nruns - 1 one bits and at most 2 (nruns - 1) zero bits at the
// Elias-Fano width floor(log2(e_max / (nruns - 1))) fit in it.
constexpr uint32_t kMaxRunHighBits = 256;

namespace cluster {

// Reads w <= 57 bits at bit pos (one 64-bit load).
SLIM_INLINE uint64_t read_bits57(const uint8_t* p, uint64_t pos, uint32_t w) {
  uint64_t x;
  std::memcpy(&x, p + (pos >> 3), 8);
  return (x >> (pos & 7)) & ((uint64_t(1) << w) - 1);
}
// The same for w <= 32 bits.
SLIM_INLINE uint32_t read_bits(const uint8_t* p, uint64_t pos, uint32_t w) {
  return uint32_t(read_bits57(p, pos, w));
}

// Order-preserving map of float bit patterns to unsigned integers (and back).
SLIM_INLINE uint32_t float_key(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
SLIM_INLINE float key_float(uint32_t k) {
  uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

// The header's ib byte: bits of a reused vertex's distance back, and the lossless coordinate mode
// (0: float keys; 1 + k: decimal with k digits).
SLIM_INLINE uint32_t index_bits(const ClusterHeader& h) { return h.ib & 15u; }
// Bits of the topology stream; the child table's width codes (above).
SLIM_INLINE uint32_t topology_bits(const ClusterHeader& h) { return h.tbits & 0x7ffu; }
SLIM_INLINE uint32_t table_offset_code(const ClusterHeader& h) { return (h.tbits >> 11) & 7u; }
SLIM_INLINE uint32_t table_vertex_code(const ClusterHeader& h) { return uint32_t(h.tbits) >> 14; }
constexpr uint32_t kPlainVertexCode = 3;
// A cluster's most triangles: 8 children of at most 8 (a multi-leaf's 8 leaves of kBlockPrims).
constexpr uint32_t kMaxTriangles = 64;
// 2^16 / n for n = 1..64 (entries 0 and 65..127 0): the child table's slopes without a division,
// indexed by the cluster's triangle count (tri_count: 1..64 for 1..8 children, 0 for none).
struct InvTris {
  uint32_t v[128];
  constexpr InvTris() : v{} {
    for (uint32_t n = 1; n <= kMaxTriangles; ++n) v[n] = 65536u / n;
  }
};
inline constexpr InvTris kInvTris{};
SLIM_INLINE uint32_t coord_mode(const ClusterHeader& h) { return uint32_t(h.ib) >> 4; }
// The header's id widths (idw, 4 x 6 bits): bits of a run start's low part (pb), of a geomID
// offset (gb), of prim_base (bb) and of geom_base (hb).
SLIM_INLINE uint32_t id_widths(const ClusterHeader& h) {
  return uint32_t(h.idw[0]) | uint32_t(h.idw[1]) << 8 | uint32_t(h.idw[2]) << 16;
}
SLIM_INLINE uint32_t run_low_bits(const ClusterHeader& h) { return id_widths(h) & 63u; }
SLIM_INLINE uint32_t geom_bits(const ClusterHeader& h) { return (id_widths(h) >> 6) & 63u; }
SLIM_INLINE uint32_t prim_base_bits(const ClusterHeader& h) { return (id_widths(h) >> 12) & 63u; }
SLIM_INLINE uint32_t geom_base_bits(const ClusterHeader& h) { return id_widths(h) >> 18; }
SLIM_INLINE void set_id_widths(ClusterHeader& h, uint32_t pb, uint32_t gb, uint32_t bb,
                               uint32_t hb) {
  const uint32_t w = (pb & 63u) | (gb & 63u) << 6 | (bb & 63u) << 12 | (hb & 63u) << 18;
  for (int i = 0; i < 3; ++i) h.idw[i] = uint8_t(w >> (8 * i));
}
// Bits of a primID's offset in its run; whether the cluster has repeat bits.
SLIM_INLINE uint32_t offset_bits(const ClusterHeader& h) { return h.ob & 63u; }
SLIM_INLINE bool has_repeats(const ClusterHeader& h) { return h.ob >> 7; }
// The primID runs; whether the cluster has step bits (with its repeat bits; without them, the
// three planes of the double steps: id_flag_planes).
SLIM_INLINE uint32_t run_count(const ClusterHeader& h) { return h.nruns & 127u; }
SLIM_INLINE bool has_steps(const ClusterHeader& h) { return h.nruns >> 7; }
// The ids' flag planes (ntris bits each, from Layout::ids): 0; 1, the repeat bits; 2, with the
// step bits; 3 (the step bit without the repeat bit), with the double steps.
SLIM_INLINE uint32_t id_flag_planes(const ClusterHeader& h) {
  return has_repeats(h) ? 1 + uint32_t(has_steps(h)) : 3 * uint32_t(has_steps(h));
}
// A lossy multi-leaf's cluster whose boxes take 8-bit planes (their low bits right after the
// header; below, "the lossy clusters' multi-leaf boxes").
SLIM_INLINE bool has_fine_planes(const ClusterHeader& h) { return (h.ob >> 6) & 1; }
// Bits of axis a's vertex offsets.
SLIM_INLINE uint32_t axis_bits(const ClusterHeader& h, int a) { return h.bits[a] & 63u; }
// Decimal mode: the digits of axis a, the cluster's k less the axis's top 2 bits of bits[a]
// (taken mod 16: a block check() rejects still indexes kInvPow10).
SLIM_INLINE uint32_t axis_digits(const ClusterHeader& h, int a) {
  return (coord_mode(h) - 1 - (uint32_t(h.bits[a]) >> 6)) & 15u;
}
// decode_coord's mode argument for axis a: 0 float keys, 1 + the axis's digits.
SLIM_INLINE uint32_t axis_mode(const ClusterHeader& h, int a) {
  return coord_mode(h) ? 1 + axis_digits(h, a) : 0;
}
constexpr uint32_t kMaxDecimalDigits = 9;  // mode 1 + k: up to a float's 9 significant digits

// 10^k, exact in a double for k <= 22 (the encoder's q = round(f x 10^k)), and 10^-k, the double
// nearest to it (the decoders multiply by it: a multiplication's latency is a quarter of a
// division's, and the decoders sit ahead of the box and triangle tests). 16 entries: any 4-bit
// mode indexes inside the tables, so a block that check() would reject (mode 11..15, a scene file
// opened without the structure check) decodes wrong positions, never reads beyond them.
inline constexpr double kPow10[16] = {1e0, 1e1, 1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                      1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15};
inline constexpr double kInvPow10[16] = {1e0,  1e-1, 1e-2,  1e-3,  1e-4,  1e-5,  1e-6,  1e-7,
                                         1e-8, 1e-9, 1e-10, 1e-11, 1e-12, 1e-13, 1e-14, 1e-15};
// The one decoding of a decimal-mode coordinate (the encoder's verification, the scalar and the
// AVX2 decoders compute these operations): q (two's complement) times 10^-k. The conversion of q
// is exact, the product correctly rounded, then one rounding to float. (The product can round to
// the other side of a float's rounding boundary than the exact quotient would; the encoder keeps
// a coordinate in decimal mode only if this function gives back its float, so such a cluster
// keeps its float keys.)
SLIM_INLINE float decimal_coord(uint32_t q, uint32_t k) {
  return float(double(int32_t(q)) * kInvPow10[k]);
}

// The decimal code of f with k digits before the range check: round(f x 10^k), the encoder's code
// for each coordinate (non-decreasing in f, so the smallest coordinate of an axis has the
// smallest code). The product is exact (24 + 21 bits for k <= 9) and std::round ignores the
// rounding mode, so the decoder derives the encoder's anchor under any mode.
SLIM_INLINE double decimal_q(float f, uint32_t k) { return std::round(double(f) * kPow10[k]); }

// A lossless cluster's stream starts with its box start, the smallest coordinate per axis as its
// float (the multi-leaf visit reads it with one load, no decode ahead of the box test); the anchor
// the vertex offsets count from is that coordinate's code in the cluster's mode, derived on
// decoding (a cache miss): its float key, or its decimal code decimal_q (clamped to -2^31 out of
// range, which check() rejects).
SLIM_INLINE uint32_t lossless_anchor(uint32_t start_bits, uint32_t mode, uint32_t digits) {
  float f;
  std::memcpy(&f, &start_bits, 4);
  if (!mode) return float_key(f);
  const double q = decimal_q(f, digits);
  return std::fabs(q) < 2147483648.0 ? uint32_t(int32_t(q)) : 0x80000000u;
}

// The one decoding of a lossy coordinate (build and traversal use this function only).
SLIM_INLINE float lattice_coord(const ClusterLattice& lat, int axis, uint32_t q) {
  return lat.origin[axis] + float(q) * lat.step[axis];  // exact product (check_lattice)
}

// ---- the lossy clusters' multi-leaf boxes (ClusterLeaf<false>, traverse.h HasMultiLeafBoxes) ----
// A MultiLeaf8 spends 24 of its 72 bytes on a float start and extent per axis. A lossy cluster's
// lowest vertex lies on the lattice at its anchor (the stream's first field), so its boxes start
// there, start_a = lattice_coord(anchor_a), and the extent (one of the 255 steps) is one scale
// byte per axis, e << 3 | m: extent_a = (8 + m) 2^e x step_a / 8, at most 1/8 above the smallest
// extent that reaches the cluster's top (a power of two alone would waste up to 2x in looser child
// boxes). The planes decode as a QNode8's, start + q x extent with one fma, so the traversal tests
// them with the same instructions; the builder takes the smallest scale whose q = 255 decodes at or
// above the cluster's box and quantizes the child boxes conservatively in that frame (validate()
// checks every child box against its decoded triangles).
//
// The planes are stored in 6 bits: plane p (lo_x, hi_x, lo_y, hi_y, lo_z, hi_z) of child i is the
// 8-bit plane q = c << 2 | l, c the 6-bit value i of the plane's 6 bytes (from bit 6i), l its low
// bits: in a cluster with the fine-planes bit, the 2-bit value i of the plane's 2 bytes in the
// kPlaneLowBytes after the cluster's header; otherwise 0 on low planes and 3 on high ones (the
// 8-bit box rounded outward to the 64 coarse planes: at most 3/255 of the cluster wider per side).
// The encoder (cluster::multileaf_boxes) takes the coarse planes where the children's boxes grow
// in surface area by at most kCoarsePlaneGrowth (scans: nearly every cluster), the fine ones
// elsewhere (grid terrains' abutting children: the coarse boxes' overlaps would send a ray into
// more children), so a multi-leaf takes 39 bytes or 51 (39 + the 12 low bytes in the cluster);
// a coarse cluster's boxes cost 12 bytes fewer (docs/results.md, "Coarse multi-leaf planes").
constexpr uint32_t kCoarsePlaneBits = 6;
constexpr uint32_t kPlaneLowBytes = 6 * (8 - kCoarsePlaneBits);  // 6 planes x 8 values x 2 bits
constexpr double kCoarsePlaneGrowth = 0.10;
struct LatticeBoxes8 {
  uint8_t c[6 * kCoarsePlaneBits];  // 36 B: plane p's 8 values of 6 bits in bytes 6p..6p+5
  uint8_t scale[3];                 // 3 B: per axis e << 3 | m, e <= kMaxBoxScaleExp
};
static_assert(sizeof(LatticeBoxes8) == 39 && offsetof(LatticeBoxes8, scale) == 36,
              "lossy cluster multi-leaf boxes are 39 bytes, the scale bytes last");
// The byte after the header of a cluster's data: the fine planes' low bits, if any, then the
// stream (at data + stream_offset).
SLIM_INLINE uint32_t stream_offset(const ClusterHeader& h) {
  return uint32_t(sizeof(ClusterHeader)) + (has_fine_planes(h) ? kPlaneLowBytes : 0);
}
SLIM_INLINE const uint8_t* stream_of(const uint8_t* data) {
  const uint8_t ob = data[offsetof(ClusterHeader, ob)];
  return data + sizeof(ClusterHeader) + ((ob >> 6) & 1) * kPlaneLowBytes;
}
// The fine planes' low bits of the lossy multi-leaf whose cluster is at `data` (nullptr: coarse
// planes).
SLIM_INLINE const uint8_t* plane_lows(const uint8_t* data) {
  const uint8_t ob = data[offsetof(ClusterHeader, ob)];
  return (ob >> 6) & 1 ? data + sizeof(ClusterHeader) : nullptr;
}
// The 8-bit planes q[6][8] of the LatticeBoxes8 at `boxes`, their low bits at `lows`
// (plane_lows; nullptr: 0 on low planes, 3 on high ones). Empty slots (children >= k: 6-bit lo
// 63, hi 0) give lo 252 > hi 3 (coarse) or lo 255 > hi 0 (fine).
SLIM_INLINE void lattice_planes(const uint8_t* boxes, const uint8_t* lows, uint8_t (*q)[8]) {
  for (uint32_t p = 0; p < 6; ++p) {
    uint64_t c = 0;
    std::memcpy(&c, boxes + kCoarsePlaneBits * p, kCoarsePlaneBits);
    const uint32_t l =
        lows ? uint32_t(lows[2 * p]) | uint32_t(lows[2 * p + 1]) << 8 : (p & 1 ? 0xffffu : 0u);
    for (uint32_t i = 0; i < 8; ++i)
      q[p][i] = uint8_t(((c >> (kCoarsePlaneBits * i)) & 63) << 2 | ((l >> (2 * i)) & 3));
  }
}
// The coarse plane of 8-bit plane q, plane p's (low planes even, high ones odd): rounded outward.
SLIM_INLINE uint8_t coarse_plane(uint32_t p, uint8_t q) { return uint8_t(p & 1 ? q | 3 : q & ~3); }
// The builder's side: the coarse values of 8-bit planes q into `boxes` and, for fine planes,
// their low bits into `lows` (kPlaneLowBytes); either may be nullptr.
SLIM_INLINE void pack_planes(const uint8_t (*q)[8], LatticeBoxes8* boxes, uint8_t* lows) {
  for (uint32_t p = 0; p < 6; ++p) {
    uint64_t c = 0;
    uint32_t l = 0;
    for (uint32_t i = 0; i < 8; ++i) {
      c |= uint64_t(q[p][i] >> 2) << (kCoarsePlaneBits * i);
      l |= uint32_t(q[p][i] & 3) << (2 * i);
    }
    if (boxes) std::memcpy(boxes->c + kCoarsePlaneBits * p, &c, kCoarsePlaneBits);
    if (lows) {
      lows[2 * p] = uint8_t(l);
      lows[2 * p + 1] = uint8_t(l >> 8);
    }
  }
}
#if defined(SLIM_SIMD_AVX2)
// The six planes of the LatticeBoxes8 at `boxes` as 8 ints each (lattice_planes' values), q[p]
// for plane p: per plane the 6 bytes in both 128-bit halves (an 8-byte load: `boxes` has 39
// bytes), lane i's two bytes (from byte 6i / 8) as the lane's bytes 1 and 2 by a byte shuffle, a
// shift by 6i mod 8 + 6 that puts its 6 bits at bits 2..7 (c << 2) and a mask; then the low bits:
// 3 on the high planes (lows nullptr), or fine planes' 2 bits a value (2 bytes a plane at `lows`)
// the same way.
SLIM_INLINE void lattice_planes_avx2(const uint8_t* boxes, const uint8_t* lows, __m256i* q) {
  static_assert(kCoarsePlaneBits == 6, "the byte shuffle and shifts below are for 6-bit planes");
  const __m256i bytes = _mm256_setr_epi8(-1, 0, 1, -1, -1, 0, 1, -1, -1, 1, 2, -1, -1, 2, 3, -1,  //
                                         -1, 3, 4, -1, -1, 3, 4, -1, -1, 4, 5, -1, -1, 5, 6, -1);
  const __m256i shift = _mm256_setr_epi32(6, 12, 10, 8, 6, 12, 10, 8);
  const __m256i mask = _mm256_set1_epi32(0xfc), three = _mm256_set1_epi32(3);
  for (uint32_t p = 0; p < 6; ++p) {
    int64_t c;
    std::memcpy(&c, boxes + kCoarsePlaneBits * p, 8);
    q[p] = _mm256_and_si256(
        _mm256_srlv_epi32(_mm256_shuffle_epi8(_mm256_set1_epi64x(c), bytes), shift), mask);
  }
  if (!lows) {
    for (uint32_t p = 1; p < 6; p += 2) q[p] = _mm256_or_si256(q[p], three);
    return;
  }
  const __m256i lshift = _mm256_setr_epi32(0, 2, 4, 6, 8, 10, 12, 14);
  for (uint32_t p = 0; p < 6; ++p) {
    uint16_t l;
    std::memcpy(&l, lows + 2 * p, 2);
    q[p] = _mm256_or_si256(
        q[p], _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(l), lshift), three));
  }
}
#endif
constexpr uint32_t kMaxBoxScaleExp = 24;  // 255 x 2^24 steps span any cluster (< 2^24 steps)
// The lattice steps a lossy scene may have (check_lattice): normal floats whose box extents
// (box_extent: up to 2^(kMaxBoxScaleExp + 1) steps) stay finite, (8 + m) 2^e / 8 with m below
// 2^kStepMantissaBits; with m > 0 the axis' codes stay below 2^kFineStepCodeBits, so that
// float(q) x step is exact (q x 15 < 2^24).
constexpr double kMinLatticeStep = 0x1p-126, kMaxLatticeStep = 0x1p102;
constexpr uint32_t kStepMantissaBits = 3, kFineStepCodeBits = 20;

// ---- the lossless clusters' multi-leaf boxes (ClusterLeaf<true>) ----
// The start is the cluster's lowest coordinate per axis, exactly a vertex coordinate: the
// stream's first field holds it as a float (the anchors are its codes, lossless_anchor). The
// extent per axis is a bfloat16 (a float's top 16 bits, decoded by a shift), the
// smallest normal one whose q = 255 plane, start + 255 x extent with the traversal's fma, reaches
// the cluster's top: at most 1/128 above the exact 1/255 of the span. 54 bytes instead of 72.
struct ExactBoxes8 {
  uint8_t q[6][8];     // 48 B: lo_x, hi_x, lo_y, hi_y, lo_z, hi_z (as QuantBoxes8::q)
  uint16_t extent[3];  // 6 B: per axis a bfloat16, a positive normal float
};
static_assert(sizeof(ExactBoxes8) == 54, "lossless cluster multi-leaf boxes are 54 bytes");
SLIM_INLINE float bfloat16_float(uint16_t b) {
  const uint32_t u = uint32_t(b) << 16;
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}
// A bfloat16 extent the traversal takes as given: positive, normal (denormals may be flushed to
// zero while tracing) and finite.
SLIM_INLINE bool extent_ok(uint16_t b) { return b >= 0x0080 && b < 0x7f80; }

// The float (8 + m) 2^e / 8 of scale byte e << 3 | m: e in the exponent, m the top 3 mantissa
// bits.
SLIM_INLINE float scale_factor(uint32_t scale) {
  const uint32_t u = ((scale & 0xff) << 20) + (127u << 23);
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}
// The extent of scale byte `scale` (build and traversal use this function only): (8 + m) 2^e / 8
// steps, an exact product (two mantissas of at most 4 bits; check_lattice keeps it a normal
// float).
SLIM_INLINE float box_extent(const ClusterLattice& lat, int axis, uint32_t scale) {
  return scale_factor(scale) * lat.step[axis];
}

// mode: coord_mode() of the cluster (lossless only).
template <bool kLossless>
SLIM_INLINE float decode_coord(const ClusterLattice& lat, int axis, uint32_t code, uint32_t mode) {
  if constexpr (kLossless)
    return mode ? decimal_coord(code, mode - 1) : key_float(code);
  else
    return lattice_coord(lat, axis, code);
}

#if defined(__GNUC__)
#define SLIM_INLINE_LAMBDA __attribute__((always_inline))
#else
#define SLIM_INLINE_LAMBDA
#endif

SLIM_INLINE uint32_t bit_width(uint32_t x) { return x ? 32u - uint32_t(__builtin_clz(x)) : 0u; }

// Vertices numbered 0, 1, ... in order of first sight by their three codes (a vertex is its
// codes: duplicated input vertices with the same code are one), through an open-addressing table
// kept at most half full: up to kMaxVertices vertices (the encoder's cluster, the reshaper's
// sibling pairs).
class CodeNumbering {
 public:
  static constexpr uint32_t kSlots = 1024, kMaxVertices = kSlots / 2;
  CodeNumbering() { std::fill(std::begin(slot_), std::end(slot_), kEmpty); }
  // The number of the vertex with these codes; a new number if none had them before.
  SLIM_INLINE uint32_t number(const uint32_t* code) {
    const uint32_t x0 = (code[0] * 0x9E3779B1u) ^ (code[1] * 0x85EBCA77u) ^ (code[2] * 0xC2B2AE3Du);
    for (uint32_t x = (x0 ^ (x0 >> 15)) & (kSlots - 1);; x = (x + 1) & (kSlots - 1)) {
      const uint16_t i = slot_[x];
      if (i == kEmpty) {
        slot_[x] = uint16_t(n_);
        std::copy(code, code + 3, codes_ + 3 * n_);
        return n_++;
      }
      const uint32_t* seen = codes_ + 3 * i;
      if (seen[0] == code[0] && seen[1] == code[1] && seen[2] == code[2]) return i;
    }
  }
  uint32_t size() const { return n_; }
  const uint32_t* codes(uint32_t v) const { return codes_ + 3 * v; }  // vertex v's codes

 private:
  static constexpr uint16_t kEmpty = 0xffff;
  uint16_t slot_[kSlots];
  uint32_t codes_[3 * kMaxVertices];
  uint32_t n_ = 0;
};

SLIM_INLINE uint32_t child_sizes(const ClusterHeader& h) {
  return uint32_t(h.sizes[0]) | uint32_t(h.sizes[1]) << 8 | uint32_t(h.sizes[2]) << 16;
}
// Triangles of child c.
SLIM_INLINE uint32_t child_size(uint32_t sizes, uint32_t c) { return 1 + ((sizes >> (3 * c)) & 7); }
// The first triangle of child c: the sizes of the children before it.
SLIM_INLINE uint32_t child_first(uint32_t sizes, uint32_t c) {
  const uint32_t m = sizes & ((1u << (3 * c)) - 1);  // c <= 8: at most 24 bits
  return c + uint32_t(__builtin_popcount(m & 0x249249u)) +
         2 * uint32_t(__builtin_popcount(m & 0x492492u)) +
         4 * uint32_t(__builtin_popcount(m & 0x924924u));
}

// Triangles of a cluster of k children (the header stores no count: the sizes of its k children
// add up to it).
SLIM_INLINE uint32_t tri_count(const ClusterHeader& h, uint32_t k) {
  return child_first(child_sizes(h), k);
}
// Bits of a cluster's anchor on axis a: 32 lossless (the smallest coordinate's float, from which
// lossless_anchor derives the anchor), the lattice's anchor_bits lossy.
SLIM_INLINE uint32_t anchor_bits(const ClusterLattice& lat, bool lossless, int a) {
  return lossless ? 32u : lat.anchor_bits[a];
}

// Bit positions of the streams of a cluster of k children.
// ids: the flag planes (id_flag_planes); end: the topology's end, where the ids' entries begin
// (as many as triangles whose flag bits are all clear: popcounts), then the run highs (they end
// after their nruns - 1 one bits). The stream's length depends on both, so check() and the
// encoder find it, not the layout.
struct Layout {
  uint64_t table = 0, verts = 0, runs = 0, ids = 0, topo = 0, end = 0;  // from the stream start
  uint32_t aw[3] = {};                                                  // bits per anchor, per axis
  uint32_t bases = 0;           // bit of prim_base (the end of the anchors or start floats)
  uint32_t ntris = 0;           // triangles (tri_count)
  uint32_t vbits = 0;           // bits per vertex
  uint32_t tb = 0, vbw = 0;     // bits per child topology offset / first new vertex
  uint32_t ts = 0, tbias = 0;   // the offset's slope (x 2^-12 per triangle) and bias
  uint32_t vs = 0, vbias = 0;   // the first new vertex's slope and bias
  uint32_t rb = 0, idbits = 0;  // bits per run index; per triangle's ids (rb + ob + gb)
};
// The layout L of a cluster with header h (from layout() with kPlainVertexBits) for a vertex
// section of vertex_bits bits: the sections behind it move (as layout() with vertex_bits).
SLIM_INLINE void with_vertex_bits(Layout& L, const ClusterHeader& h, uint64_t vertex_bits) {
  const uint64_t d = vertex_bits - uint64_t(h.nverts) * L.vbits;  // mod 2^64
  L.runs += d;
  L.ids += d;
  L.topo += d;
  L.end += d;
}
// vertex_bits: the vertex section's bits when the cluster has per-child vertex ranges (their
// ChildRanges::total, below), else kPlainVertexBits: nverts x (bx + by + bz).
constexpr uint64_t kPlainVertexBits = ~uint64_t(0);
SLIM_INLINE Layout layout(const ClusterHeader& h, uint32_t k, const ClusterLattice& lat,
                          bool lossless, uint64_t vertex_bits = kPlainVertexBits) {
  Layout l;
  for (int a = 0; a < 3; ++a) l.aw[a] = anchor_bits(lat, lossless, a);
  l.bases = l.aw[0] + l.aw[1] + l.aw[2];
  l.ntris = tri_count(h, k);
  l.vbits = axis_bits(h, 0) + axis_bits(h, 1) + axis_bits(h, 2);
  const uint32_t tbits = topology_bits(h), to = table_offset_code(h), vo = table_vertex_code(h);
  const uint32_t inv = kInvTris.v[l.ntris & 127u];
  const bool vplain = vo == kPlainVertexCode;
  l.tb = to + 5;
  l.ts = (tbits * inv) >> 4;
  l.tbias = 1u << (to + 4);
  l.vbw = vplain ? bit_width(h.nverts) : vo + 3;
  l.vs = vplain ? 0 : (uint32_t(h.nverts) * inv) >> 4;
  l.vbias = vplain ? 0 : 1u << (l.vbw - 1);
  l.rb = run_count(h) ? bit_width(run_count(h) - 1) : 0;
  l.idbits = l.rb + offset_bits(h) + geom_bits(h);
  l.table = l.bases + prim_base_bits(h) + geom_base_bits(h);
  l.verts = l.table + uint64_t(k ? k - 1 : 0) * (l.tb + l.vbw);
  l.runs = l.verts + uint64_t(h.nverts) * l.vbits;
  l.ids = l.runs + uint64_t(run_count(h) ? run_count(h) - 1 : 0) * run_low_bits(h);
  l.topo = l.ids + uint64_t(l.ntris) * id_flag_planes(h);
  l.end = l.topo + tbits;
  if (vertex_bits != kPlainVertexBits) with_vertex_bits(l, h, vertex_bits);
  return l;
}
// A lossy cluster's anchors: the stream's first fields, at the lattice's widths (L.aw).
SLIM_INLINE void lossy_anchors(const uint8_t* bits, const Layout& L, uint32_t* anchor) {
  for (int a = 0, at = 0; a < 3; at += int(L.aw[a]), ++a)
    anchor[a] = read_bits(bits, uint64_t(at), L.aw[a]);
}
// The child table's predictions for the child after `first` triangles (the header comment's
// formula, its bias subtracted, in 32-bit wrapping arithmetic): the entry's fields are the child's
// topology offset and first new vertex less these (the encoder), and these plus the fields give
// them back (the decoders).
SLIM_INLINE uint32_t predicted_offset(const Layout& L, uint32_t first) {
  return ((first * L.ts) >> 12) - L.tbias;
}
SLIM_INLINE uint32_t predicted_vertex(const Layout& L, uint32_t first) {
  return ((first * L.vs) >> 12) - L.vbias;
}
// Bytes of a cluster's data (header + stream) with `tail` bits of ids' entries and run highs,
// without the read slack.
SLIM_INLINE uint64_t data_bytes(const ClusterHeader& h, uint32_t k, const ClusterLattice& lat,
                                bool lossless, uint64_t tail,
                                uint64_t vertex_bits = kPlainVertexBits) {
  return stream_offset(h) + (layout(h, k, lat, lossless, vertex_bits).end + tail + 7) / 8;
}

// ---- per-child vertex ranges (lossy clusters of 2..8 children) ----
// With the ranges bit (the top bit of the header's bits[0]: lossless clusters use the top 2 bits
// of bits[a] for their decimal digits, lossy ones nothing else) a vertex is an offset in the range
// of the child that uses it first, not in the cluster's: vertices are numbered in order of first
// use, so child c's new vertices are first_c .. first_{c+1} - 1 (first_0 = 0, first_c the child
// table's, first_k = nverts), and the child's box planes in the multi-leaf's LatticeBoxes8 (right
// before the cluster's data) bound them. In lattice steps from the anchor, with the axis's scale
// byte e << 3 | m, the planes' real values give the range
//   lo = floor(q_lo x (8 + m) 2^e / 8),  hi = ceil(q_hi x (8 + m) 2^e / 8),
// so the vertex's offsets from lo (+ the anchor) on the three axes are digits o_a < R_a of radix
// R_a = hi - lo + 1, stored as one mixed-radix number
//   m = o_x + R_x (o_y + R_y o_z)  in  w = bit_width(R_x R_y R_z - 1) bits,
// at most 1 bit more than log2 of the box's lattice points instead of up to 3 (three fields of
// bit_width(hi - lo) bits each): 0.3-0.5 bits a coordinate fewer (docs/results.md,
// "Mixed-radix vertices"). The decoders get the digits with two divisions, o_z = m / (R_x R_y)
// and t = m / R_x (AVX2: in floats or doubles, exact: decode_vertices_ranges_avx2), o_x =
// m - t R_x, o_y = t - o_z R_y.
// The vertex section holds child 0's new vertices, then child 1's, and so on, child c's at w_c
// bits each. A child of a scan's cluster spans about a third of the cluster per axis: some 1.5
// bits a coordinate fewer than the cluster's fields (docs/results.md, "Per-child vertex ranges").
// The encoder sets the bit when every vertex lies in its child's range (unless a float plane
// rounds past a vertex's lattice point, it does), every w_c is at most kMaxRangeVertexBits and the
// ranges take fewer bits; the free box planes cost nothing to store.
SLIM_INLINE bool has_ranges(const ClusterHeader& h) { return h.bits[0] >> 7; }
// Scale exponents of a cluster with ranges at most: 255 x 15 x 2^20 < 2^32, so the ranges'
// 32-bit products do not wrap (a cluster spans fewer than 2^24 steps: e <= 17 reaches it).
constexpr uint32_t kMaxRangeScaleExp = 20;
// Bits of a vertex of a child with ranges at most (check() rejects more): the AVX2 decoder
// converts the mixed-radix number to a double exactly (below 2^52) and divides it.
constexpr uint32_t kMaxRangeVertexBits = 52;
// Bits of the vertices of every child of a cluster at most whose AVX2 decoder divides in floats.
constexpr uint32_t kFloatRadixBits = 23;
// The range of planes q_lo, q_hi under scale byte `scale` (e <= kMaxRangeScaleExp): its low end
// and its radix hi - lo + 1 (wrapped when q_hi < q_lo: check() rejects radices beyond 2^24).
SLIM_INLINE void plane_range(uint32_t qlo, uint32_t qhi, uint32_t scale, uint32_t& lo,
                             uint32_t& radix) {
  const uint32_t m = 8 + (scale & 7), e = (scale >> 3) & 31;
  lo = ((qlo * m) << e) >> 3;
  radix = ((((qhi * m) << e) + 7) >> 3) - lo + 1;
}
// Bits of a mixed-radix vertex: bit_width(R_x R_y R_z - 1), exact for any radices (a radix 0, a
// wrapped one, gives 128).
SLIM_INLINE uint32_t radix_bits(uint32_t rx, uint32_t ry, uint32_t rz) {
  const unsigned __int128 p = (unsigned __int128)(uint64_t(rx) * ry) * rz - 1;
  const uint64_t high = uint64_t(p >> 64), low = uint64_t(p);
  return high  ? 128 - uint32_t(__builtin_clzll(high))
         : low ? 64 - uint32_t(__builtin_clzll(low))
               : 0;
}
// What a decoder takes from the ranges, per child (lanes c >= k: first kNoChildVertex, pos and w
// 0, radices 1).
constexpr uint32_t kNoChildVertex = 0x100;  // above every vertex number (signed compares work)
struct ChildRanges {
  alignas(32) uint32_t first[8];     // the child's first new vertex
  alignas(32) uint32_t pos[8];       // vertex v of the child lies at bit pos + v x w (mod 2^32)
  alignas(32) uint32_t w[8];         // bits a vertex (radix_bits)
  alignas(32) uint32_t radix[3][8];  // per axis hi - lo + 1
  alignas(32) uint32_t base[3][8];   // the code of digit 0: anchor + lo
  uint64_t total;                    // bits of the vertex section
  uint32_t wmax;                     // the widest child's w
  bool operator==(const ChildRanges&) const = default;  // field by field (the fuzz target's check)
};
// The ranges of the k children of the cluster with header h (L: its layout, from vertex_bits
// anything: the child table lies before the vertices), its stream `bits`, its anchors and the
// multi-leaf boxes' 8-bit planes q (lattice_planes) and scale bytes.
SLIM_INLINE void child_ranges(const ClusterHeader& h, const Layout& L, const uint8_t* bits,
                              const uint32_t* anchor, const uint8_t (*q)[8], const uint8_t* scale,
                              uint32_t k, ChildRanges& r) {
  const uint32_t sizes = child_sizes(h);
  r.first[0] = 0;
  for (uint32_t c = 1; c < 8; ++c)
    r.first[c] =
        c < k
            ? (read_bits(bits, L.table + uint64_t(c - 1) * (L.tb + L.vbw), L.tb + L.vbw) >> L.tb) +
                  predicted_vertex(L, child_first(sizes, c))
            : kNoChildVertex;
  uint32_t p = uint32_t(L.verts);
  uint64_t total = 0;
  r.wmax = 0;
  for (uint32_t c = 0; c < 8; ++c) {
    for (int a = 0; a < 3; ++a) {
      uint32_t lo = 0, radix = 1;
      if (c < k) plane_range(q[2 * a][c], q[2 * a + 1][c], scale[a], lo, radix);
      r.radix[a][c] = radix;
      r.base[a][c] = anchor[a] + lo;
    }
    const uint32_t wsum = radix_bits(r.radix[0][c], r.radix[1][c], r.radix[2][c]);
    r.w[c] = wsum;
    r.wmax = std::max(r.wmax, wsum);
    r.pos[c] = 0;
    if (c < k) {
      const uint32_t n = (c + 1 < k ? r.first[c + 1] : uint32_t(h.nverts)) - r.first[c];
      r.pos[c] = p - r.first[c] * wsum;
      p += n * wsum;
      total += uint64_t(n) * wsum;  // check(): the firsts ascend, so n <= nverts
    }
  }
  r.total = total;
}
#if defined(SLIM_SIMD_AVX2)
// The low 32 bits of each 64-bit lane, lanes 0-3 from lo, 4-7 from hi.
SLIM_INLINE __m256i low32_lanes(__m256i lo, __m256i hi) {
  const __m256 pair =
      _mm256_shuffle_ps(_mm256_castsi256_ps(lo), _mm256_castsi256_ps(hi), _MM_SHUFFLE(2, 0, 2, 0));
  return _mm256_permute4x64_epi64(_mm256_castps_si256(pair), 0xD8);
}
// The 64 bits from bit 8 x byte + sh of `base` for four lanes (a gather, a shift per lane).
SLIM_INLINE __m256i gather_window(const uint8_t* base, __m128i byte, __m128i sh) {
  return _mm256_srlv_epi64(
      _mm256_i32gather_epi64(reinterpret_cast<const long long*>(base), byte, 1),
      _mm256_cvtepu32_epi64(sh));
}
// child_ranges with the 8 children in the lanes of AVX2 vectors (the traversal's view computes it
// at every multi-leaf visit that decodes a child): the same fields bit for bit for a cluster
// check() accepted (radices of at most 2^24 whose product is at most 2^52: the double product
// that gives a child's vertex width is exact).
// The planes come from the LatticeBoxes8 at `boxes` and their low bits at `lows` (plane_lows).
SLIM_INLINE void child_ranges_avx2(const ClusterHeader& h, const Layout& L, const uint8_t* bits,
                                   const uint32_t* anchor, const uint8_t* boxes,
                                   const uint8_t* lows, const uint8_t* scale, uint32_t k,
                                   ChildRanges& r) {
  auto store = [](uint32_t* p, __m256i x) { _mm256_store_si256(reinterpret_cast<__m256i*>(p), x); };
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i zero = _mm256_setzero_si256(), one = _mm256_set1_epi32(1);
  const __m256i used = _mm256_cmpgt_epi32(_mm256_set1_epi32(int(k)), lane);  // c < k
  // Inclusive prefix sums over the 8 lanes.
  auto prefix = [&](__m256i x) {
    x = _mm256_add_epi32(x, _mm256_slli_si256(x, 4));
    x = _mm256_add_epi32(x, _mm256_slli_si256(x, 8));
    const __m256i low_total = _mm256_permutevar8x32_epi32(x, _mm256_set1_epi32(3));
    return _mm256_add_epi32(x, _mm256_blend_epi32(zero, low_total, 0xF0));
  };
  // The children's first triangles (the sizes before them) and their table entries' firsts.
  const __m256i sizes = _mm256_add_epi32(
      _mm256_and_si256(_mm256_srlv_epi32(_mm256_set1_epi32(int(child_sizes(h))),
                                         _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21)),
                       _mm256_set1_epi32(7)),
      one);
  const __m256i tri_first = _mm256_sub_epi32(prefix(sizes), sizes);
  const uint32_t stride = L.tb + L.vbw;
  // Entry c - 1 at bit table + (c - 1) x stride: 32 bits from its byte hold it (7 + 12 + 8 bits).
  const __m256i epos = _mm256_add_epi32(
      _mm256_set1_epi32(int(L.table)),
      _mm256_mullo_epi32(_mm256_sub_epi32(lane, one), _mm256_set1_epi32(int(stride))));
  const __m256i entry = _mm256_mask_i32gather_epi32(
      zero, reinterpret_cast<const int*>(bits), _mm256_srli_epi32(epos, 3),
      _mm256_and_si256(used, _mm256_cmpgt_epi32(lane, zero)), 1);
  const __m256i field = _mm256_and_si256(
      _mm256_srl_epi32(_mm256_srlv_epi32(entry, _mm256_and_si256(epos, _mm256_set1_epi32(7))),
                       _mm_cvtsi32_si128(int(L.tb))),
      _mm256_set1_epi32(int((1u << L.vbw) - 1)));
  const __m256i predicted = _mm256_sub_epi32(
      _mm256_srli_epi32(_mm256_mullo_epi32(tri_first, _mm256_set1_epi32(int(L.vs))), 12),
      _mm256_set1_epi32(int(L.vbias)));
  __m256i first = _mm256_blend_epi32(_mm256_add_epi32(field, predicted), zero, 1);  // child 0: 0
  first = _mm256_blendv_epi8(_mm256_set1_epi32(int(kNoChildVertex)), first, used);
  // The ranges per axis.
  __m256i q[6];
  lattice_planes_avx2(boxes, lows, q);
  __m256i radix[3], base[3];
  for (int a = 0; a < 3; ++a) {
    const __m128i e = _mm_cvtsi32_si128(int(scale[a] >> 3));
    const __m256i m = _mm256_set1_epi32(int(8 + (scale[a] & 7)));
    const __m256i lo = _mm256_srli_epi32(_mm256_sll_epi32(_mm256_mullo_epi32(q[2 * a], m), e), 3);
    const __m256i hi =
        _mm256_srli_epi32(_mm256_add_epi32(_mm256_sll_epi32(_mm256_mullo_epi32(q[2 * a + 1], m), e),
                                           _mm256_set1_epi32(7)),
                          3);
    radix[a] = _mm256_blendv_epi8(one, _mm256_add_epi32(_mm256_sub_epi32(hi, lo), one), used);
    base[a] = _mm256_blendv_epi8(_mm256_set1_epi32(int(anchor[a])),
                                 _mm256_add_epi32(_mm256_set1_epi32(int(anchor[a])), lo), used);
  }
  // radix_bits: the exponent of R_x R_y R_z - 1 as a double (exact: radices of at most 2^24
  // whose product is at most 2^52), 0 for 0; four children in each half.
  auto vertex_bits = [&](int half) {
    auto rd = [&](int a) {
      return _mm256_cvtepi32_pd(half ? _mm256_extracti128_si256(radix[a], 1)
                                     : _mm256_castsi256_si128(radix[a]));
    };
    const __m256d p =
        _mm256_sub_pd(_mm256_mul_pd(_mm256_mul_pd(rd(0), rd(1)), rd(2)), _mm256_set1_pd(1.0));
    return _mm256_sub_epi64(_mm256_srli_epi64(_mm256_castpd_si256(p), 52),
                            _mm256_set1_epi64x(1022));
  };
  const __m256i wsum = _mm256_max_epi32(low32_lanes(vertex_bits(0), vertex_bits(1)), zero);
  // Vertices per child: the next child's first (the last child's: nverts) less the child's.
  const __m256i next = _mm256_blendv_epi8(
      _mm256_permutevar8x32_epi32(
          first, _mm256_min_epi32(_mm256_add_epi32(lane, one), _mm256_set1_epi32(7))),
      _mm256_set1_epi32(int(h.nverts)), _mm256_cmpeq_epi32(lane, _mm256_set1_epi32(int(k) - 1)));
  const __m256i n = _mm256_and_si256(_mm256_sub_epi32(next, first), used);
  const __m256i bits_in = prefix(_mm256_mullo_epi32(n, wsum));  // through child c
  const __m256i before = _mm256_sub_epi32(bits_in, _mm256_mullo_epi32(n, wsum));
  const __m256i pos =
      _mm256_and_si256(_mm256_sub_epi32(_mm256_add_epi32(_mm256_set1_epi32(int(L.verts)), before),
                                        _mm256_mullo_epi32(first, wsum)),
                       used);
  store(r.first, first);
  store(r.pos, pos);
  store(r.w, wsum);
  for (int a = 0; a < 3; ++a) {
    store(r.radix[a], radix[a]);
    store(r.base[a], base[a]);
  }
  alignas(32) uint32_t tot[8];
  store(tot, bits_in);
  r.total = tot[7];
  const __m128i w4 = _mm_max_epu32(_mm256_castsi256_si128(wsum), _mm256_extracti128_si256(wsum, 1));
  const __m128i w2 = _mm_max_epu32(w4, _mm_shuffle_epi32(w4, _MM_SHUFFLE(1, 0, 3, 2)));
  r.wmax = uint32_t(
      _mm_cvtsi128_si32(_mm_max_epu32(w2, _mm_shuffle_epi32(w2, _MM_SHUFFLE(2, 3, 0, 1)))));
}
#endif
// The child whose new vertices include vertex v: the firsts of children 1..7 at or below it.
SLIM_INLINE uint32_t range_child(const ChildRanges& r, uint32_t v) {
  uint32_t c = 0;
  for (int j = 1; j < 8; ++j) c += r.first[j] <= v;
  return c;
}

// Decodes the strip of child c (n triangles) into idx[corner][lane], lanes < n. get(pos, w) reads
// w <= 32 bits at bit pos of the stream (one read per triangle: a restart's 2 + 3 x 9 bits at
// most); *end receives the bit after the strip's last. kCheck: returns false if a reused vertex
// lies before vertex 0 or a 2-bit edge is 3. The checker runs this; the decoders run
// decode_strip_packed (below: the same triangles) on checked blocks only.
template <bool kCheck, class Get>
SLIM_INLINE bool decode_strip(const ClusterHeader& h, const Layout& L, Get&& get, uint32_t c,
                              uint32_t n, uint32_t (&idx)[3][8], uint64_t* end = nullptr) {
  uint64_t pos = L.topo;
  uint32_t cnt = 0;
  if (c) {
    const uint32_t first = child_first(child_sizes(h), c);
    const uint64_t e = L.table + uint64_t(c - 1) * (L.tb + L.vbw);
    const uint32_t x = get(e, L.tb + L.vbw);
    // A wrong residual gives an offset or count beyond the stream or the vertices (the 32-bit
    // wrap of a negative one too): the checker's end and index tests reject it.
    pos += uint32_t((x & ((1u << L.tb) - 1)) + predicted_offset(L, first));
    cnt = (x >> L.tb) + predicted_vertex(L, first);
  }
  bool ok = true;
  const uint32_t ib = index_bits(h), dmask = (1u << ib) - 1;
  // One reference from the bits x (consumed: x and used shift right).
  auto ref = [&](uint32_t& x, uint32_t& used) SLIM_INLINE_LAMBDA {
    const uint32_t isnew = x & 1, d = (x >> 1) & dmask;
    const uint32_t w = isnew ? 1 : 1 + ib;
    if constexpr (kCheck) ok &= isnew || d < cnt;
    const uint32_t v = isnew ? cnt : cnt - 1 - d;
    cnt += isnew;
    x >>= w;
    used += w;
    return v;
  };
  uint32_t v0 = 0, v1 = 0, v2 = 0;
  uint32_t q = 3;  // the previous triangle's p (3: a first triangle or a restart)
  for (uint32_t j = 0; j < n; ++j) {
    uint32_t x = get(pos, 32), used = 0;
    const uint32_t p = j ? x & 3 : 3;
    if (p == 3) {
      const uint32_t skip = j ? 2 : 0;
      x >>= skip;
      used = skip;
      v0 = ref(x, used);
      v1 = ref(x, used);
      v2 = ref(x, used);
    } else {
      uint32_t e;
      if (q == 3) {
        e = (x >> 2) & 3;
        if constexpr (kCheck) ok &= e < 3;
        x >>= 4;
        used = 4;
      } else {
        e = (q + 2 * ((x >> 2) & 1)) % 3;
        x >>= 3;
        used = 3;
      }
      // Corner p + 1 takes the previous corner e + 1, corner p + 2 the previous corner e (edge 3
      // reads as edge 0).
      const uint32_t a = e == 1 ? v1 : e == 2 ? v2 : v0, b = e == 1 ? v2 : e == 2 ? v0 : v1;
      const uint32_t r = ref(x, used);
      v0 = p == 0 ? r : p == 1 ? a : b;
      v1 = p == 1 ? r : p == 2 ? a : b;
      v2 = p == 2 ? r : p == 0 ? a : b;
    }
    q = p;
    pos += used;
    idx[0][j] = v0;
    idx[1][j] = v1;
    idx[2][j] = v2;
  }
  if (end) *end = pos;
  return ok;
}

// The decoders' strip step as a table, entry q << 4 | c: q the previous triangle's p (3 after a
// first triangle or a restart) and c the step's next 4 bits (p | e << 2 after a first triangle or
// a restart; p | b << 2 after a step, e = q + 2b, bit 3 then the reference's). An entry's shuffle
// picks the new corners from the previous triangle packed in a word (corner k's vertex in byte k)
// with the step's vertex in byte 3: corner p takes the step's vertex, corner p + 1 the previous
// corner e + 1, corner p + 2 the previous corner e (edge 3 reads as edge 0, as in decode_strip);
// byte 3 is 0x80 (zero). The AVX2 path loads 16 bytes from the entry as a pshufb control (the
// bytes after the shuffle, the entry's and the next one's, only move bytes 4..15 of the result,
// which nothing reads; the table ends with 8 bytes of padding for the last entry's load); the
// scalar path applies the shuffle with shifts. next: the next step's row (p << 4). Entries with
// p = 3 (a restart) are unused.
struct StepTable {
  struct Entry {
    uint8_t shuffle[4];
    uint8_t next;
    uint8_t pad[3];
  };
  Entry e[64];
  uint8_t tail[8];
  constexpr StepTable() : e{}, tail{} {
    for (int i = 0; i < 64; ++i) {
      const int q = i >> 4, c = i & 15, p = c & 3;
      if (p == 3) continue;
      int edge;
      if (q == 3) {
        const int x = (c >> 2) & 3;
        edge = x == 3 ? 0 : x;
      } else {
        edge = (q + 2 * ((c >> 2) & 1)) % 3;
      }
      Entry& t = e[i];
      t.shuffle[p] = 3;
      t.shuffle[(p + 1) % 3] = uint8_t((edge + 1) % 3);
      t.shuffle[(p + 2) % 3] = uint8_t(edge);
      t.shuffle[3] = 0x80;
      t.next = uint8_t(p << 4);
    }
  }
};
static_assert(sizeof(StepTable) == 64 * 8 + 8, "8-byte entries, 8 bytes of padding");
inline constexpr StepTable kStepTable{};

// decode_strip for the decoders (blocks that check() accepted, read with the slack): the same
// triangles, corner k's vertex in byte k of tri[j]. One 64-bit load per triangle (a restart takes
// at most 2 + 3 x 9 bits of the 57 it holds); a strip step is one kStepTable entry (its byte
// shuffle of the previous triangle and the next row) plus one reference. AVX2 keeps the packed
// triangle in a vector register (the step's vertex inserted in byte 3, one pshufb).
SLIM_INLINE void decode_strip_packed(const ClusterHeader& h, const Layout& L, const uint8_t* bits,
                                     uint32_t c, uint32_t first, uint32_t n, uint32_t (&tri)[8]) {
  uint64_t pos = L.topo;
  uint32_t cnt = 0;
  if (c) {
    const uint32_t x = read_bits(bits, L.table + uint64_t(c - 1) * (L.tb + L.vbw), L.tb + L.vbw);
    pos += uint32_t((x & ((1u << L.tb) - 1)) + predicted_offset(L, first));
    cnt = (x >> L.tb) + predicted_vertex(L, first);
  }
  const uint32_t ib = index_bits(h), dmask = (1u << ib) - 1;
  // One reference from the low bits of y: the vertex; y shifted past it, its width added to s.
  // Without branches: the new bit follows the mesh (about a third of the compiler's branches on it
  // were mispredicted), so both cases are computed and one is kept by a mask.
  auto ref = [&](uint32_t& y, uint32_t& s) SLIM_INLINE_LAMBDA {
    const uint32_t isnew = y & 1;
    const uint32_t reused = isnew - 1;  // all ones for a reused vertex, 0 for a new one
    const uint32_t v = cnt - ((1 + ((y >> 1) & dmask)) & reused);
    const uint32_t w = 1 + (ib & reused);
    cnt += isnew;
    y >>= w;
    s += w;
    return v;
  };
  // Three references from the bits x on (a child's first triangle, a restart's after its 2 bits).
  auto restart = [&](uint64_t x, uint32_t& s) SLIM_INLINE_LAMBDA {
    uint32_t y = uint32_t(x >> s);
    const uint32_t v0 = ref(y, s);
    const uint32_t v1 = ref(y, s);
    const uint32_t v2 = ref(y, s);
    return v0 | v1 << 8 | v2 << 16;
  };
  auto load = [&] {
    uint64_t x;
    std::memcpy(&x, bits + (pos >> 3), 8);
    return x >> (pos & 7);
  };
#if defined(SLIM_SIMD_AVX2)
  using Packed = __m128i;
  auto pack = [](uint32_t t) { return _mm_cvtsi32_si128(int(t)); };
  auto unpack = [](Packed t) { return uint32_t(_mm_cvtsi128_si32(t)); };
  auto step = [](Packed t, uint32_t r, const StepTable::Entry& e) {
    return _mm_shuffle_epi8(_mm_insert_epi8(t, int(r), 3),
                            _mm_loadu_si128(reinterpret_cast<const __m128i*>(&e)));
  };
#else
  using Packed = uint32_t;
  auto pack = [](uint32_t t) { return t; };
  auto unpack = [](Packed t) { return t; };
  auto step = [](Packed t, uint32_t r, const StepTable::Entry& e) {
    const uint8_t* s = e.shuffle;
    const uint32_t t4 = (t & 0xffffffu) | r << 24;
    return (t4 >> (8 * s[0]) & 0xff) | (t4 >> (8 * s[1]) & 0xff) << 8 |
           (t4 >> (8 * s[2]) & 0xff) << 16;
  };
#endif
  uint32_t s = 0;
  Packed t = pack(restart(load(), s));
  pos += s;
  tri[0] = unpack(t);
  // The previous triangle's p as the table's row (q << 4), and the bits of a step's p and edge
  // after it (4 after a first triangle or a restart, 3 after a step). The step's width comes from
  // the bits and w, not from the table, so that the next load's position waits on one load only.
  uint32_t row = 3 << 4, w = 4;
  for (uint32_t j = 1; j < n; ++j) {
    const uint64_t x = load();
    if (((x + 1) & 3) == 0) [[unlikely]] {  // p = 3: a restart (1 in 8 of canyon's later triangles)
      s = 2;
      t = pack(restart(x, s));
      row = 3 << 4;
      w = 4;
    } else {
      const StepTable::Entry& e = kStepTable.e[row | (uint32_t(x) & 15)];
      const uint32_t isnew = uint32_t(x >> w) & 1;
      const uint32_t reused = isnew - 1;  // all ones for a reused vertex, 0 for a new one
      // A reused vertex is cnt - 1 - d = cnt + ~d.
      const uint32_t r = cnt + (~(uint32_t(x >> (w + 1)) & dmask) & reused);
      cnt += isnew;
      s = w + 1 + (ib & reused);
      t = step(t, r, e);
      row = e.next;
      w = 3;
    }
    pos += s;
    tri[j] = unpack(t);
  }
}

// The triangles of child i decoded: v[corner][axis][lane], lanes >= n repeat the last triangle.
struct Decoded8 {
  alignas(32) float v[3][3][8];
  int first = 0, n = 0;  // first triangle of the child in the cluster, its triangle count
};

#if defined(SLIM_SIMD_AVX2)
// key_float lane by lane (exact bit operations: the same bits).
SLIM_INLINE __m256 key_floats8(__m256i code) {
  const __m256i positive = _mm256_srai_epi32(code, 31);  // key's top bit: a positive float
  const __m256i pos_bits = _mm256_and_si256(code, _mm256_set1_epi32(0x7fffffff));
  const __m256i neg_bits = _mm256_xor_si256(code, _mm256_set1_epi32(-1));
  return _mm256_castsi256_ps(_mm256_blendv_epi8(neg_bits, pos_bits, positive));
}
// decimal_coord of 4 lanes times their powers of ten 10^-k: the exact conversion, one correctly
// rounded product, one rounding to float (the same bits).
SLIM_INLINE __m128 decimal_coords4(__m128i q, __m256d inv_pow10) {
  return _mm256_cvtpd_ps(_mm256_mul_pd(_mm256_cvtepi32_pd(q), inv_pow10));
}

// The 8 lanes' vertices at once: the whole vertex (bx + by + bz bits) with one 64-bit gather per
// lane when it fits 57 bits, else with two (the float keys of lossless clusters: about 21 bits an
// axis). The float operations are the scalar decode's, lane by lane (the same conversion, product
// and sum), so both give the same bits.
template <bool kLossless>
SLIM_INLINE void decode_vertices_avx2(const ClusterLattice& lat, const ClusterHeader& h,
                                      const uint8_t* bits, const Layout& L, const uint32_t* anchor,
                                      const uint32_t (&tri)[8], Decoded8& d) {
  // The 64 bits from bit `pos` of each lane (lanes 0-3 in lo, 4-7 in hi): two 64-bit gathers.
  auto gather64 = [&](__m256i pos, __m256i& lo, __m256i& hi) {
    const __m256i byte = _mm256_srli_epi32(pos, 3);
    const __m256i sh = _mm256_and_si256(pos, _mm256_set1_epi32(7));
    lo = gather_window(bits, _mm256_castsi256_si128(byte), _mm256_castsi256_si128(sh));
    hi = gather_window(bits, _mm256_extracti128_si256(byte, 1), _mm256_extracti128_si256(sh, 1));
  };
  // The low 32 bits of each 64-bit lane after a right shift by s, lanes 0-3 from lo, 4-7 from hi.
  auto low32 = [&](__m256i lo, __m256i hi, uint32_t s) {
    const __m128i s64 = _mm_cvtsi32_si128(int(s));
    return low32_lanes(_mm256_srl_epi64(lo, s64), _mm256_srl_epi64(hi, s64));
  };
  auto mask = [](uint32_t w) { return _mm256_set1_epi32(int(uint32_t((uint64_t(1) << w) - 1))); };
  // Per-axis constants, broadcast once for the 3 corners.
  __m256i anchors[3], masks[3];
  __m256 origins[3], steps[3];
  for (int a = 0; a < 3; ++a) {
    anchors[a] = _mm256_set1_epi32(int(anchor[a]));
    masks[a] = mask(axis_bits(h, a));
    origins[a] = _mm256_set1_ps(lat.origin[a]);
    steps[a] = _mm256_set1_ps(lat.step[a]);
  }
  const uint32_t mode = coord_mode(h);
  __m256d inv_pow10[3] = {};
  if (kLossless && mode)
    for (int a = 0; a < 3; ++a) inv_pow10[a] = _mm256_set1_pd(kInvPow10[axis_digits(h, a)]);
  auto store = [&](int k, int a, __m256i off) {
    const __m256i code = _mm256_add_epi32(off, anchors[a]);
    __m256 x;
    if constexpr (kLossless) {
      x = mode ? _mm256_set_m128(decimal_coords4(_mm256_extracti128_si256(code, 1), inv_pow10[a]),
                                 decimal_coords4(_mm256_castsi256_si128(code), inv_pow10[a]))
               : key_floats8(code);
    } else {
      // q < 2^24: the signed conversion is the scalar float(q).
      x = _mm256_add_ps(origins[a], _mm256_mul_ps(_mm256_cvtepi32_ps(code), steps[a]));
    }
    _mm256_store_ps(d.v[k][a], x);
  };
  // Lanes >= n repeat lane n - 1 (their tri entries are not written).
  const __m256i lanes =
      _mm256_min_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), _mm256_set1_epi32(d.n - 1));
  const __m256i packed =
      _mm256_permutevar8x32_epi32(_mm256_load_si256(reinterpret_cast<const __m256i*>(tri)), lanes);
  for (int k = 0; k < 3; ++k) {
    const __m256i vi =
        _mm256_and_si256(_mm256_srli_epi32(packed, 8 * k), _mm256_set1_epi32(0xff));  // corner k
    __m256i vpos = _mm256_add_epi32(_mm256_set1_epi32(int(L.verts)),
                                    _mm256_mullo_epi32(vi, _mm256_set1_epi32(int(L.vbits))));
    // 64-bit windows of the vertex's bits: one for vertices of up to 57 bits, a second from the
    // first axis the first does not hold (axes are at most 32 bits: a window holds any axis whole).
    __m256i lo, hi;
    gather64(vpos, lo, hi);
    uint32_t start = 0, off = 0;  // the window's first bit and the axis's, from the vertex's
    for (int a = 0; a < 3; ++a) {
      const uint32_t w = axis_bits(h, a);
      if (off + w - start > 57) {
        gather64(_mm256_add_epi32(vpos, _mm256_set1_epi32(int(off))), lo, hi);
        start = off;
      }
      store(k, a, _mm256_and_si256(low32(lo, hi, off - start), masks[a]));
      off += w;
    }
  }
}

// The same for a lossy cluster with per-child vertex ranges (a vertex at most kMaxRangeVertexBits):
// per lane the child of the vertex (7 compares with the firsts), its vertex's bit, width, radices
// and bases from the ChildRanges by that child, one 64-bit window per vertex, the mixed-radix
// number's digits from two divisions: in floats, 8 lanes at once, where every child's vertices
// take at most kFloatRadixBits (a grid terrain's: some 10 bits a vertex), else in doubles, 4
// lanes at once. Both exact: the number m and the divisor R are integers the type holds exactly,
// and with m + R below 2^p (p the mantissa's bits with the hidden one: 24 or 53) the
// correctly rounded quotient m / R = q + f, f <= 1 - 1 / R, stays below q + 1, so its floor is q.
SLIM_INLINE void decode_vertices_ranges_avx2(const ClusterLattice& lat, const uint8_t* bits,
                                             const ChildRanges& r, const uint32_t (&tri)[8],
                                             Decoded8& d) {
  auto load = [](const uint32_t* p) {
    return _mm256_load_si256(reinterpret_cast<const __m256i*>(p));
  };
  const __m256i lanes =
      _mm256_min_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), _mm256_set1_epi32(d.n - 1));
  const __m256i packed = _mm256_permutevar8x32_epi32(load(tri), lanes);
  const __m256i rpos = load(r.pos), rw = load(r.w);
  // Every corner's child at once, byte by byte: the children 1..7 whose first (at most 255: a
  // vertex number is at most 254) lies at or below the vertex, each compare -1 where it does.
  __m256i children = _mm256_setzero_si256();
  for (int j = 1; j < 8; ++j) {
    const __m256i f = _mm256_set1_epi8(char(std::min<uint32_t>(r.first[j], 255)));
    children = _mm256_sub_epi8(children, _mm256_cmpeq_epi8(_mm256_max_epu8(packed, f), packed));
  }
  const bool in_floats = r.wmax <= kFloatRadixBits;
  for (int k = 0; k < 3; ++k) {
    const __m256i vi = _mm256_and_si256(_mm256_srli_epi32(packed, 8 * k), _mm256_set1_epi32(0xff));
    const __m256i c = _mm256_and_si256(_mm256_srli_epi32(children, 8 * k), _mm256_set1_epi32(0xff));
    const __m256i w = _mm256_permutevar8x32_epi32(rw, c);
    const __m256i pos =
        _mm256_add_epi32(_mm256_permutevar8x32_epi32(rpos, c), _mm256_mullo_epi32(vi, w));
    const __m256i byte = _mm256_srli_epi32(pos, 3);
    const __m256i sh = _mm256_and_si256(pos, _mm256_set1_epi32(7));
    // Lanes 0-3 (half 0) or 4-7 (half 1) of x; the vertices' 64-bit windows of a half.
    auto part = [](__m256i x, int half) {
      return half ? _mm256_extracti128_si256(x, 1) : _mm256_castsi256_si128(x);
    };
    auto window = [&](int half) { return gather_window(bits, part(byte, half), part(sh, half)); };
    const __m256i rx = _mm256_permutevar8x32_epi32(load(r.radix[0]), c);
    const __m256i ry = _mm256_permutevar8x32_epi32(load(r.radix[1]), c);
    auto store = [&](int a, __m256i o) {
      const __m256i code = _mm256_add_epi32(o, _mm256_permutevar8x32_epi32(load(r.base[a]), c));
      // The code is below 2^31 for any block check() accepts (below 2^24 for one the encoder
      // wrote): the signed conversion is the scalar float(q); the sum rounds as lattice_coord's.
      _mm256_store_ps(d.v[k][a], _mm256_add_ps(_mm256_set1_ps(lat.origin[a]),
                                               _mm256_mul_ps(_mm256_cvtepi32_ps(code),
                                                             _mm256_set1_ps(lat.step[a]))));
    };
    if (in_floats) {
      // The low 32 bits of each lane's window, m < 2^23, R_x R_y <= 2^23.
      const __m256i one = _mm256_set1_epi32(1);
      const __m256i m = _mm256_and_si256(low32_lanes(window(0), window(1)),
                                         _mm256_sub_epi32(_mm256_sllv_epi32(one, w), one));
      const __m256 mf = _mm256_cvtepi32_ps(m), x = _mm256_cvtepi32_ps(rx),
                   y = _mm256_cvtepi32_ps(ry);
      const __m256 t = _mm256_floor_ps(_mm256_div_ps(mf, x));
      const __m256 z = _mm256_floor_ps(_mm256_div_ps(mf, _mm256_mul_ps(x, y)));
      store(0, _mm256_cvtps_epi32(_mm256_fnmadd_ps(t, x, mf)));
      store(1, _mm256_cvtps_epi32(_mm256_fnmadd_ps(z, y, t)));
      store(2, _mm256_cvtps_epi32(z));
      continue;
    }
    // The digits of lanes 0-3 (half 0) or 4-7 (half 1), as doubles.
    __m256d digit[3][2];
    for (int half = 0; half < 2; ++half) {
      const __m256i ones = _mm256_set1_epi64x(1);
      const __m256i m = _mm256_and_si256(
          window(half),
          _mm256_sub_epi64(_mm256_sllv_epi64(ones, _mm256_cvtepu32_epi64(part(w, half))), ones));
      // m < 2^52: its bits under the exponent of 2^52 are the double 2^52 + m.
      const __m256d two52 = _mm256_set1_pd(4503599627370496.0);
      const __m256d md =
          _mm256_sub_pd(_mm256_castsi256_pd(_mm256_or_si256(m, _mm256_castpd_si256(two52))), two52);
      const __m256d x = _mm256_cvtepi32_pd(part(rx, half)), y = _mm256_cvtepi32_pd(part(ry, half));
      const __m256d t = _mm256_floor_pd(_mm256_div_pd(md, x));
      const __m256d z = _mm256_floor_pd(_mm256_div_pd(md, _mm256_mul_pd(x, y)));
      digit[0][half] = _mm256_fnmadd_pd(t, x, md);
      digit[1][half] = _mm256_fnmadd_pd(z, y, t);
      digit[2][half] = z;
    }
    for (int a = 0; a < 3; ++a)
      store(a, _mm256_set_m128i(_mm256_cvtpd_epi32(digit[a][1]), _mm256_cvtpd_epi32(digit[a][0])));
  }
}
#endif

// What every child of one cluster shares: its header, the stream layout, the child sizes, the
// anchors and the per-child vertex ranges, for the cluster's child count (the layout and the
// ranges depend on it). The traversal takes them from the thread's DecodeCache
// (ClusterLeaf::MultiLeafView::get) at most once per multi-leaf visit, and makes them there when
// the cache holds another cluster's.
struct View {
  const uint8_t* bits = nullptr;  // the bit stream (right behind the header)
  ClusterHeader h{};
  Layout L;
  uint32_t sizes = 0;       // child_sizes(h)
  uint32_t anchor[3] = {};  // per-axis anchor codes
  bool ranges = false;      // per-child vertex ranges (has_ranges; lossy only)
  ChildRanges r;            // if ranges
};
template <bool kLossless>
SLIM_INLINE void view_into(View& v, const ClusterLattice& lat, const uint8_t* data,
                           uint32_t children) {
  std::memcpy(&v.h, data, sizeof(v.h));
  v.bits = data + stream_offset(v.h);
  v.L = layout(v.h, children, lat, kLossless);
  v.sizes = child_sizes(v.h);
  if constexpr (kLossless) {
    uint32_t w[3];  // the box start's floats
    std::memcpy(w, v.bits, 12);
    for (int a = 0; a < 3; ++a)
      v.anchor[a] = lossless_anchor(w[a], coord_mode(v.h), axis_digits(v.h, a));
    v.ranges = false;
    return;
  }
  uint64_t x;  // anchors 0 and 1 (at most 64 bits together)
  std::memcpy(&x, v.bits, 8);
  const uint32_t aw0 = v.L.aw[0], aw1 = v.L.aw[1];
  v.anchor[0] = uint32_t(x & ((uint64_t(1) << aw0) - 1));
  v.anchor[1] = uint32_t((x >> aw0) & ((uint64_t(1) << aw1) - 1));
  v.anchor[2] = read_bits(v.bits, aw0 + aw1, v.L.aw[2]);
  if (has_ranges(v.h)) {  // a multi-leaf's cluster (check()): its boxes lie right before it
    const uint8_t* boxes = data - sizeof(LatticeBoxes8);
    const uint8_t* scale = boxes + offsetof(LatticeBoxes8, scale);
#if defined(SLIM_SIMD_AVX2)
    child_ranges_avx2(v.h, v.L, v.bits, v.anchor, boxes, plane_lows(data), scale, children, v.r);
#else
    uint8_t q[6][8];
    lattice_planes(boxes, plane_lows(data), q);
    child_ranges(v.h, v.L, v.bits, v.anchor, q, scale, children, v.r);
#endif
    with_vertex_bits(v.L, v.h, v.r.total);
    v.ranges = true;
  } else {
    v.ranges = false;
  }
}
// The view of a cluster (built in place by view_into where it is kept: the ranges make it some
// 480 bytes).
template <bool kLossless>
SLIM_INLINE View view(const ClusterLattice& lat, const uint8_t* data, uint32_t children) {
  View v;
  view_into<kLossless>(v, lat, data, children);
  return v;
}

// Child `child` of the cluster `v`.
// kScalar: the scalar vertex decode on AVX2 builds too (the tests' and fuzz target's reference).
template <bool kLossless, bool kScalar = false>
SLIM_INLINE void decode_child(const ClusterLattice& lat, const View& v, int child, Decoded8& d) {
  const ClusterHeader& h = v.h;
  const Layout& L = v.L;
  d.first = int(child_first(v.sizes, uint32_t(child)));
  d.n = int(child_size(v.sizes, uint32_t(child)));
  alignas(32) uint32_t tri[8];
  decode_strip_packed(h, L, v.bits, uint32_t(child), uint32_t(d.first), uint32_t(d.n), tri);
#if defined(SLIM_SIMD_AVX2)
  if (!kScalar && !v.ranges) {
    decode_vertices_avx2<kLossless>(lat, h, v.bits, L, v.anchor, tri, d);
    return;
  }
  if (!kScalar && v.ranges) {
    decode_vertices_ranges_avx2(lat, v.bits, v.r, tri, d);
    return;
  }
#endif
  for (int l = d.n; l < 8; ++l) tri[l] = tri[d.n - 1];
  for (int l = 0; l < 8; ++l)
    for (int k = 0; k < 3; ++k) {
      const uint32_t vi = (tri[l] >> (8 * k)) & 0xff;
      if (v.ranges) {
        const ChildRanges& r = v.r;
        const uint32_t c = range_child(r, vi);
        const uint64_t m = read_bits57(v.bits, r.pos[c] + vi * r.w[c], r.w[c]);
        const uint64_t t = m / r.radix[0][c], z = t / r.radix[1][c];
        const uint64_t o[3] = {m - t * r.radix[0][c], t - z * r.radix[1][c], z};
        for (int a = 0; a < 3; ++a)
          d.v[k][a][l] = lattice_coord(lat, a, r.base[a][c] + uint32_t(o[a]));
        continue;
      }
      uint64_t pos = L.verts + uint64_t(vi) * L.vbits;
      for (int a = 0; a < 3; ++a) {
        d.v[k][a][l] = decode_coord<kLossless>(
            lat, a, v.anchor[a] + read_bits(v.bits, pos, axis_bits(h, a)), axis_mode(h, a));
        pos += axis_bits(h, a);
      }
    }
}
// Child `child` of a cluster of `children` children (the multi-leaf's count).
template <bool kLossless>
SLIM_INLINE void decode_child(const ClusterLattice& lat, const uint8_t* data, uint32_t children,
                              int child, Decoded8& d) {
  decode_child<kLossless>(lat, view<kLossless>(lat, data, children), child, d);
}

// What the ids of a child's triangles take from the cluster's view (kept with a decoded child in
// the DecodeCache, so that a hit in a cached child needs no view).
struct ChildIds {
  uint64_t repeats = 0;  // bit of the flag planes (the first: the repeat bits)
  uint64_t entries = 0;  // bit of the ids' entries
  uint64_t runs = 0;     // bit of the run starts' low parts
  uint32_t prim_base = 0, geom_base = 0;
  uint8_t idbits = 0, rb = 0, ob = 0, gb = 0, pb = 0;
  uint8_t first = 0, ntris = 0;  // the child's first triangle; the cluster's triangles
  uint8_t flag_planes = 0;       // id_flag_planes
};
// The ids of the triangles from triangle `first` of the cluster `v` on.
SLIM_INLINE ChildIds child_ids(const View& v, uint32_t first) {
  const ClusterHeader& h = v.h;
  const Layout& L = v.L;
  ChildIds c;
  c.repeats = L.ids;
  c.entries = L.end;
  c.runs = L.runs;
  c.first = uint8_t(first);
  c.ntris = uint8_t(L.ntris);
  c.flag_planes = uint8_t(id_flag_planes(h));
  const uint32_t bb = prim_base_bits(h);
  c.prim_base = read_bits(v.bits, L.bases, bb);
  c.geom_base = read_bits(v.bits, L.bases + bb, geom_base_bits(h));
  c.idbits = uint8_t(L.idbits);
  c.rb = uint8_t(L.rb);
  c.ob = uint8_t(offset_bits(h));
  c.gb = uint8_t(geom_bits(h));
  c.pb = uint8_t(run_low_bits(h));
  return c;
}
// The start of run `run` (from prim_base; bits: the cluster's stream): 0 for run 0, else
// e + run x 2^ob with e's high part the position of the highs' (run - 1)-th one bit less run - 1.
// The scan reads 64-bit words from the byte of its position (the first word's bits below the
// position shifted out), at most the words that cover kMaxRunHighBits bits: a block check()
// accepted has the bit there, and none makes the scan read further.
SLIM_INLINE uint32_t run_start(const uint8_t* bits, const ChildIds& c, uint64_t highs,
                               uint32_t run) {
  if (run == 0) return 0;
  const uint32_t i = run - 1;
  uint64_t pos = highs;
  uint32_t k = i, high = 0;
  constexpr uint32_t kWords = 1 + (kMaxRunHighBits - 57 + 63) / 64;  // the first word: >= 57 bits
  for (uint32_t w = 0; w < kWords; ++w) {
    uint64_t x;
    std::memcpy(&x, bits + (pos >> 3), 8);
    x >>= pos & 7;
    const uint32_t n = uint32_t(__builtin_popcountll(x));
    if (k < n) {
      high = uint32_t(pos - highs) + simd::select_bit(x, k) - i;
      break;
    }
    k -= n;
    pos += 64 - (pos & 7);
  }
  const uint64_t e = (uint64_t(high) << c.pb) + read_bits(bits, c.runs + uint64_t(i) * c.pb, c.pb);
  return uint32_t(e + (uint64_t(run) << c.ob));
}
// primID and geomID of triangle `first + l` (bits: the cluster's stream; l below the child's
// triangle count: a padding lane names a triangle of the next child, or none). With repeat bits
// (r), step bits (s) and double steps (d; those missing: 0), the triangles without an entry are
// those with r, s or d set (triangle 0's bits are ignored: it always has one); triangle t takes the
// ids of the last triangle p <= t with an entry, its entry p less the triangles without one before
// it, plus the steps s + 2d of triangles p + 1..t without r less those with r; the entries are
// ntris less all triangles without one.
// The flag plane of ntris <= 64 bits from bit `pos` (bits beyond ntris as the stream has them):
// two 64-bit loads, the second from the next word where the plane reaches into a ninth byte (more
// than 56 of the plane's bits then lie behind its first byte, so the load ends inside the read
// slack), else from the same word; the choice without a branch (the shift's start varies from
// cluster to cluster).
SLIM_INLINE uint64_t id_flag_bits(const uint8_t* bits, uint64_t pos, uint32_t ntris) {
  const uint8_t* at = bits + (pos >> 3);
  const uint32_t sh = uint32_t(pos & 7);
  const bool two = sh + ntris > 64;  // then sh >= 1
  uint64_t x, y;
  std::memcpy(&x, at, 8);
  std::memcpy(&y, at + (two ? 8 : 0), 8);
  return (x >> sh) | (two ? (y << 1) << (63 - sh) : 0);
}
SLIM_INLINE void decode_ids(const uint8_t* bits, const ChildIds& c, uint32_t l, uint32_t& geom,
                            uint32_t& prim) {
  const uint32_t t = (uint32_t(c.first) + l) & 63;
  uint32_t entry = t, entries = c.ntris, p = t;
  int32_t step = 0;
  if (c.flag_planes) {
    const uint64_t r = id_flag_bits(bits, c.repeats, c.ntris);
    const uint64_t s = c.flag_planes > 1 ? id_flag_bits(bits, c.repeats + c.ntris, c.ntris) : 0;
    const uint64_t d =
        c.flag_planes > 2 ? id_flag_bits(bits, c.repeats + 2 * uint64_t(c.ntris), c.ntris) : 0;
    const uint64_t valid = (uint64_t(2) << ((c.ntris - 1) & 63)) - 2;  // triangles 1..ntris - 1
    const uint64_t none = (r | s | d) & valid, upto = (uint64_t(2) << t) - 1;  // no entry; 0..t
    p = 63 - uint32_t(__builtin_clzll(~none & upto));  // triangle 0 has an entry
    entry = p - uint32_t(__builtin_popcountll(none & ((uint64_t(1) << p) - 1)));
    entries -= uint32_t(__builtin_popcountll(none));
    const uint64_t after = upto & ~((uint64_t(2) << p) - 1);  // triangles p + 1..t
    auto count = [after](uint64_t x) { return int32_t(__builtin_popcountll(x & after)); };
    step = count(s & ~r) + 2 * count(d & ~r) - count(s & r) - 2 * count(d & r);
  }
  const uint64_t highs = c.entries + uint64_t(entries) * c.idbits;
  const uint64_t pos = c.entries + uint64_t(entry) * c.idbits;
  const uint32_t run = read_bits(bits, pos, c.rb);
  prim = c.prim_base + run_start(bits, c, highs, run) + read_bits(bits, pos + c.rb, c.ob) +
         uint32_t(step);
  geom = c.geom_base + read_bits(bits, pos + c.rb + c.ob, c.gb);
}
// primID and geomID of triangle t of the cluster `v`.
SLIM_INLINE void decode_ids(const View& v, uint32_t t, uint32_t& geom, uint32_t& prim) {
  decode_ids(v.bits, child_ids(v, t), 0, geom, prim);
}
// primID and geomID of triangle t of a cluster of `children` children.
template <bool kLossless>
SLIM_INLINE void decode_ids(const ClusterLattice& lat, const uint8_t* data, uint32_t children,
                            uint32_t t, uint32_t& geom, uint32_t& prim) {
  decode_ids(view<kLossless>(lat, data, children), t, geom, prim);
}

// What box_frame takes from the lattice, made once per scene (lattice_frame: Context::frame): the
// lattice, and where the anchors lie in the stream's first 16 bytes: anchor a's bits first[a] ..
// first[a] + width[a] (the lattice's anchor_bits, first[a] <= 48), for the AVX2 path as the 4
// bytes from its first byte (a pshufb control: byte 48 / 8 + 3 at most), a right shift in them
// and a mask; the origin, the step and its bits as vectors (memory operands of the frame's
// instructions, no broadcasts per visit).
struct LatticeFrame {
  ClusterLattice lat;
  alignas(16) uint8_t bytes[16] = {};
  alignas(16) uint32_t shift[4] = {};
  alignas(16) uint32_t mask[4] = {};
  alignas(16) float origin[4] = {};  // lane 3: 0
  alignas(16) float step[4] = {};    // lat.step, lane 3: 0
  uint32_t first[3] = {}, width[3] = {};
};
SLIM_INLINE LatticeFrame lattice_frame(const ClusterLattice& lat) {
  LatticeFrame f;
  f.lat = lat;
  for (int a = 0; a < 3; ++a) {
    f.origin[a] = lat.origin[a];
    f.step[a] = lat.step[a];
  }
  uint32_t o = 0;
  for (int a = 0; a < 3; ++a) {
    const uint32_t w = std::min<uint32_t>(lat.anchor_bits[a], 24);  // check_opened: <= 24
    f.first[a] = o;
    f.width[a] = w;
    for (int j = 0; j < 4; ++j) f.bytes[4 * a + j] = uint8_t((o >> 3) + uint32_t(j));
    f.shift[a] = o & 7;
    f.mask[a] = (1u << w) - 1;
    o += w;
  }
  for (int j = 12; j < 16; ++j) f.bytes[j] = 0x80;  // lane 3: 0
  return f;
}

// The boxes' start per axis (4 floats, the 4th unused): the anchor's lattice coordinate, from the
// anchors (f.width[a] <= 24 bits each) in the first 16 bytes at `bits` (the stream's start; the
// builder passes a padded copy). The one computation of it, for the builder and the traversal
// alike; the AVX2 path takes the three axes at once (one load, a byte shuffle, a shift and a mask
// per lane: read_bits' bits) with one fma (the product is exact, check_lattice: it rounds as
// lattice_coord's sum).
SLIM_INLINE void box_start(const LatticeFrame& f, const uint8_t* bits, float* start) {
#if defined(SLIM_SIMD_AVX2)
  const __m128i raw = _mm_lddqu_si128(reinterpret_cast<const __m128i*>(bits));
  const __m128i x =
      _mm_shuffle_epi8(raw, _mm_load_si128(reinterpret_cast<const __m128i*>(f.bytes)));
  const __m128i q =
      _mm_and_si128(_mm_srlv_epi32(x, _mm_load_si128(reinterpret_cast<const __m128i*>(f.shift))),
                    _mm_load_si128(reinterpret_cast<const __m128i*>(f.mask)));
  _mm_storeu_ps(start,
                _mm_fmadd_ps(_mm_cvtepi32_ps(q), _mm_load_ps(f.step), _mm_load_ps(f.origin)));
#else
  for (int a = 0; a < 3; ++a)
    start[a] = lattice_coord(f.lat, a, read_bits(bits, f.first[a], f.width[a]));
  start[3] = 0.0f;
#endif
}

// The frame (start, extent per axis; 4 floats each, the 4th unused) of the LatticeBoxes8 at p,
// the cluster's data right behind them (its stream holds the anchors and more, plus
// kClusterReadSlack: 16 bytes to read). Read on every multi-leaf visit: the AVX2 path takes the
// three axes at once (a dozen instructions instead of some 45), the extents as box_extent's
// products lane by lane.
SLIM_INLINE void box_frame(const LatticeFrame& f, const uint8_t* p, float* start, float* extent) {
  const uint8_t* scale = p + offsetof(LatticeBoxes8, scale);
  box_start(f, stream_of(p + sizeof(LatticeBoxes8)), start);
#if defined(SLIM_SIMD_AVX2)
  uint32_t sc;
  std::memcpy(&sc, scale, 4);  // the 3 scale bytes and the cluster header's first
  const __m128i e = _mm_add_epi32(_mm_slli_epi32(_mm_cvtepu8_epi32(_mm_cvtsi32_si128(int(sc))), 20),
                                  _mm_set1_epi32(127 << 23));  // scale_factor's bits
  _mm_storeu_ps(extent, _mm_mul_ps(_mm_castsi128_ps(e), _mm_load_ps(f.step)));
#else
  for (int a = 0; a < 3; ++a) extent[a] = box_extent(f.lat, a, scale[a]);
  extent[3] = 0.0f;
#endif
}
// The builder's side: writes the scale bytes into `boxes` for the lossy cluster at `data` whose
// vertices lie in `box` (decoded), and returns the frame in start and extent (4 floats each, as
// box_frame decodes it). False if no scale reaches the box (coordinates near the float range).
bool write_box_frame(const ClusterLattice& lat, const uint8_t* data, const Box3f& box,
                     LatticeBoxes8& boxes, float* start, float* extent);

// The frame of the ExactBoxes8 at p (4 floats each, the 4th unused), the lossless cluster's data
// right behind it: the start the stream's first 3 floats (lossless_anchor), the extents the
// bfloat16s. The one computation of it, for the builder (exact_box_start on the encoded cluster)
// and the traversal, which reads it on every multi-leaf visit.
SLIM_INLINE void exact_box_start(const uint8_t* data, float* start) {
  const uint8_t* bits = data + sizeof(ClusterHeader);  // the start's 3 floats, then more stream
#if defined(SLIM_SIMD_AVX2)
  _mm_storeu_ps(start, _mm_loadu_ps(reinterpret_cast<const float*>(bits)));  // lane 3 unused
#else
  std::memcpy(start, bits, 12);
  start[3] = 0.0f;
#endif
}
SLIM_INLINE void exact_box_frame(const uint8_t* p, float* start, float* extent) {
  exact_box_start(p + sizeof(ExactBoxes8), start);
#if defined(SLIM_SIMD_AVX2)
  // The 3 bfloat16s (and the header's first 2 bytes, lane 3, unused) widened and shifted at once.
  uint64_t e;
  std::memcpy(&e, p + offsetof(ExactBoxes8, extent), 8);
  _mm_storeu_ps(extent, _mm_castsi128_ps(
                            _mm_slli_epi32(_mm_cvtepu16_epi32(_mm_cvtsi64_si128(int64_t(e))), 16)));
#else
  uint16_t e[3];
  std::memcpy(e, p + offsetof(ExactBoxes8, extent), sizeof(e));
  for (int a = 0; a < 3; ++a) extent[a] = bfloat16_float(e[a]);
  extent[3] = 0.0f;
#endif
}
// The builder's side: writes the extents into `boxes` for the lossless cluster at `data` whose
// vertices lie in `box`, and returns the frame as exact_box_frame decodes it. False if no normal
// bfloat16 reaches the box (coordinates near the float range).
bool write_exact_box_frame(const uint8_t* data, const Box3f& box, ExactBoxes8& boxes, float* start,
                           float* extent);
// The multi-leaf boxes (a LatticeBoxes8 or an ExactBoxes8) of the k children (boxes[c]: the BVH2
// leaves') of the cluster at `data` into `header`: the frame of their union and the children's
// planes in it (quantize_planes). Lossy, the cluster's encoder has taken the planes already
// (multileaf_boxes below: the same frame, planes and choice of fine or coarse ones) and stored
// their low bits if fine; this writes their coarse values and throws std::logic_error if its
// choice or the low bits differ from the encoder's.
// False if no frame reaches the union (coordinates near the float range).
bool write_multileaf_boxes(const ClusterLattice& lat, bool lossless, const uint8_t* data, int k,
                           const Box3f* boxes, uint8_t* header);

// The children a thread decoded last, so that the rays after it that enter the same child (the
// neighbouring pixels of a tile, a bounce leaving the surface it hit) skip the strip and vertex
// decoding. Direct-mapped on the child's address; a scene's tag (Context::cache_tag, unique per
// scene for the process) is part of the key, so a later scene at the same addresses never reads
// another's entries. One per tracing thread, allocated at its first cluster ray: 4096 entries of
// 384 bytes (1.5 MiB) and 256 views (below, 128 KiB), not scene memory. A decode costs some 850
// instructions (canyon:1024: strip 390, vertex gathers 370, ids 85) plus the cluster's view where
// the cache lacks it; a hit costs an entry read from L2 or L3, prefetched when the ray enters the
// child's box (prefetch, below): diffuse bounces spread over the scene come back to children
// decoded thousands of visits before (4096 entries decode a quarter fewer children than 1024 on
// canyon:1024, 40% fewer on stanford_bunny; 1024 x 1024 pixels, 8 bounces). The entries start on
// cache lines (6 lines each).
//
// It keeps the clusters' views too (View: header, layout, anchors, per-child vertex ranges; some
// 600 instructions to make), direct-mapped on the cluster's address and keyed by it, the scene's
// tag and the child count (a view holds one count's layout; the structure check refuses a scene
// file whose references name one multi-leaf twice, possibly with two counts, and the key keeps
// each count to its own view all the same): a visit that decodes a child needs its cluster's view,
// and on canyon:1024 a visit decodes 1.3 children on average while the next rays through the
// cluster decode its others. 256 views already hold 81% of the views canyon:1024's primary rays
// need (50% with 8 diffuse bounces, 33% on stanford_bunny's; docs/results.md, "The clusters' views
// in the decode cache").
struct alignas(64) DecodeCache {
  static constexpr uint32_t kLogEntries = 12, kLogViews = 8;
  struct Entry {
    Decoded8 d;
    ChildIds ids;                   // of d's triangles
    const uint8_t* bits = nullptr;  // the cluster's data (its header)
    uint64_t tag = 0;               // 0: empty (scene tags start at 1)
    int child = -1;
  };
  struct alignas(64) ViewEntry {
    View v;
    const uint8_t* data = nullptr;  // the cluster's data (its header)
    uint64_t tag = 0;               // 0: empty
    uint32_t children = 0;          // the multi-leaf's child count v was made for
  };
  Entry e[1u << kLogEntries];
  ViewEntry views[1u << kLogViews];
  // Fibonacci hashing: the top bits pick the entry.
  static SLIM_INLINE uint64_t hash(const uint8_t* bits, int child) {
    return (uint64_t(reinterpret_cast<uintptr_t>(bits)) + uint64_t(child)) * 0x9E3779B97F4A7C15ull;
  }
  SLIM_INLINE Entry& slot(const uint8_t* bits, int child) {
    return e[hash(bits, child) >> (64 - kLogEntries)];
  }
  SLIM_INLINE ViewEntry& view_slot(const uint8_t* bits) {
    return views[hash(bits, 0) >> (64 - kLogViews)];
  }
  // Starts loading the entry of each child in `mask` (its 6 cache lines), ahead of the tag check
  // and the triangle test that read it (or the decoding that writes it).
  SLIM_INLINE void prefetch(const uint8_t* bits, uint32_t mask) {
    while (mask) {
      const auto* p = reinterpret_cast<const char*>(&slot(bits, int(__builtin_ctz(mask))));
      mask &= mask - 1;
      for (int l = 0; l < int(sizeof(Entry) / 64); ++l) __builtin_prefetch(p + 64 * l, 1, 3);
    }
  }
};
static_assert(sizeof(DecodeCache::Entry) % 64 == 0, "entries on whole cache lines");
static_assert(sizeof(DecodeCache::ViewEntry) == 512, "256 views in 128 KiB");
// This thread's cache, read on every multi-leaf visit a ray enters: a plain thread_local pointer
// (constant-initialized: no guard, no call), set by allocate_decode_cache (cluster.cpp) at the
// thread's first cluster ray, which also frees the cache at thread exit.
inline thread_local DecodeCache* t_decode_cache = nullptr;
DecodeCache* allocate_decode_cache();
SLIM_INLINE DecodeCache& decode_cache() {
  DecodeCache* c = t_decode_cache;
  if (!c) [[unlikely]]
    c = allocate_decode_cache();
  return *c;
}
// A tag no scene had before (1, 2, ...).
uint64_t next_cache_tag();

// Checks that `size` bytes at `data` hold a well-formed cluster of `children` children on the
// scene's lattice `lat` (lossy: the anchors' widths, at most 24 bits; lossless decimal: the start
// floats decimals of their axes' digits (lossless_anchor); header fields in range, no
// child sizes beyond the child count, every strip inside the topology stream with every vertex
// index below nverts, every run index below nruns, the run highs' nruns - 1 one bits within
// kMaxRunHighBits bits, the stream inside `size`). The decoders read only what this accepts (plus
// kClusterReadSlack bytes). `boxes`: the LatticeBoxes8 right before a lossy multi-leaf's cluster,
// from which its per-child vertex ranges come (nullptr elsewhere: a cluster with the ranges bit
// or the fine-planes bit fails).
bool check(const uint8_t* data, uint64_t size, uint32_t children, const ClusterLattice& lat,
           bool lossless, std::string* why, const uint8_t* boxes = nullptr);
// The lattice fields the decoders take as given (lossy: anchor widths of at most 24 bits, steps
// (8 + m) 2^e / 8 with m < 8 in [kMinLatticeStep, kMaxLatticeStep], anchor widths of at most
// kFineStepCodeBits where m > 0), else what is wrong (and its byte in `offset`).
std::string check_lattice(const ClusterLattice& lat, size_t* offset = nullptr);

// Per-scene encoding figures (info --clusters). The four parts add up to the clusters' bytes
// (but for the padding to whole bytes and of short streams to kMinStreamBytes).
struct EncodeStats {
  std::mutex m;
  uint64_t clusters = 0, triangles = 0, vertices = 0;
  uint64_t position_bits = 0;     // sum over clusters of nverts * (bx + by + bz)
  uint64_t topology_bits = 0;     // strips, the child table, the child sizes and tbits
  uint64_t id_bits = 0;           // run starts, run indices, offsets, geomIDs, the bases and widths
  uint64_t header_bits = 0;       // the rest of the header, the anchors (lossless: start floats)
  uint64_t decimal_clusters = 0;  // lossless clusters in decimal mode
  uint64_t plane_clusters = 0;    // lossy multi-leaves' clusters (their boxes' planes) ...
  uint64_t fine_plane_clusters = 0;  // ... with the fine-planes bit
};

}  // namespace cluster

// Build-time source: decoded positions (what the leaves return) and the per-vertex codes.
struct ClusterSource {
  const Vec3f* vertices = nullptr;  // decoded position per vertex
  const uint32_t* codes = nullptr;  // 3 per vertex: lattice integers or order keys
  const uint32_t* tris = nullptr;
  const uint32_t* geom_ids = nullptr;
  const uint32_t* prim_ids = nullptr;
  bool lossless = false;
  ClusterLattice lattice;                // lossy: the multi-leaf boxes' frames
  std::vector<uint8_t>* side = nullptr;  // isolated leaves' cluster records
  std::mutex* side_mutex = nullptr;
  cluster::EncodeStats* stats = nullptr;
  // Blocks encoded ahead (keyed by their first triangle), taken by encode_multileaf.
  // Each with its triangles in child order.
  std::unordered_map<uint32_t, std::pair<std::vector<uint32_t>, std::vector<uint8_t>>>* encoded =
      nullptr;
  // Isolated one-triangle leaves' records, placed in `side` ahead (keyed by the triangle) in an
  // order that does not depend on the threads; encode() takes their offsets.
  std::unordered_map<uint32_t, uint64_t>* side_offsets = nullptr;
};

namespace cluster {
// Encodes the triangles prims[c][0..counts[c]) of k <= 8 children (each <= 8 triangles) as one
// cluster: header + stream, followed by kClusterReadSlack zero bytes only if `slack`.
// ranges: the cluster will be a multi-leaf's (its LatticeBoxes8 right before it, as
// multileaf_boxes below makes them): lossy, it takes per-child vertex ranges when they are smaller.
std::vector<uint8_t> encode(const ClusterSource& s, const uint32_t* const* prims,
                            const uint32_t* counts, int k, bool slack, bool ranges = false);
// The multi-leaf boxes of a lossy cluster of these children with these anchors (the per-axis
// smallest codes), as the build writes them: write_box_frame of the union of the children's boxes,
// quantize_planes of each child's (the union of its triangles' decoded boxes: the BVH2 leaf's
// box), the 8-bit planes the traversal decodes: fine (these) where the coarse ones would grow the
// children's boxes by more than kCoarsePlaneGrowth in surface area, else coarse (these rounded
// outward, LatticeBoxes8). False if no frame reaches the box (write_box_frame).
struct MultiLeafPlanes {
  uint8_t q[6][8];   // the 8-bit planes (as QuantBoxes8::q; lanes >= k empty)
  uint8_t scale[3];  // the scale bytes
  bool fine;         // q are fine planes (the cluster keeps their low bits)
};
bool multileaf_boxes(const ClusterSource& s, const uint32_t* const* prims, const uint32_t* counts,
                     int k, const uint32_t* anchor, MultiLeafPlanes& out);

// The lossy lattice's steps (per axis a power of two) for an error bound (rel_error x the box
// diagonal) over `box` (empty: steps 1): s, the largest power of two with s sqrt(3) / 2 <= bound
// (rounding to the nearest lattice point moves a vertex by at most half a step per axis), or 2s on
// one or two axes (the widest first) where the bound still holds with the decode's rounding (half
// an ulp of the box's largest coordinate per axis). s is kept within [kMinLatticeStep,
// kMaxLatticeStep] and at most the power of two at or above the widest extent; an axis is
// coarsened (its step doubled) until the box's extent spans fewer than 2^24 - 1 steps (so that
// every offset fits a block's 24 bits and float(q) is exact). Returns false if a step had to be
// coarser than the bound's (the bound may not hold); throws Error if an axis would need a step
// above kMaxLatticeStep.
bool lattice_steps(double bound, const Box3f& box, double* step);
// The lossy lattice's finer steps: per axis (8 + m) 2^e / 8 (m < 2^kStepMantissaBits), the three
// with the largest product (the fewest lattice points, so the fewest bits a vertex) whose error,
// half a step and the decode's rounding per axis, stays within the bound (of equal products the
// smallest error). Powers of two alone waste up to about 1.5 bits a vertex of that: 0.07-1.22 on
// the benchmark's meshes (docs/results.md, "Lattice steps between powers of two"). An axis takes
// a step with m > 0 only where its extent spans fewer than 2^kFineStepCodeBits - 2 of them, a
// power of two where fewer than 2^24 - 2. False where no three steps within [kMinLatticeStep,
// kMaxLatticeStep] and at most the power of two at or above the widest extent keep the bound (a
// bound not positive, an empty box, coordinates whose rounding takes most of the bound, an
// extent too wide): lattice_steps' then.
bool fine_lattice_steps(double bound, const Box3f& box, double* step);

// Codes and decoded positions of the vertices that the triangles use (others: code 0, position
// unchanged). Lossy: origin = the box minimum, the steps fine_lattice_steps' where they apply,
// else lattice_steps'. The box is `lattice_box` when it is not empty (BuildOptions::lattice_box,
// which must contain the vertices: meshes quantized with the same box share one lattice, so a
// vertex they share gets the same code and decodes to the same bits in each), else the used
// vertices' box; then an axis whose codes all end in k zero bits takes 2^k times the step and the
// codes k bits less (the same decoded bits).
// That is checked on lattice_steps' codes first: where an axis has such codes (the rows of a
// grid terrain, whose grid lies on a power-of-two lattice) the lattice keeps lattice_steps'.
// The lattice's anchor_bits: per axis the bit width of the largest code of the box (or of a used
// vertex, if larger). Lossless: the order keys of the exact floats.
struct Quantized {
  ClusterLattice lattice;
  bool coarsened = false;
  std::vector<uint32_t> codes;  // 3 per vertex
  std::vector<Vec3f> decoded;
  double diag = 0, max_error = 0, rms_error = 0,
         mean_error = 0;  // error: |decoded - input| over used vertices
};
Quantized quantize(const Vec3f* vertices, size_t vertex_count, const uint32_t* tris,
                   size_t tri_count, double rel_error, bool lossless,
                   const Box3f& lattice_box = Box3f());
}  // namespace cluster

template <bool kLossless>
struct ClusterLeaf {
  struct Context {
    ClusterLattice lattice;
    cluster::LatticeFrame frame = cluster::lattice_frame(lattice);  // from `lattice`
    const uint8_t* side = nullptr;
    uint64_t side_bytes = 0;                         // scene files: the section's size
    uint64_t cache_tag = cluster::next_cache_tag();  // this scene's key in cluster::DecodeCache
  };
  // Scene files: the lattice and the side data.
  template <class V>
  static void context_sections(V& v, const std::string& p, Context& c) {
    v.pod(p + "cluster.lattice", c.lattice);
    if (!v.saving()) c.frame = cluster::lattice_frame(c.lattice);  // of the lattice read
    v.array(p + "cluster.side", c.side, c.side_bytes);
  }
  static constexpr uint32_t kBlockPrims = 8;
  static constexpr uint32_t kBlockBytes = 8;
  static constexpr bool kMultiLeafLayout = true;
  // Every read of a cluster, its boxes and its isolated leaves' blocks is an unaligned load or a
  // memcpy: the collapse packs them without padding (traverse.h leaf_align).
  static constexpr uint32_t kLeafAlign = 1;

  // Scene files' structure check (OpenOptions::check_structure): the cluster a multi-leaf holds
  // (`avail` bytes from `data` to the end of the leaf arena, whose last kClusterReadSlack bytes
  // are the decoders' read slack), and the side arena's record an isolated leaf names.
  static std::string check_multileaf(const Context& ctx, const uint8_t* data, uint32_t k,
                                     uint64_t avail) {
    if constexpr (!kLossless) {  // the box scales right before the data (the walk checked them in)
      for (const uint8_t* sc = data - 3; sc < data; ++sc)
        if (uint32_t(*sc >> 3) > cluster::kMaxBoxScaleExp)
          return "multi-leaf box scale exponent " + std::to_string(*sc >> 3) + " beyond " +
                 std::to_string(cluster::kMaxBoxScaleExp);
    } else {  // the box extents right before the data
      uint16_t e[3];
      std::memcpy(e, data - sizeof(e), sizeof(e));
      for (uint16_t x : e)
        if (!cluster::extent_ok(x))
          return "multi-leaf box extent " + std::to_string(x) +
                 " (bfloat16 bits) not a positive normal float";
    }
    std::string why;
    if (avail < kClusterReadSlack) return "cluster beyond the leaf arena";
    if (!cluster::check(data, avail - kClusterReadSlack, k, ctx.lattice, kLossless, &why,
                        kLossless ? nullptr : data - sizeof(cluster::LatticeBoxes8)))
      return why;
    return {};
  }
  static std::string check_block(const Context& ctx, const uint8_t* block) {
    uint64_t off;
    std::memcpy(&off, block, 8);
    if (ctx.side_bytes < kClusterReadSlack || off > ctx.side_bytes - kClusterReadSlack)
      return "cluster record offset beyond the side arena (cluster.side)";
    std::string why;
    if (!cluster::check(ctx.side + off, ctx.side_bytes - kClusterReadSlack - off, 1, ctx.lattice,
                        kLossless, &why))
      return why + " (cluster.side)";
    return {};
  }

  // ---- build side ----
  // A block encoded ahead was made of exactly these children (the cache is keyed by the first
  // triangle only).
  static bool same_children(const std::vector<uint32_t>& order, const uint32_t* const* prims,
                            const uint32_t* counts, int k) {
    size_t i = 0;
    for (int c = 0; c < k; ++c)
      for (uint32_t j = 0; j < counts[c]; ++j, ++i)
        if (i >= order.size() || order[i] != prims[c][j]) return false;
    return i == order.size();
  }
  static Box3f source_bounds(const ClusterSource& s, uint32_t t) {
    Box3f b;
    for (int k = 0; k < 3; ++k) b.extend(s.vertices[s.tris[3 * size_t(t) + k]]);
    return b;
  }
  static uint64_t source_key(const ClusterSource& s, uint32_t t) {
    const uint32_t* v = &s.tris[3 * size_t(t)];
    return triangle_key(s.vertices[v[0]], s.vertices[v[1]], s.vertices[v[2]], s.geom_ids[t],
                        s.prim_ids[t]);
  }
  // Exact duplicates at the positions the clusters store (TriangleSourceOps::duplicate_key),
  // which the BVH2 builder may drop from stacks of coincident triangles.
  static TriangleSource triangles(const ClusterSource& s) {
    return {s.vertices, s.tris, s.geom_ids, s.prim_ids};
  }
  static uint64_t duplicate_key(const ClusterSource& s, uint32_t t) {
    return TriangleSourceOps::duplicate_key(triangles(s), t);
  }
  static bool same_surface(const ClusterSource& s, uint32_t a, uint32_t b) {
    return TriangleSourceOps::same_surface(triangles(s), a, b);
  }
  static std::vector<uint8_t> encode_multileaf(const ClusterSource& s, const uint32_t* const* prims,
                                               const uint32_t* counts, int k) {
    if (s.encoded) {
      auto it = s.encoded->find(prims[0][0]);
      if (it != s.encoded->end()) {
        std::vector<uint8_t> block = std::move(it->second.second);
        const bool same = same_children(it->second.first, prims, counts, k);
        s.encoded->erase(it);
        if (same) return block;
      }
    }
    return cluster::encode(s, prims, counts, k, false, true);
  }
  static void encode(const ClusterSource& s, const uint32_t* prims, uint32_t n, uint8_t* out) {
    if (s.side_offsets && n == 1) {
      const auto it = s.side_offsets->find(prims[0]);
      if (it != s.side_offsets->end()) {
        std::memcpy(out, &it->second, 8);
        return;
      }
    }
    std::vector<uint8_t> rec = cluster::encode(s, &prims, &n, 1, false);
    std::lock_guard<std::mutex> lock(*s.side_mutex);
    const uint64_t off = s.side->size();
    s.side->insert(s.side->end(), rec.begin(), rec.end());
    std::memcpy(out, &off, 8);
  }

  // The multi-leaf boxes are a cluster::LatticeBoxes8 (39 B, lossy: 6-bit planes, 8-bit ones
  // with the low bits in the cluster) or cluster::ExactBoxes8 (54 B, lossless) instead of a
  // 72-byte MultiLeaf8 (traverse.h, HasMultiLeafBoxes).
  static constexpr bool kMultiLeafBoxes = true;
  static constexpr uint32_t kMultiLeafHeaderBytes =
      kLossless ? sizeof(cluster::ExactBoxes8) : sizeof(cluster::LatticeBoxes8);
  // The builder's side (bvh_scene.h): the boxes of the k children (boxes[c]: the BVH2 leaves')
  // of the cluster at `data` into `header`: the frame of their union and the child boxes'
  // planes in it (quantize_planes). Lossy, the cluster's encoder has taken the planes already
  // (cluster::multileaf_boxes: the same frame and planes) and stored their low bits if fine;
  // this writes their coarse values and checks that the planes are the encoder's. Multi-leaves
  // lie at any byte (kLeafAlign): the boxes are written through a copy (an ExactBoxes8's extents
  // are 2-byte fields).
  static void write_multileaf_boxes(const ClusterSource& s, const uint8_t* data, int k,
                                    const Box3f* boxes, uint8_t* header) {
    if (!cluster::write_multileaf_boxes(s.lattice, kLossless, data, k, boxes, header))
      throw Error(
          "cluster: a cluster's box does not fit its multi-leaf frame (coordinates near the "
          "float range)");
  }
  static SLIM_INLINE void multileaf_frame(const Context& ctx, const uint8_t* p, float* start,
                                          float* extent) {  // 4 floats each
    if constexpr (kLossless)
      cluster::exact_box_frame(p, start, extent);
    else
      cluster::box_frame(ctx.frame, p, start, extent);
  }
  // The six planes of the multi-leaf at p, 8 ints each (traverse.h: the 8-bit planes q[6][8]).
  static SLIM_INLINE void multileaf_planes(const uint8_t* p, simd::vint8* q) {
    if constexpr (kLossless) {
      for (uint32_t i = 0; i < 6; ++i) q[i] = simd::vint8::load_u8(p + 8 * i);
    } else {
      const uint8_t* lows = cluster::plane_lows(p + sizeof(cluster::LatticeBoxes8));
#if defined(SLIM_SIMD_AVX2)
      __m256i v[6];
      cluster::lattice_planes_avx2(p, lows, v);
      for (uint32_t i = 0; i < 6; ++i) q[i] = v[i];
#else
      uint8_t b[6][8];
      cluster::lattice_planes(p, lows, b);
      for (uint32_t i = 0; i < 6; ++i) q[i] = simd::vint8::load_u8(b[i]);
#endif
    }
  }
  // The 8-bit planes of the multi-leaf at p (the structure check's).
  static void multileaf_planes8(const uint8_t* p, uint8_t (*q)[8]) {
    if constexpr (kLossless)
      std::memcpy(q, p, 48);
    else
      cluster::lattice_planes(p, cluster::plane_lows(p + sizeof(cluster::LatticeBoxes8)), q);
  }

  // ---- traversal side ----
  // What the children of one multi-leaf share, per visit (traverse.h, HasMultiLeafView): the
  // thread's decode cache, and the cluster's view (header, layout, anchors, ranges), looked up at
  // the first child the cache does not hold, not at all when it holds every child the ray enters.
  // The view is the cache's entry, made there if it holds another cluster's (or this one's for
  // another child count): nothing else writes the cache's views until the visit ends.
  struct MultiLeafView {
    const uint8_t* data;
    uint32_t children;
    cluster::DecodeCache* cache;
    mutable const cluster::View* v = nullptr;
    SLIM_INLINE const cluster::View& get(const Context& ctx) const {
      if (!v) {
        cluster::DecodeCache::ViewEntry& e = cache->view_slot(data);
        if (e.data != data || e.tag != ctx.cache_tag || e.children != children) {
          cluster::view_into<kLossless>(e.v, ctx.lattice, data, children);
          e.data = data;
          e.tag = ctx.cache_tag;
          e.children = children;
        }
        v = &e.v;
      }
      return *v;
    }
  };
  static SLIM_INLINE MultiLeafView multileaf_view(const Context&, const uint8_t* data,
                                                  uint32_t children) {
    return {data, children, &cluster::decode_cache()};
  }
  // The cache entries of the children the ray enters (`mask`), loaded while the first is tested.
  static SLIM_INLINE void prefetch_in_view(const MultiLeafView& view, uint32_t mask) {
    view.cache->prefetch(view.data, mask);
  }
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_in_view(const Context& ctx, const MultiLeafView& view, int i,
                                            TravRay& ray, HitRecord& hit, Stats& st) {
    using namespace simd;
    cluster::DecodeCache::Entry& en = view.cache->slot(view.data, i);
    if (en.bits != view.data || en.child != i || en.tag != ctx.cache_tag) {
      const cluster::View& v = view.get(ctx);
      cluster::decode_child<kLossless>(ctx.lattice, v, i, en.d);
      en.ids = cluster::child_ids(v, uint32_t(en.d.first));
      en.bits = view.data;
      en.child = i;
      en.tag = ctx.cache_tag;
    }
    const cluster::Decoded8& d = en.d;
    st.prims(d.n);
    const WatertightRay& r = ray.wt;
    // The coordinates loaded in the ray's axis order (no copies to pick them from).
    auto vert = [&](int k) {
      return to_ray_space_permuted(r, vfloat8::load(d.v[k][r.kx]), vfloat8::load(d.v[k][r.ky]),
                                   vfloat8::load(d.v[k][r.kz]));
    };
    RayVertex<vfloat8> A = vert(0), B = vert(1), C = vert(2);
    vfloat8 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, 0xFF, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    alignas(32) float tt[8];
    t.store(tt);
    int l = pop_lowest(m);
    while (m) {
      int j = pop_lowest(m);
      if (tt[j] < tt[l]) l = j;
    }
    uint32_t geom, prim;
    cluster::decode_ids(cluster::stream_of(view.data), en.ids, uint32_t(l), geom, prim);
    auto p = [&](int k) { return Vec3f(d.v[k][0][l], d.v[k][1][l], d.v[k][2][l]); };
    detail::record_hit(tt[l], u[l], v[l], p(0), p(1), p(2), geom, prim, ray, hit);
    return true;
  }
  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_in_multileaf(const Context& ctx, const uint8_t* data,
                                                 uint32_t children, int i, TravRay& ray,
                                                 HitRecord& hit, Stats& st) {
    return intersect_in_view<kAny>(ctx, multileaf_view(ctx, data, children), i, ray, hit, st);
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context& ctx, const uint8_t* block, TravRay& ray,
                                    HitRecord& hit, Stats& st) {
    uint64_t off;
    std::memcpy(&off, block, 8);
    return intersect_in_multileaf<kAny>(ctx, ctx.side + off, 1, 0, ray, hit, st);
  }

  template <class F>
  static void visit_in_multileaf(const Context& ctx, const uint8_t* data, uint32_t children, int i,
                                 F&& fn) {
    cluster::Decoded8 d;
    const cluster::View v = cluster::view<kLossless>(ctx.lattice, data, children);
    cluster::decode_child<kLossless>(ctx.lattice, v, i, d);
    for (int l = 0; l < d.n; ++l) {
      Vec3f c[3];
      Box3f box;
      for (int k = 0; k < 3; ++k) {
        c[k] = Vec3f(d.v[k][0][l], d.v[k][1][l], d.v[k][2][l]);
        box.extend(c[k]);
      }
      uint32_t geom, prim;
      cluster::decode_ids(v, uint32_t(d.first + l), geom, prim);
      fn(box, triangle_key(c[0], c[1], c[2], geom, prim));
    }
  }
  template <class F>
  static void visit(const Context& ctx, const uint8_t* block, F&& fn) {
    uint64_t off;
    std::memcpy(&off, block, 8);
    visit_in_multileaf(ctx, ctx.side + off, 1, 0, fn);
  }
};

}  // namespace slim
