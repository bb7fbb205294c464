// The index-key pairing order of A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing"
// (Imagination Technologies), applied in the two ways the library does not use, for
// tests/test_pairing.cpp and fuzz/fuzz_pairing.cpp: they must give the pairs of the library's
// TwinSort (pair_by_edge_heuristic) and of the std::stable_sort reference
// (tests/pairing_reference.h).
#pragma once

#include "mesh/pairing.h"

namespace slim::test {

enum class EdgeOrder {
  FullTable,  // LSD radix sort of the whole packed-key half-edge table, then the linear scan
  TwinSort,   // the library's: pair_by_edge_heuristic(in, false)
  Local,      // twins by the library's counting sort, then the greedy order applied locally
};

// The paper's pairing alone with index keys (no weld, pre-scan or augmenting pass), in `order`.
PairingResult pair_in_order(const PairingInput& in, EdgeOrder order);

}  // namespace slim::test
