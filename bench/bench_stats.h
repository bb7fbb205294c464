// The round structure of `slimrt bench` and the statistics of its per-round figures.
//
// The configurations of a scene are timed in interleaved rounds: each round runs every measured
// configuration once, in an order that rotates from round to round, so that a drift of the
// (shared) machine is spread over every configuration instead of landing on the one that happens
// to be timed during it. A figure is the median of its per-round values, reported with their
// min..max range.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace slim::bench {

// A range wider than this fraction of the median on either side is flagged (noisy()).
constexpr double kNoisyFraction = 0.10;

// The median of the per-round values and their range.
struct Spread {
  double median = 0, lo = 0, hi = 0;
  // lo or hi lies further than kNoisyFraction * median from the median.
  bool noisy() const;
};

// Median of v (mean of the two middle values for an even count); 0 for an empty v.
double median(std::vector<double> v);
// Median and min..max of v; v must not be empty.
Spread spread_of(const std::vector<double>& v);

// The order in which round `round` (0-based) runs n configurations: index i of the round runs
// configuration (i + round) % n. Every configuration appears once per round, and each one opens
// a round in turn.
std::vector<size_t> round_order(size_t n, int round);

// Which built scenes stay in memory between rounds: greedily in the given order (the reference,
// embree-tri, first), a scene is kept while the kept total stays within budget_bytes; the others
// are rebuilt in each round.
std::vector<bool> keep_between_rounds(const std::vector<uint64_t>& bytes, uint64_t budget_bytes);

// Half of MemAvailable in /proc/meminfo, or 4 GiB where it cannot be read.
uint64_t default_memory_budget();

}  // namespace slim::bench
