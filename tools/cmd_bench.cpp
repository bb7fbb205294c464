// `slimrt bench SCENE... [--config NAME...] [--repeat K] [--min-time S] [--memory-budget MB]
//                [--json FILE] [--plot FILE] [--strict] [build options: --threads N, --collapse
//                ..., build_flags.h]`
// Every configuration beside Embree 3 on the same rays in this process (docs/benchmark.md);
// the work is done by bench/bench_runner, the output by bench/bench_{markdown,json,plot}. Prints
// the markdown table on stdout, progress and ERROR lines on stderr. Exit code 0, or 1 with --strict
// when an ERROR was reported (a lossless configuration under 99.9% hit agreement, a build failure,
// a non-deterministic run).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <string>
#include <vector>

#include "bench_configs.h"
#include "bench_json.h"
#include "bench_markdown.h"
#include "bench_plot.h"
#include "bench_runner.h"
#include "build_flags.h"
#include "commands.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"

namespace slim::cli {

int cmd_bench(int argc, char** argv) {
  CLI::App app{"Benchmark every configuration beside Embree on the same rays (docs/benchmark.md).",
               "slimrt bench"};
  bench::BenchOptions opt;
  std::string json_path, plot_path;
  bool strict = false;
  app.add_option(
         "scenes", opt.scenes,
         "mesh files (.obj .ply .gltf .glb, optionally .xz) or terrain:N, torus:N, canyon:N")
      ->required();
  app.add_option("--config", opt.configs,
                 "configurations (registry names or Embree anchors, repeatable or "
                 "comma-separated); default: "
                 "every Embree anchor and every slimrt configuration; embree-tri always runs")
      ->delimiter(',');
  add_build_options(app, opt.tuning);  // --threads: builds and rays
  app.add_option("--repeat", opt.repeat,
                 "interleaved timed rounds (each builds, then traces every configuration once; "
                 "medians and ranges over the rounds)")
      ->check(CLI::Range(1, 1000))
      ->capture_default_str();
  app.add_option("--min-time", opt.min_seconds,
                 "seconds each timing repeats its workload for at least (the fastest pass counts; "
                 "0 = one pass)")
      ->check(CLI::Range(0.0, 60.0))
      ->capture_default_str();
  double budget_mb = 0;
  app.add_option("--memory-budget", budget_mb,
                 "MB of built scenes kept between rounds (the others are rebuilt in each round); "
                 "0 = half of MemAvailable")
      ->check(CLI::Range(0.0, 1e9))
      ->capture_default_str();
  app.add_option("--json", json_path, "write the figures as JSON (docs/benchmark.md schema)");
  app.add_option("--plot", plot_path,
                 "draw bytes/triangle vs diffuse MRays/s into a PNG with gnuplot");
  app.add_flag("--strict", strict, "exit with 1 if any ERROR was reported");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  for (const std::string& sc : opt.scenes)
    if (is_scene_file(sc))
      throw Error(sc +
                  ": bench builds every configuration and Embree from the input mesh, which "
                  "a scene file does not hold; give the mesh, or time the file with `slimrt "
                  "render " +
                  sc + "` (MRays/s)");
  for (const std::string& c : opt.configs) bench::check_config_name(c);  // before any work
  opt.threads = opt.tuning.threads;
  // A tuning a configuration cannot take: an error now, not in the middle of the run.
  for (const std::string& c : opt.configs.empty() ? bench::default_configs() : opt.configs)
    if (find_config(c)) build_options(c, opt.tuning);
  opt.memory_budget = uint64_t(budget_mb * 1e6);
  if (!json_path.empty()) check_output_path(json_path);
  if (!plot_path.empty()) check_output_path(plot_path);

  const bench::BenchReport report = bench::run_bench(opt);
  std::fputs(bench::report_markdown(report).c_str(), stdout);
  std::fflush(stdout);

  if (!json_path.empty()) bench::write_json(report, json_path);
  if (!plot_path.empty()) {
    std::string why;
    if (!bench::write_plot(report, plot_path, &why))
      std::fprintf(stderr, "slimrt bench: warning: no plot written to %s: %s\n", plot_path.c_str(),
                   why.c_str());
  }
  if (!report.errors.empty())
    std::fprintf(stderr, "slimrt bench: %zu ERROR(s), see above\n", report.errors.size());
  return strict && !report.errors.empty() ? 1 : 0;
}

}  // namespace slim::cli
