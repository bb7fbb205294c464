// slimrt build SCENE --config CONFIG -o FILE.slim [--memory-budget MIB] [build options: --threads
// N, ...]
//              [--chunk-triangles N] [--chunked] [--spill-dir D]: builds a scene and writes it as a
// scene file (Scene::save), which info and render then take in place of SCENE. An input whose
// in-memory build would exceed the budget is built chunk by chunk (Scene::build_chunked).
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <optional>

#include <unistd.h>

#include "build_flags.h"
#include "commands.h"
#include "discarded.h"
#include "mesh/chunk_sources.h"
#include "mesh/procedural.h"
#include "progress.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"
#include "slimrt/scene.h"

namespace slim::cli {

bool is_scene_file(const std::string& name) {
  return name.size() > 5 && name.compare(name.size() - 5, 5, ".slim") == 0;
}

Scene open_scene_file(const std::string& name, double* seconds) {
  const auto t0 = std::chrono::steady_clock::now();
  Scene s = Scene::open(name);
  if (seconds)
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

namespace {

// Triangles of an input, to choose between the in-memory and the chunked build: exact for
// procedural scenes, else from the file size at 16 bytes per triangle (a binary PLY triangle
// takes about 19 with its share of the vertices, text more; an .xz file is taken as 4x smaller).
uint64_t estimated_triangles(const std::string& name) {
  if (detail::is_subdivision(name)) return 0;  // only chunked, its size known once loaded
  if (is_procedural(name)) {
    const detail::ProceduralGrid grid(detail::parse_procedural(name, detail::kMaxProceduralN));
    return 2 * uint64_t(grid.cells_x) * uint64_t(grid.cells_y);
  }
  std::error_code ec;
  const uint64_t bytes = std::filesystem::file_size(name, ec);
  if (ec) return 0;  // the load reports the file's problem
  const bool xz = name.size() > 3 && name.compare(name.size() - 3, 3, ".xz") == 0;
  return bytes / 16 * (xz ? 4 : 1);
}

// Saves the scene and prints one line: the figures of `slimrt info`, the file's size; load_s < 0
// for a chunked build (its reading is part of the build).
int save_and_report(const std::string& scene_name, const Scene& scene, const std::string& output,
                    double load_s) {
  const auto t0 = std::chrono::steady_clock::now();
  scene.save(output);
  const double save_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const MemoryStats m = scene.memory();
  char load[64] = "";
  if (load_s >= 0) std::snprintf(load, sizeof load, "load %.3f s | ", load_s);
  std::string chunks;
  if (const std::optional<double> n = stat_detail(scene, "chunks"))
    chunks = std::to_string(uint64_t(*n)) + " chunks, ";
  // A device or a named pipe (slimrt/output.h writes them in place) has no size to report.
  std::error_code ec;
  const uint64_t bytes = std::filesystem::file_size(output, ec);
  const std::string file_size = ec ? std::string("not a regular file") : format_bytes(bytes);
  std::printf(
      "%s: %s, %s%llu triangles%s | %sbuild %.3f s | save %.3f s | scene %s (%.2f B/triangle) | "
      "file %s, %s\n",
      scene_name.c_str(), scene.options().config_name().c_str(), chunks.c_str(),
      (unsigned long long)m.triangles, discarded_note(scene).c_str(), load,
      scene.stats().build_seconds, save_s, format_bytes(m.total()).c_str(), m.bytes_per_triangle(),
      output.c_str(), file_size.c_str());
  return 0;
}

}  // namespace

int cmd_build(int argc, char** argv) {
  CLI::App app{"slimrt build: build a scene and write it as a scene file (.slim)"};
  std::string scene_name, config = "bvh8-tri4v", output;
  BuildOptions tuning;
  bool quiet = false;
  app.add_option("scene", scene_name, "mesh file or procedural scene")->required();
  app.add_option("--config,--accel", config, "the configuration (see the README)")
      ->capture_default_str();
  app.add_option("-o,--output", output, "the scene file to write (FILE.slim)")->required();
  add_build_options(app, tuning);
  app.add_flag("-q,--quiet", quiet, "no build progress on the terminal");
  ChunkedBuildOptions chunking;
  uint64_t budget_mib = 0;
  bool chunked = false;
  app.add_option("--memory-budget", budget_mib,
                 "MiB the build may hold besides the scene (default: a quarter of the RAM); an "
                 "input whose in-memory build would need more is built chunk by chunk")
      ->check(CLI::Range(uint64_t(16), uint64_t(1) << 30));
  app.add_option("--chunk-triangles", chunking.max_chunk_triangles,
                 "build chunk by chunk, at most this many triangles per chunk (default: from the "
                 "budget)")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 32));
  app.add_option(
      "--spill-dir", chunking.spill_dir,
      "chunked builds: directory for the temporary chunk files (default $TMPDIR or /tmp)");
  app.add_flag("--chunked", chunked, "build chunk by chunk even if the input fits the budget");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (!is_scene_file(output)) throw Error("-o " + output + ": expected a FILE.slim name");
  if (is_scene_file(scene_name)) throw Error(scene_name + ": already a scene file");
  BuildOptions opt = build_options(config, tuning);  // throws on an unknown name
  check_output_path(output);
  chunking.memory_budget = budget_mib << 20;
  if (!chunking.spill_dir.empty() && !std::filesystem::is_directory(chunking.spill_dir))
    throw Error("--spill-dir " + chunking.spill_dir + ": not a directory");
  using clock = std::chrono::steady_clock;
  // Chunked when asked, or when the in-memory build would need more than the budget.
  const uint64_t estimate = estimated_triangles(scene_name);
  const uint64_t budget = chunking.memory_budget ? chunking.memory_budget : default_memory_budget();
  if (chunked || chunking.max_chunk_triangles > 0 || detail::is_subdivision(scene_name) ||
      estimate > budget / kChunkBuildBytesPerTriangle) {
    Scene scene;
    {
      BuildMeter meter(!quiet && isatty(fileno(stderr)) != 0, config, estimate);
      opt.progress = meter.callback();
      scene = out_of_memory_context("building " + scene_name + " as " + config, [&] {
        return Scene::build_chunked(scene_name, opt, chunking);
      });
    }
    return save_and_report(scene_name, scene, output, -1.0);
  }
  auto t0 = clock::now();
  PolyMesh mesh = out_of_memory_context("loading " + scene_name, [&] { return load(scene_name); });
  const double load_s = std::chrono::duration<double>(clock::now() - t0).count();
  Scene scene;
  {
    // Phase, percentage and rate on a terminal (tools/progress.h), as render shows them.
    BuildMeter meter(!quiet && isatty(fileno(stderr)) != 0, config, mesh.fan_triangle_count());
    opt.progress = meter.callback();
    scene = out_of_memory_context("building " + scene_name + " as " + config,
                                  [&] { return Scene::build(mesh, opt); });
  }
  mesh = PolyMesh();
  return save_and_report(scene_name, scene, output, load_s);
}

}  // namespace slim::cli
