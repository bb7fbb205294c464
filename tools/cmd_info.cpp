// slimrt info SCENE [--json] [--accel CONFIG] [--pairs [--repeat K]] [--costa] [--grids]
//                   [--clusters [--cluster-error E]]
//        slimrt info SCENE --chunks MAX_TRIANGLES [--spill [--spill-dir D] [--memory-budget MIB]]
//                   [--chunk-accel CONFIG] [--json]     (SCENE may also be subdiv:LEVELS:MESH)
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "build_flags.h"
#include "commands.h"
#include "io/face_stream.h"
#include "mesh/chunk_sources.h"
#include "mesh/chunks.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"

namespace slim::cli {

namespace {

nlohmann::json box_json(const Box3f& b) {
  if (b.empty()) return nullptr;
  return {{"min", {b.lo.x, b.lo.y, b.lo.z}}, {"max", {b.hi.x, b.hi.y, b.hi.z}}};
}

uint64_t peak_rss_bytes() {
  struct rusage u;
  getrusage(RUSAGE_SELF, &u);
  return uint64_t(u.ru_maxrss) * 1024;
}

// The figures of a built or opened scene: JSON (config, build time, memory, details, validate)
// and, unless `json`, the same as text. Returns the JSON; `valid` gets validate()'s answer.
nlohmann::json scene_report(const Scene& scene, bool json, bool& valid) {
  const MemoryStats m = scene.memory();
  const SceneStats& st = scene.stats();
  const std::string config = scene.options().config_name();
  std::string why;
  valid = scene.validate(&why);
  nlohmann::json a;
  a["config"] = config;
  a["build_s"] = st.build_seconds;
  a["primitives"] = st.primitives;
  a["skipped_faces"] = st.skipped_faces;
  a["bytes_geometry"] = m.geometry_bytes;
  a["bytes_bvh"] = m.bvh_bytes;
  a["bytes_other"] = m.other_bytes;
  a["bytes_total"] = m.total();
  a["bytes_per_triangle"] = m.bytes_per_triangle();
  for (const auto& [k, v] : stat_details(scene)) a["details"][k] = v;
  a["valid"] = valid;
  if (!why.empty()) a["validate_error"] = why;
  if (!json) {
    std::printf("\n%s: built in %.3f s over %llu primitives\n", config.c_str(), st.build_seconds,
                (unsigned long long)st.primitives);
    std::printf(
        "  memory: geometry %llu B, bvh %llu B, other %llu B, total %llu B = %.2f B/triangle\n",
        (unsigned long long)m.geometry_bytes, (unsigned long long)m.bvh_bytes,
        (unsigned long long)m.other_bytes, (unsigned long long)m.total(), m.bytes_per_triangle());
    for (const auto& [k, v] : stat_details(scene)) std::printf("  %-24s %.6g\n", k.c_str(), v);
    std::printf("  validate: %s%s\n", why.empty() ? "ok" : "FAILED: ", why.c_str());
  }
  return a;
}

// --chunks: the scene in spatial chunks of at most `max_triangles`, never loaded whole: a
// procedural scene (terrain:N, canyon:N, torus:N) in tiles and a subdivided mesh
// (subdiv:LEVELS:MESH) generated chunk by chunk (mesh/chunk_sources.h), anything else (or with
// `spill`) streamed and spilled to temporary files (mesh/chunks.h). Each chunk is then loaded,
// and built with `accel` if given, one at a time. Prints the chunks and the peak resident memory.

// The chunks of `src`, each loaded (and built with `accel` if given) one at a time; `out` already
// holds the source's own figures.
int list_chunks(const detail::ChunkSource& src, uint64_t max_triangles, const std::string& accel,
                const BuildOptions& tuning, bool json, nlohmann::json out) {
  uint64_t max_chunk_tris = 0, scene_bytes = 0;
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t i = 0; i < src.size(); ++i) {
    const detail::ChunkInfo& ci = src.info(i);
    max_chunk_tris = std::max(max_chunk_tris, ci.triangles);
    nlohmann::json c = {
        {"faces", ci.faces}, {"triangles", ci.triangles}, {"bounds", box_json(ci.bounds)}};
    detail::Chunk chunk = src.load(i);
    if (!accel.empty()) {
      const Scene scene = Scene::build(chunk.mesh, build_options(accel, tuning));
      c["bytes_scene"] = scene.memory().total();
      scene_bytes += scene.memory().total();
    }
    out["chunk"].push_back(c);
    if (!json && (i < 8 || i + 8 >= src.size()))
      std::printf("  chunk %5zu  %9llu triangles  [%g %g %g] - [%g %g %g]\n", i,
                  (unsigned long long)ci.triangles, ci.bounds.lo.x, ci.bounds.lo.y, ci.bounds.lo.z,
                  ci.bounds.hi.x, ci.bounds.hi.y, ci.bounds.hi.z);
    else if (!json && i == 8)
      std::printf("  ...\n");
  }
  const double load_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  out["load_s"] = load_s;
  out["peak_rss"] = peak_rss_bytes();
  if (!accel.empty()) out["bytes_chunk_scenes"] = scene_bytes;
  if (json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    if (!accel.empty())
      std::printf("chunk scenes     %s: %llu B in all\n", accel.c_str(),
                  (unsigned long long)scene_bytes);
    std::printf("largest chunk    %llu triangles (at most %llu asked)\n",
                (unsigned long long)max_chunk_tris, (unsigned long long)max_triangles);
    std::printf("read back        every chunk in %.2f s%s\n", load_s,
                accel.empty() ? "" : ", built included");
    std::printf("peak RSS         %llu B after reading back%s every chunk\n",
                (unsigned long long)peak_rss_bytes(), accel.empty() ? "" : " and building");
  }
  return 0;
}

// Chunks generated on demand (mesh/chunk_sources.h): procedural tiles or a subdivided mesh.
int info_generated_chunks(const detail::ChunkSource& src, const std::string& scene_name,
                          uint64_t max_triangles, double setup_s, const std::string& accel,
                          const BuildOptions& tuning, bool json) {
  nlohmann::json out;
  out["scene"] = scene_name;
  out["source"] = "generated";
  out["faces"] = src.faces();
  out["triangles"] = src.triangles();
  out["bounds"] = box_json(src.bounds());
  out["chunks"] = src.size();
  out["max_triangles"] = max_triangles;
  out["setup_s"] = setup_s;
  out["peak_rss_after_setup"] = peak_rss_bytes();
  if (!json) {
    std::printf("scene            %s (chunks generated on demand, nothing spilled)\n",
                scene_name.c_str());
    std::printf("faces            %llu, %llu fan triangles\n", (unsigned long long)src.faces(),
                (unsigned long long)src.triangles());
    std::printf("chunks           %zu of at most %llu triangles\n", src.size(),
                (unsigned long long)max_triangles);
    std::printf("set-up           %.2f s (chunk table and exact bounds)\n", setup_s);
    std::printf("peak RSS         %llu B after set-up\n", (unsigned long long)peak_rss_bytes());
  }
  return list_chunks(src, max_triangles, accel, tuning, json, std::move(out));
}

int info_chunks(const std::string& scene_name, uint64_t max_triangles, const std::string& dir,
                uint64_t budget_mib, const std::string& accel, const BuildOptions& tuning,
                bool json, bool spill) {
  if (!spill) {
    const auto t0 = std::chrono::steady_clock::now();
    auto generated = detail::open_generated_chunks(scene_name, max_triangles);
    const double setup_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (generated)
      return info_generated_chunks(*generated, scene_name, max_triangles, setup_s, accel, tuning,
                                   json);
  }
  detail::ChunkOptions opt;
  opt.max_triangles = max_triangles;
  opt.memory_budget = budget_mib << 20;
  opt.spill_dir = dir.empty() ? std::filesystem::temp_directory_path().string() : dir;
  auto stream = detail::open_face_stream(scene_name);
  detail::ChunkSet set(*stream, opt);
  const detail::ChunkingStats& st = set.stats();
  const uint64_t rss_partition = peak_rss_bytes();
  nlohmann::json out;
  out["scene"] = scene_name;
  out["source"] = "spilled";
  out["faces"] = st.faces;
  out["triangles"] = st.triangles;
  out["bounds"] = box_json(st.bounds);
  out["chunks"] = set.size();
  out["max_triangles"] = max_triangles;
  out["cells_used"] = st.cells_used;
  out["bytes_histogram"] = st.histogram_bytes;
  out["bytes_spill_buffers"] = st.buffer_bytes;
  out["bytes_stream"] = st.stream_bytes;
  out["bytes_spilled"] = st.spilled_bytes;
  out["pass_s"] = {st.seconds[0], st.seconds[1], st.seconds[2]};
  out["peak_rss_after_partition"] = rss_partition;
  if (!json) {
    std::printf("scene            %s (streamed)\n", scene_name.c_str());
    std::printf("faces            %llu, %llu fan triangles\n", (unsigned long long)st.faces,
                (unsigned long long)st.triangles);
    std::printf("chunks           %zu of at most %llu triangles (%llu Morton cells used)\n",
                set.size(), (unsigned long long)max_triangles, (unsigned long long)st.cells_used);
    std::printf("passes           bounds %.2f s, histogram %.2f s, spill %.2f s\n", st.seconds[0],
                st.seconds[1], st.seconds[2]);
    std::printf("memory           histogram %s, spill buffers %s, stream %s, spilled %s\n",
                format_bytes(st.histogram_bytes).c_str(), format_bytes(st.buffer_bytes).c_str(),
                format_bytes(st.stream_bytes).c_str(), format_bytes(st.spilled_bytes).c_str());
    std::printf("peak RSS         %llu B after partitioning\n", (unsigned long long)rss_partition);
  }
  return list_chunks(set, max_triangles, accel, tuning, json, std::move(out));
}

}  // namespace

