// Internals of the triangle pairing (mesh/pairing.cpp), shared with the edge orders that only
// the tests run (tests/pairing_orders.cpp: the index-key full table and the local order): the
// greedy scan state, the twins of the counting sort, the full-table record and its sort + scan.
// Not part of the library's interface; A. Aman, S. Fenney, "Fast Triangle Pairing for Ray
// Tracing", Imagination Technologies.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <utility>
#include <vector>

#include "core/large_array.h"
#include "mesh/pairing.h"
#include "slimrt/math.h"

namespace slim::pairing_detail {

constexpr uint32_t kNone = 0xffffffffu;

// kNone in every entry: a memset (0xff bytes), a sequential stream instead of the random writes
// of the entries that stay kNone.
inline void fill_none(uint32_t* p, size_t n) {
  if (n) std::memset(p, 0xff, n * sizeof(uint32_t));  // p is null for an empty array
}

SLIM_INLINE uint32_t float_bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

SLIM_INLINE bool same_bits(const Vec3f& a, const Vec3f& b) {
  return std::memcmp(&a, &b, sizeof(Vec3f)) == 0;
}

// Surface area of the edge's bounding box, halved (the factor 2 changes no order). Symmetric in
// (p, q) bit for bit, so twin half-edges get the same value. Axis-aligned edges give 0 and sort
// last (paper, "Halfedge table sorting"). An overflow to NaN counts as +inf.
SLIM_INLINE float edge_box_area(const Vec3f& p, const Vec3f& q) {
  Vec3f d = abs(q - p);
  float a = d.x * d.y + d.y * d.z + d.z * d.x;
  return a >= 0.0f ? a : kInf;
}

inline int bit_width(uint64_t x) { return x ? 64 - __builtin_clzll(x) : 0; }

SLIM_INLINE const Vec3f& corner(const PairingInput& in, uint32_t tri, int k) {
  return in.vertices[in.tris[3 * size_t(tri) + k]];
}
SLIM_INLINE int next3(int k) { return k == 2 ? 0 : k + 1; }

// Greedy scan state (paper, "Greedy pairing"). The scan reads one bit per triangle ("paired"; a
// bit set of T/8 bytes stays in cache where a 4 B-per-triangle array would not) and writes the
// accepted twins into mate[t] = the half-edge of t's partner on the shared edge (3 * partner +
// corner), kNone for unpaired triangles. twin[h] (only if asked for, for the augmenting pass of
// the full table) is the other half-edge of a manifold edge, kNone otherwise.
struct Greedy {
  const PairingInput& in;
  bool verify_positions;
  std::vector<uint64_t> used;
  LargeArray<uint32_t> mate;
  uint64_t pairs = 0;  // accepted so far
  LargeArray<uint32_t> twin;
  uint64_t nonmanifold = 0;

  Greedy(const PairingInput& i, bool verify, bool want_twins)
      : in(i), verify_positions(verify), used((i.tri_count + 63) / 64, 0) {
    mate = LargeArray<uint32_t>(i.tri_count);
    fill_none(mate.data(), mate.size());
    if (want_twins) {
      twin = LargeArray<uint32_t>(3 * i.tri_count);
      fill_none(twin.data(), twin.size());
    }
  }

  SLIM_INLINE bool is_used(uint32_t t) const { return (used[t >> 6] >> (t & 63)) & 1; }
  SLIM_INLINE void set_used(uint32_t t) { used[t >> 6] |= uint64_t(1) << (t & 63); }

  bool compatible(uint32_t ha, uint32_t hb) const {
    uint32_t ta = ha / 3, tb = hb / 3;
    if (ta == tb) return false;
    if (in.groups && in.groups[ta] != in.groups[tb]) return false;
    if (!verify_positions) return true;
    // Different edges may share a compressed key: accept real shared edges only.
    TrianglePair p{std::min(ta, tb), std::max(ta, tb), uint8_t((ta < tb ? ha : hb) % 3),
                   uint8_t((ta < tb ? hb : ha) % 3)};
    return pair_shares_edge(in, p, true);
  }

  SLIM_INLINE void set_twins(uint32_t ha, uint32_t hb) {
    if (!twin.empty()) {
      twin[ha] = hb;
      twin[hb] = ha;
    }
  }

