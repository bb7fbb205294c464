// The JSON writer of `slimrt bench` (the schema of docs/benchmark.md, with the rounds' ranges).
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "bench_report.h"

namespace slim::bench {

// The JSON object of docs/benchmark.md ("machine", "results"); rows that were not measured carry
// their figures as null and a "reason". Each MRays/s figure and ratio is the median over the
// rounds, with "<name>_range": [min, max] and "<name>_noisy": the range is wider than +-10% of the
// median.
nlohmann::json report_json(const BenchReport& report);
// Writes report_json(report) to path, complete or not at all (write_file_atomically); throws
// slim::Error if the file cannot be written.
void write_json(const BenchReport& report, const std::string& path);

}  // namespace slim::bench
