// Triangle pairing: A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing", Imagination
// Technologies.
//
// pair_triangles() pairs triangles on shared edges with the edge-box surface-area heuristic of the
// paper: a half-edge table (BBSA, smaller vertex, larger vertex, triangle), sorted descending by
// (BBSA, smaller vertex, larger vertex) with an LSD radix sort, then a greedy linear scan that
// pairs twins (equal keys, adjacent after the sort) whose triangles are both still unpaired. The
// "coordinate" key form of the paper (edge midpoint + BBSA, 24 bits each, 16 B per half-edge) is
// offered for meshes whose vertices are not welded, and weld_positions() merges bit-identical
// positions. window_pairs() is the paper's baseline (in-order window N = 2) and the pre-scan.
// Beyond the paper, an augmenting-path pass re-pairs around triangles the greedy scan stranded
// (PairingOptions::augment).
#pragma once

#include <cstdint>
#include <vector>

#include "core/large_array.h"
#include "slimrt/math.h"
#include "slimrt/pairing.h"

namespace slim {

// One pair: triangles a and b share the edge (a's corners ea, ea+1 mod 3) = (b's corners eb,
// eb+1 mod 3) in either direction; a < b.
struct TrianglePair {
  uint32_t a = 0, b = 0;
  uint8_t ea = 0, eb = 0;
};

struct PairingResult {
  LargeVector<TrianglePair> pairs;  // ascending by a
  LargeVector<uint32_t> unpaired;   // triangles in no pair, ascending
  PairingStats stats;               // pairing_stats() figures of this result
};

// Input triangles: 3 vertex indices each into `vertices`. `groups` (optional, one per triangle,
// e.g. the input mesh) keeps pairs inside a group. Triangles whose corners repeat a vertex index
// (or, with coordinate keys, a position) are never paired on the degenerate edge.
struct PairingInput {
  const Vec3f* vertices = nullptr;
  uint64_t vertex_count = 0;
  const uint32_t* tris = nullptr;
  uint64_t tri_count = 0;
  const uint32_t* groups = nullptr;
};

// Pairs the triangles (one thread). Deterministic: the same input gives the same pairs.
// Runs weld (opt.weld), the pre-scan, and unless it finds the input order good enough, the
// edge-heuristic pairing and (opt.augment) the augmenting-path pass. Throws slim::Error if 3 *
// tri_count >= 2^32.
PairingResult pair_triangles(const PairingInput& in, const PairingOptions& opt = {});

// The paper's pairing alone (no weld, pre-scan or augmenting pass), index or coordinate keys: the
// descending (BBSA, smaller vertex, larger vertex) order by TwinSort for index keys, the full
// table for coordinate keys (see pairing.cpp). tests/pairing_orders.h applies the same order two
// other ways, which give the same pairs.
PairingResult pair_by_edge_heuristic(const PairingInput& in, bool coordinate_keys);

// The paper's baseline: triangle i pairs with i+1 when both are unpaired and share an edge (two
// corners with equal vertex indices, or with coordinate keys, bit-identical positions).
// stats.pairing_s is its wall time.
PairingResult window_pairs(const PairingInput& in, bool by_position = false);

// Vertex remap that merges bit-identical positions (+0.0 and -0.0 stay apart): remap[v] is the
// first vertex with v's position. Returns the number of vertices merged away.
uint64_t weld_positions(const Vec3f* vertices, uint64_t vertex_count, std::vector<uint32_t>& remap);

// True if triangles a and b share the edge (a corner ea, ea+1) = (b corner eb, eb+1) (either
// direction) by vertex index, or by position when `by_position`; the edge must not be degenerate.
bool pair_shares_edge(const PairingInput& in, const TrianglePair& p, bool by_position);

}  // namespace slim
