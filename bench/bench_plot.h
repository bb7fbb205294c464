// The gnuplot plot of `slimrt bench --plot`.
#pragma once

#include <string>

#include "bench_report.h"

namespace slim::bench {

// Draws bytes/triangle (x, log) against diffuse MRays/s (y, the median over the rounds), one
// labelled point per configuration, one panel per scene, into a PNG with gnuplot. Returns false
// with the reason if gnuplot is missing or fails. The PNG is written through write_atomically
// (slimrt/output.h): complete or not at all.
bool write_plot(const BenchReport& report, const std::string& png_path, std::string* why);

}  // namespace slim::bench
