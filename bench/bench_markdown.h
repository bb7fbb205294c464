// The Markdown table of `slimrt bench` (stdout).
#pragma once

#include <optional>
#include <string>

#include "bench_report.h"

namespace slim::bench {

// The markdown table with a short legend above it. A ratio cell is "median (min-max)" over the
// rounds, followed by "!" when the range is wider than +-10% of the median.
std::string report_markdown(const BenchReport& report);
// One ratio (or build time) cell: "1.02 (0.97-1.08)", "1.02 (0.85-1.08) !", or "—" when absent;
// `format` prints each number.
std::string ratio_cell(const std::optional<Spread>& s, const char* format = "%.2f");

}  // namespace slim::bench
