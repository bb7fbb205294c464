// Rounds and per-round statistics of `slimrt bench`: see bench_stats.h.
#include "bench_stats.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <string>

namespace slim::bench {

bool Spread::noisy() const {
  const double tol = kNoisyFraction * std::fabs(median);
  return lo < median - tol || hi > median + tol;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0.0 : (n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

Spread spread_of(const std::vector<double>& v) {
  Spread s;
  if (v.empty()) return s;
  s.median = median(v);
  const auto [lo, hi] = std::minmax_element(v.begin(), v.end());
  s.lo = *lo;
  s.hi = *hi;
  return s;
}

std::vector<size_t> round_order(size_t n, int round) {
  std::vector<size_t> order(n);
  const size_t shift = n ? size_t(round < 0 ? 0 : round) % n : 0;
  for (size_t i = 0; i < n; ++i) order[i] = (i + shift) % n;
  return order;
}

std::vector<bool> keep_between_rounds(const std::vector<uint64_t>& bytes, uint64_t budget_bytes) {
  std::vector<bool> keep(bytes.size(), false);
  uint64_t kept = 0;
  for (size_t i = 0; i < bytes.size(); ++i) {
    if (bytes[i] > budget_bytes - kept) continue;  // kept <= budget_bytes always holds
    kept += bytes[i];
    keep[i] = true;
  }
  return keep;
}

uint64_t default_memory_budget() {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("MemAvailable:", 0) != 0) continue;
    std::istringstream s(line.substr(13));
    uint64_t kib = 0;
    if (s >> kib && kib > 0) return kib * 1024 / 2;
  }
  return uint64_t(4) << 30;
}

}  // namespace slim::bench
