// The JSON writer of `slimrt bench`: see bench_json.h.
#include "bench_json.h"

#include <cmath>
#include <optional>
#include <type_traits>

#include "slimrt/output.h"

namespace slim::bench {

namespace {

template <class T>
nlohmann::json opt_json(const std::optional<T>& v) {
  if (!v || (std::is_floating_point_v<T> && !std::isfinite(double(*v)))) return nullptr;
  return *v;
}

nlohmann::json finite_or_null(double v) {
  if (!std::isfinite(v)) return nullptr;
  return v;
}

// "<name>": median, "<name>_range": [lo, hi], "<name>_noisy": bool; all null when absent.
void spread_json(nlohmann::json& j, const std::string& name, const std::optional<Spread>& s) {
  if (!s) {
    j[name] = nullptr;
    j[name + "_range"] = nullptr;
    j[name + "_noisy"] = nullptr;
    return;
  }
  j[name] = finite_or_null(s->median);
  j[name + "_range"] = {finite_or_null(s->lo), finite_or_null(s->hi)};
  j[name + "_noisy"] = s->noisy();
}

}  // namespace

nlohmann::json report_json(const BenchReport& report) {
  nlohmann::json out;
  out["machine"] = {{"cpu", report.machine.cpu},
                    {"threads", report.machine.threads},
                    {"isa", report.machine.isa}};
  out["rounds"] = report.repeat;
  out["min_seconds_per_timing"] = report.min_seconds;
  out["memory_budget_bytes"] = report.memory_budget;
  nlohmann::json results = nlohmann::json::array();
  for (const BenchRow& r : report.rows) {
    nlohmann::json j;
    j["scene"] = r.scene;
    j["config"] = r.config;
    j["triangles"] = r.triangles;
    spread_json(j, "build_s", r.build_s);
    j["bytes_geometry"] = opt_json(r.bytes_geometry);
    j["bytes_bvh"] = opt_json(r.bytes_bvh);
    j["bytes_other"] = opt_json(r.bytes_other);
    j["bytes_total"] = opt_json(r.bytes_total);
    j["bytes_per_triangle"] = opt_json(r.bytes_per_triangle);
    spread_json(j, "mrays_primary", r.mrays_primary);
    spread_json(j, "mrays_diffuse", r.mrays_diffuse);
    spread_json(j, "ratio_primary", r.ratio_primary);
    spread_json(j, "ratio_diffuse", r.ratio_diffuse);
    j["box_tests_per_ray"] = opt_json(r.box_tests_per_ray);
    j["prim_tests_per_ray"] = opt_json(r.prim_tests_per_ray);
    // Primitive records (a pair counts once), and the counts of the workload-2 sample (the paths of
    // every 16th pixel): docs/benchmark.md, "Counters".
    j["prim_records_per_ray"] = opt_json(r.prim_records_per_ray);
    j["box_tests_per_ray_w2s"] = opt_json(r.box_tests_per_ray_w2);
    j["prim_tests_per_ray_w2s"] = opt_json(r.prim_tests_per_ray_w2);
    j["prim_records_per_ray_w2s"] = opt_json(r.prim_records_per_ray_w2);
    j["hit_agreement"] = opt_json(r.hit_agreement);
    j["hit_agreement_embree_tri"] = opt_json(r.agreement_embree_tri);
    j["error"] = {{"rms", opt_json(r.error.rms)},
                  {"diag_avg_pct", opt_json(r.error.diag_avg_pct)},
                  {"diag_max_pct", opt_json(r.error.diag_max_pct)},
                  {"psnr_db", opt_json(r.error.psnr_db)}};
    // The raw rounds and the run's identity: rays traced and the checksum of their hit distances
    // (the same in every round, and for every build of the same code).
    j["seconds_build_rounds"] = r.seconds_build;
    j["seconds_primary_rounds"] = r.seconds_primary;
    j["seconds_diffuse_rounds"] = r.seconds_diffuse;
    j["cpu_seconds_primary_rounds"] = r.cpu_seconds_primary;
    j["cpu_seconds_diffuse_rounds"] = r.cpu_seconds_diffuse;
    j["passes_primary_rounds"] = r.passes_primary;
    j["passes_diffuse_rounds"] = r.passes_diffuse;
    if (r.measured()) {
      j["kept_between_rounds"] = r.kept;
      j["rays_primary"] = r.rays_primary;
      j["rays_diffuse"] = r.rays_diffuse;
      j["checksum_primary"] = finite_or_null(r.checksum_primary);
      j["checksum_diffuse"] = finite_or_null(r.checksum_diffuse);
    } else {
      j["reason"] = r.reason;
    }
    results.push_back(std::move(j));
  }
  out["results"] = std::move(results);
  return out;
}

void write_json(const BenchReport& report, const std::string& path) {
  write_file_atomically(path, report_json(report).dump(1) + "\n");
}

}  // namespace slim::bench