int cmd_info(int argc, char** argv) {
  CLI::App app{"slimrt info: statistics of a scene (a mesh file or terrain:N/torus:N/canyon:N)"};
  std::string scene_name, accel;
  bool json = false, pairs = false, costa = false, grids = false, clusters = false;
  BuildOptions tuning;  // --accel, --chunk-accel, --clusters
  app.add_option("scene", scene_name, "mesh file, procedural scene or scene file (.slim)")
      ->required();
  app.add_flag("--json", json, "print one JSON object");
  app.add_option("--accel", accel, "build this configuration and print its statistics");
  app.add_flag("--pairs", pairs, "triangle pairing statistics (fast-triangle-pairing)");
  int repeat = 1;
  app.add_option("--repeat", repeat,
                 "--pairs: run the pairing K times; pairing_s is the first call, "
                 "pairing_later_s the median of the others")
      ->check(CLI::Range(1, 1000))
      ->needs("--pairs");
  app.add_flag("--costa", costa, "quantized n-gon mesh sizes (Costa et al.)");
  app.add_flag("--grids", grids, "grid conversion and lossy grid error statistics");
  // The compressed triangle clusters' figures.
  app.add_flag("--clusters", clusters, "compressed triangle clusters (cluster, cluster-lossless)");
  // Chunked, streamed input: the mesh is never loaded whole.
  uint64_t chunks = 0, budget_mib = 256;
  std::string spill_dir, chunk_accel;
  app.add_option("--chunks", chunks,
                 "split the scene into spatial chunks of at most this many triangles, never "
                 "loading it whole (a mesh file streamed and spilled, a procedural scene or "
                 "subdiv:LEVELS:MESH generated tile by tile); print them and the peak resident "
                 "memory")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 31));
  app.add_option("--spill-dir", spill_dir, "--chunks: directory for the temporary chunk files")
      ->needs("--chunks");
  app.add_option("--memory-budget", budget_mib, "--chunks: MiB of spill buffers (default 256)")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 30))
      ->needs("--chunks");
  app.add_option("--chunk-accel", chunk_accel, "--chunks: build every chunk with this config")
      ->needs("--chunks");
  bool spill = false;
  app.add_flag("--spill", spill,
               "--chunks: stream and spill a procedural scene too (by default its tiles are "
               "generated on demand)")
      ->needs("--chunks");
  add_build_options(app, tuning);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  if (chunks > 0)
    return info_chunks(scene_name, chunks, spill_dir, budget_mib, chunk_accel, tuning, json, spill);

  if (is_scene_file(scene_name)) {
    // A scene file: its figures (the input mesh is not in it, so no mesh statistics).
    if (pairs || costa || grids || clusters)
      throw Error(scene_name +
                  ": --pairs, --costa, --grids and --clusters need the input mesh, "
                  "which a scene file does not hold");
    double open_s = 0;
    const Scene scene = open_scene_file(scene_name, &open_s);
    if (!accel.empty() &&
        BuildOptions::from_config(accel).config_name() != scene.options().config_name())
      throw Error(scene_name + " holds a " + scene.options().config_name() + " scene, not " +
                  accel);
    const SceneStats& st = scene.stats();
    nlohmann::json out;
    out["scene"] = scene_name;
    out["open_s"] = open_s;
    out["triangles"] = st.triangles;
    out["faces"] = st.input_faces;
    out["bounds"] = box_json(scene.bounds());
    if (!json) {
      std::printf("scene file       %s (opened in %.3f s)\n", scene_name.c_str(), open_s);
      std::printf("faces            %llu (%llu fan triangles)\n",
                  (unsigned long long)st.input_faces, (unsigned long long)st.triangles);
    }
    bool valid = false;
    out["accel"] = scene_report(scene, json, valid);
    if (json) std::printf("%s\n", out.dump(2).c_str());
    return valid ? 0 : 1;
  }

  PolyMesh mesh = load(scene_name);
  MeshSummary s = summarize(mesh);
  nlohmann::json out;
  out["scene"] = scene_name;
  out["vertices"] = s.vertices;
  out["faces"] = s.faces;
  out["triangles"] = s.fan_triangles;
  out["triangle_faces"] = s.triangles;
  out["quads"] = s.quads;
  out["ngons"] = s.ngons;
  out["degenerate_faces"] = s.degenerate_faces;
  out["nonfinite_vertices"] = s.nonfinite_vertices;
  out["bounds"] = box_json(s.bounds);
  if (!json) {
    std::printf("scene            %s\n", scene_name.c_str());
    std::printf("vertices         %llu\n", (unsigned long long)s.vertices);
    std::printf("faces            %llu (%llu triangles, %llu quads, %llu n-gons)\n",
                (unsigned long long)s.faces, (unsigned long long)s.triangles,
                (unsigned long long)s.quads, (unsigned long long)s.ngons);
    std::printf("fan triangles    %llu\n", (unsigned long long)s.fan_triangles);
    std::printf("degenerate faces %llu\n", (unsigned long long)s.degenerate_faces);
    std::printf("non-finite verts %llu (faces using them are skipped at build)\n",
                (unsigned long long)s.nonfinite_vertices);
    if (!s.bounds.empty())
      std::printf("bounds           [%g %g %g] - [%g %g %g]\n", s.bounds.lo.x, s.bounds.lo.y,
                  s.bounds.lo.z, s.bounds.hi.x, s.bounds.hi.y, s.bounds.hi.z);
  }

  if (!accel.empty()) {
    BuildOptions opt = build_options(accel, tuning);
    Scene scene = Scene::build(mesh, opt);
    bool valid = false;
    out["accel"] = scene_report(scene, json, valid);
    if (!valid) {
      if (json) std::printf("%s\n", out.dump(2).c_str());
      return 1;
    }
  }
  if (pairs) info_pairs(mesh, json, repeat, out);
  if (costa) info_costa(mesh, json, out);
  if (grids) info_grids(mesh, json, out);
  if (clusters) {
    for (const char* config : {"cluster", "cluster-lossless"}) {
      BuildOptions opt = build_options(config, tuning);
      Scene scene = Scene::build(mesh, opt);
      const MemoryStats m = scene.memory();
      nlohmann::json c;
      c["triangles"] = m.triangles;
      c["build_s"] = scene.stats().build_seconds;
      c["bytes_per_triangle"] = m.bytes_per_triangle();
      for (const auto& [k, v] : stat_details(scene)) c[k] = v;
      if (!json) {
        std::printf("\n%s: %.2f B/triangle (geometry %.2f, BVH %.2f)\n", config,
                    m.bytes_per_triangle(), double(m.geometry_bytes) / double(m.triangles),
                    double(m.bvh_bytes) / double(m.triangles));
        for (const auto& [k, v] : stat_details(scene)) std::printf("  %-28s %.6g\n", k.c_str(), v);
      }
      out["clusters"][config] = c;
    }
  }
  if (json) std::printf("%s\n", out.dump(2).c_str());
  return 0;
}

}  // namespace slim::cli