  SLIM_INLINE void accept(uint32_t ha, uint32_t hb) {
    set_used(ha / 3);
    set_used(hb / 3);
    mate[ha / 3] = hb;
    mate[hb / 3] = ha;
    pairs++;
  }

  // Twins already known to be compatible.
  SLIM_INLINE void accept_if_free(uint32_t ha, uint32_t hb) {
    if (!is_used(ha / 3) && !is_used(hb / 3)) accept(ha, hb);
  }

  void two(uint32_t ha, uint32_t hb) {
    if (!compatible(ha, hb)) return;
    set_twins(ha, hb);
    accept_if_free(ha, hb);
  }

  // A run of k >= 3 equal keys (an edge of 3+ triangles, or a key collision): pair the first two
  // eligible, then the next two, ...
  void run(const uint32_t* he, size_t k) {
    nonmanifold++;
    for (size_t x = 0; x + 1 < k; ++x) {
      if (is_used(he[x] / 3)) continue;
      for (size_t y = x + 1; y < k; ++y) {
        if (is_used(he[y] / 3) || !compatible(he[x], he[y])) continue;
        accept_if_free(he[x], he[y]);
        break;
      }
    }
  }
};

// Full-table form: 16 B records with the packed key, sorted over all key bits.
struct HalfEdgeRec {
  uint64_t lo;  // key bits 0..63
  uint32_t hi;  // key bits 64..95
  uint32_t he;  // 3 * triangle + corner (the edge from that corner to the next)
};
static_assert(sizeof(HalfEdgeRec) == 16, "half-edge record is 16 bytes (paper: 16 B per entry)");

// Twins of the mesh: link[h] = the twin of h for manifold edges (two compatible half-edges),
// kNone otherwise; runs of 3+ equal keys (edges of 3+ triangles) as [count, half-edges
// ascending...] in `runs`, and for each half-edge of a run its run offset (run_of, sorted by
// half-edge). 4 B per half-edge: the edge box area is recomputed from the two corners where it is
// needed again (augment, local_scan), which is bit-identical (edge_box_area is symmetric and
// -ffp-contract=off).
struct Twins {
  LargeArray<uint32_t> link;
  // The counting sort's buckets (8 B per half-edge). With edge records asked for, the records
  // overwrite the buckets as they are read (slots[0, ne)), and slots[ne, 2 ne) is the radix
  // sort's second buffer.
  LargeArray<uint64_t> slots;
  std::vector<uint32_t> runs;
  std::vector<std::pair<uint32_t, uint32_t>> run_of;
  std::vector<uint64_t> in_run;  // bit per triangle: has a half-edge in a run

  uint32_t run_offset(uint32_t h) const {
    auto it = std::lower_bound(run_of.begin(), run_of.end(), std::make_pair(h, 0u));
    return it != run_of.end() && it->first == h ? it->second : kNone;
  }
};

// The input as the heuristic pairs it: throws slim::Error if 3 * tri_count >= 2^32; groups
// dropped when every triangle is in the same one (no group test per candidate pair).
PairingInput prepare(const PairingInput& in);

// Builds the twins (tw.link, tw.runs, tw.run_of, tw.in_run) by a counting sort of the half-edges
// on their smaller vertex; with `emit`, also the edge records of the TwinSort order (see
// pairing.cpp). Sets st.half_edges.
void find_twins(const PairingInput& in, Greedy& g, Twins& tw, bool emit, size_t* edge_count,
                uint32_t* top_hist, PairingStats& st);

// Stable LSD radix sort of the full table (n records, keys of key_bits bits, complemented so that
// ascending is the paper's descending order), then the greedy scan of its runs of equal keys.
// Sets st.sort_s and st.scan_s.
void sort_and_scan_table(HalfEdgeRec* table, size_t n, int key_bits, Greedy& g, PairingStats& st);

// Completes r from the greedy scan in g: heuristic_paired_fraction, the augmenting pass when `twin`
// (the manifold twin of each half-edge) is given, the pairs, unpaired triangles and counts.
void finish(const PairingInput& in, Greedy& g, const uint32_t* twin, PairingResult& r);

}  // namespace slim::pairing_detail
