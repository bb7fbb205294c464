// `slimrt bench`: every configuration beside Embree, on the same rays, in one process
// (BENCHMARK.md is the specification; issue 3 parts 1-4).
//
// Per scene: load it, frame it with the benchmark camera (frame_box, 1024 x 1024), then for every
// configuration (embree-tri first, the reference):
//   1. build it `repeat` times (median build time; the last build is kept);
//   2. validate before timing: the workload-1 hits are compared with embree-tri's
//      (hit_agreement); a lossless configuration under 99.9% is an ERROR;
//   3. count (slimrt only, untimed): box and primitive tests per ray over all workload-1 rays, and
//      over the paths of every 16th pixel of workload 2 (x and y multiples of 4);
//   4. lossy configurations: PSNR of a 256 x 256 normals render against bvh8-tri4v's;
//   5. time `repeat` runs of workload 1 (one primary ray per pixel centre) and workload 2
//      (slim::trace_path, up to 8 bounces, every ray counted), medians.
// Every timed run traces all of its rays and folds each hit distance into a checksum that is kept,
// so that nothing is optimised away; the ray counts and checksums of the repeats must agree.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "slimrt/scene.h"

namespace slim::bench {

struct BenchOptions {
  std::vector<std::string> scenes;   // mesh files or terrain:N, torus:N, canyon:N
  std::vector<std::string> configs;  // empty: default_configs(); embree-tri is always measured
  int threads = 0;                   // 0 = all cores
  int repeat = 3;                    // timed runs (and builds) per configuration; medians
  int width = 1024, height = 1024;   // BENCHMARK.md camera
  int max_bounces = 8;               // workload 2
  int psnr_size = 256;               // lossy configurations: normals render, size x size
  bool progress = true;              // one line per configuration on stderr
};

// Lossy formats' error figures (BENCHMARK.md, paper Table 3); null where they do not apply.
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
  std::optional<double> build_s, build_mprims_s;
  std::optional<uint64_t> bytes_geometry, bytes_bvh, bytes_other, bytes_total;
  std::optional<double> bytes_per_triangle;
  std::optional<double> mrays_primary, mrays_diffuse, ratio_primary, ratio_diffuse;
  std::optional<double> box_tests_per_ray, prim_tests_per_ray;        // workload 1 (JSON)
  std::optional<double> box_tests_per_ray_w2, prim_tests_per_ray_w2;  // workload 2 sample
  // Primitive records tested (a triangle pair counts once: TraversalCounters::prim_records).
  std::optional<double> prim_records_per_ray, prim_records_per_ray_w2;
  std::optional<double> hit_agreement;  // BENCHMARK.md definition
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
  int repeat = 0, width = 0, height = 0, max_bounces = 0;
  std::vector<BenchRow> rows;
  std::vector<std::string> errors;  // each also printed to stderr as "ERROR: ..."
};

// Every Embree anchor, then every slimrt configuration (slim::all_config_names()).
std::vector<std::string> default_configs();
// lossy-grid*, and costa-* with the V (vertex quantization) option.
bool is_lossy_config(const std::string& name);
// Throws slim::Error naming the configuration if it is neither an Embree anchor nor a slimrt name.
void check_config_name(const std::string& name);

// BENCHMARK.md hit agreement: both miss, or both hit with t equal within 1e-5 relative.
bool hits_agree(const Hit& a, const Hit& b);

// Runs the whole benchmark. Throws slim::Error for a scene that cannot be loaded or an unknown
// configuration name; a configuration that fails to build is reported in its row.
BenchReport run_bench(const BenchOptions& opt);

// The JSON object of BENCHMARK.md ("machine", "results"); rows that were not measured carry their
// figures as null and a "reason".
nlohmann::json report_json(const BenchReport& report);
// The markdown table (with a short legend above it).
std::string report_markdown(const BenchReport& report);
// Draws bytes/triangle (x, log) against diffuse MRays/s (y), one labelled point per
// configuration, one panel per scene, into a PNG with gnuplot. Returns false with the reason if
// gnuplot is missing or fails.
bool write_plot(const BenchReport& report, const std::string& png_path, std::string* why);

// "model name" of /proc/cpuinfo, or "unknown".
std::string cpu_model_name();

}  // namespace slim::bench
