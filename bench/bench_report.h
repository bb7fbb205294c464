// The figures of one `slimrt bench` run, as the runner fills them and the writers (bench_json,
// bench_markdown, bench_plot) read them.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "bench_stats.h"

namespace slim::bench {

// docs/benchmark.md: a lossless format agreeing with Embree on fewer workload-1 hits is an ERROR.
constexpr double kLosslessAgreement = 0.999;

// Lossy formats' error figures (docs/benchmark.md; Table 3 of Benthin et al., "Ray Tracing Lossy
// Compressed Grid Primitives"); null where they do not apply.
struct ErrorFigures {
  std::optional<double> rms, diag_avg_pct, diag_max_pct, psnr_db;
  bool psnr_identical = false;  // PSNR is +inf (images identical); psnr_db stays null in JSON
};

// One scene x configuration. Fields that do not apply stay empty (null in JSON).
struct BenchRow {
  std::string scene, config;
  uint64_t triangles = 0;  // fan triangles of the input (the per-triangle divisor)
  std::string reason;      // not measured: "does not apply: ...", "not implemented ...", error
  bool build_failed = false;
  bool lossy = false;
  bool embree = false;
  bool kept = true;  // the built scene stayed in memory between rounds (else rebuilt per round)
  // Build time: median over the rounds with its range (each round builds every configuration once,
  // in the round's order, before its rays are timed); build_mprims_s from the median.
  std::optional<Spread> build_s;
  std::optional<double> build_mprims_s;
  std::vector<double> seconds_build;  // per round, in round order
  std::optional<uint64_t> bytes_geometry, bytes_bvh, bytes_other, bytes_total;
  std::optional<double> bytes_per_triangle;
  // Medians over the rounds with their ranges; a ratio is the median of the per-round ratios to
  // embree-tri timed in the same round.
  std::optional<Spread> mrays_primary, mrays_diffuse, ratio_primary, ratio_diffuse;
  // Seconds of one pass of the workload, per round in round order: the fastest of the round's
  // passes_* passes (BenchOptions::min_seconds).
  std::vector<double> seconds_primary, seconds_diffuse;
  std::vector<int> passes_primary, passes_diffuse;
  // Process CPU seconds of the same runs (every thread, idle workers' spinning included): less
  // sensitive than wall time to other processes taking the cores.
  std::vector<double> cpu_seconds_primary, cpu_seconds_diffuse;
  std::optional<double> box_tests_per_ray, prim_tests_per_ray;        // workload 1 (JSON)
  std::optional<double> box_tests_per_ray_w2, prim_tests_per_ray_w2;  // workload 2 sample
  // Primitive records tested (a triangle pair counts once: TraversalCounters::prim_records).
  std::optional<double> prim_records_per_ray, prim_records_per_ray_w2;
  std::optional<double> hit_agreement;  // as docs/benchmark.md defines it
  std::optional<double> same_face;      // of the rays both hit: fraction naming the same face
  // Agreement with embree-tri on the input's fan triangles (equals hit_agreement except for the
  // formats validated on their own decoded geometry: grids, lossy grids, costa).
  std::optional<double> agreement_embree_tri;
  ErrorFigures error;
  uint64_t rays_primary = 0, rays_diffuse = 0;  // per timed run
  double checksum_primary = 0, checksum_diffuse = 0;

  bool measured() const { return reason.empty(); }
};

struct MachineInfo {
  std::string cpu;
  int threads = 0;
  std::string isa;
};

struct BenchReport {
  MachineInfo machine;
  int repeat = 0;          // rounds
  double min_seconds = 0;  // each timing repeats its workload at least this long
  int width = 0, height = 0, max_bounces = 0;
  uint64_t memory_budget = 0;  // bytes of built scenes kept between rounds (bench_stats.h)
  std::vector<BenchRow> rows;
  std::vector<std::string> errors;  // each also printed to stderr as "ERROR: ..."
};

}  // namespace slim::bench
