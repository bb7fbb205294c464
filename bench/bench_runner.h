// `slimrt bench`: every configuration beside Embree, on the same rays, in one process
// (the benchmark specification: docs/benchmark.md).
//
// Per scene: load it, frame it with the benchmark camera (frame_box, 1024 x 1024), then
// A. prepare every configuration (embree-tri first, the reference), one after the other:
//   1. build it once (untimed: the rounds time the builds);
//   2. validate before any ray is timed: the workload-1 hits are compared with embree-tri's
//      (hit_agreement); a lossless configuration under 99.9% is an ERROR;
//   3. count (slimrt only, untimed): box and primitive tests per ray over all workload-1 rays, and
//      over the paths of every 16th pixel of workload 2 (x and y multiples of 4);
//   4. lossy configurations: PSNR of a 256 x 256 normals render against bvh8-tri4v's;
//   5. keep the built scene for the rounds while the scenes kept so far fit in the memory budget
//      (Scene::memory() / EmbreeScene::memory() totals, greedily in configuration order); a scene
//      that does not fit is freed and rebuilt for its rays in every round;
// B. time `repeat` interleaved rounds (bench_stats.h), each in an order rotating by one
//    configuration per round: first every kept configuration is built once (timed; the new scene
//    replaces the kept one; one not kept is built, timed, at its turn), then every configuration
//    runs workload 1 (one primary ray per pixel centre) then workload 2 (slim::trace_path, up to 8
//    bounces, every ray counted). Build time and MRays/s are medians over the rounds; a ratio is
//    the median of the per-round ratios to embree-tri's MRays/s in the same round; all come with
//    their min..max range.
// Every timed run traces all of its rays and folds each hit distance into a checksum that is kept,
// so that nothing is optimised away; the ray counts and checksums of the rounds must agree.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "bench_configs.h"
#include "bench_report.h"
#include "slimrt/analysis.h"

namespace slim::bench {

// Passes of one timing at most (BenchOptions::min_seconds).
constexpr int kMaxTimingPasses = 1000;

struct BenchOptions {
  std::vector<std::string> scenes;   // mesh files or terrain:N, torus:N, canyon:N
  std::vector<std::string> configs;  // empty: default_configs(); embree-tri is always measured
  int threads = 0;                   // 0 = all cores
  // The build options besides the format (BuildOptions::from_config(name, tuning)); its threads
  // are replaced by `threads`.
  BuildOptions tuning;
  int repeat = 3;  // timed rounds (each builds and traces every config)
  // Each timing repeats its workload until this many seconds have passed (at least one pass,
  // at most kMaxTimingPasses) and keeps the fastest pass: a pass of a small scene takes tens of
  // milliseconds, and on a shared machine other processes only ever slow a pass down.
  double min_seconds = 0.25;
  int width = 1024, height = 1024;  // docs/benchmark.md camera
  int max_bounces = 8;              // workload 2
  int psnr_size = 256;              // lossy configurations: normals render, size x size
  uint64_t memory_budget = 0;       // bytes of built scenes kept between rounds; 0: half of
                                    // MemAvailable (default_memory_budget())
  bool progress = true;             // progress lines on stderr
};

// docs/benchmark.md hit agreement: both miss, or both hit with t equal within 1e-5 relative.
bool hits_agree(const Hit& a, const Hit& b);

// Runs the whole benchmark. Throws slim::Error for a scene that cannot be loaded or an unknown
// configuration name; a configuration that fails to build is reported in its row.
BenchReport run_bench(const BenchOptions& opt);

// "model name" of /proc/cpuinfo, or "unknown".
std::string cpu_model_name();

}  // namespace slim::bench
