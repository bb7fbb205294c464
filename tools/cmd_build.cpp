// slimrt build SCENE --config CONFIG -o FILE.slim [--threads N]: builds a scene and writes it as a
// scene file (Scene::save), which info, render, bench and verify then take in place of SCENE.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>

#include <unistd.h>

#include "commands.h"
#include "progress.h"
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

int cmd_build(int argc, char** argv) {
  CLI::App app{"slimrt build: build a scene and write it as a scene file (.slim)"};
  std::string scene_name, config = "bvh8-tri4v", output;
  int threads = 0;
  bool quiet = false;
  app.add_option("scene", scene_name, "mesh file or procedural scene")->required();
  app.add_option("--config,--accel", config, "the configuration (see the README)")
      ->capture_default_str();
  app.add_option("-o,--output", output, "the scene file to write (FILE.slim)")->required();
  app.add_option("--threads", threads, "build threads, 0 = all cores")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  app.add_flag("-q,--quiet", quiet, "no build progress on the terminal");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (!is_scene_file(output)) throw Error("-o " + output + ": expected a FILE.slim name");
  if (is_scene_file(scene_name)) throw Error(scene_name + ": already a scene file");
  BuildOptions opt = BuildOptions::from_config(config);  // throws on an unknown name
  opt.threads = threads;
  check_output_path(output);
  using clock = std::chrono::steady_clock;
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
  t0 = clock::now();
  scene.save(output);
  const double save_s = std::chrono::duration<double>(clock::now() - t0).count();
  const MemoryStats m = scene.memory();
  std::printf(
      "%s: %s, %llu triangles | load %.3f s | build %.3f s | save %.3f s | scene %s "
      "(%.2f B/triangle) | file %s, %s\n",
      scene_name.c_str(), opt.config_name().c_str(), (unsigned long long)m.triangles, load_s,
      scene.stats().build_seconds, save_s, format_bytes(m.total()).c_str(), m.bytes_per_triangle(),
      output.c_str(), format_bytes(std::filesystem::file_size(output)).c_str());
  return 0;
}

}  // namespace slim::cli
