// slimrt info SCENE [--json] [--accel CONFIG] [--pairs [--repeat K]] [--costa] [--grids]
//                   [--clusters [--cluster-error E]]
#include <CLI/CLI.hpp>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "commands.h"
#include "slimrt/analysis.h"

namespace slim::cli {

namespace {

nlohmann::json box_json(const Box3f& b) {
  if (b.empty()) return nullptr;
  return {{"min", {b.lo.x, b.lo.y, b.lo.z}}, {"max", {b.hi.x, b.hi.y, b.hi.z}}};
}

}  // namespace

int cmd_info(int argc, char** argv) {
  CLI::App app{"slimrt info: statistics of a scene (a mesh file or terrain:N/torus:N/canyon:N)"};
  std::string scene_name, accel;
  bool json = false, pairs = false, costa = false, grids = false, clusters = false;
  double cluster_error = BuildOptions().cluster_error;
  app.add_option("scene", scene_name, "mesh file or procedural scene")->required();
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
  app.add_option("--cluster-error", cluster_error,
                 "--clusters: the lossy error bound, a fraction of the box diagonal")
      ->needs("--clusters");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
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
    BuildOptions opt = BuildOptions::from_config(accel);
    Scene scene = Scene::build(mesh, opt);
    MemoryStats m = scene.memory();
    const SceneStats& st = scene.stats();
    nlohmann::json a;
    a["config"] = opt.config_name();
    a["build_s"] = st.build_seconds;
    a["primitives"] = st.primitives;
    a["skipped_faces"] = st.skipped_faces;
    a["bytes_geometry"] = m.geometry_bytes;
    a["bytes_bvh"] = m.bvh_bytes;
    a["bytes_other"] = m.other_bytes;
    a["bytes_total"] = m.total();
    a["bytes_per_triangle"] = m.bytes_per_triangle();
    for (const auto& [k, v] : st.details) a["details"][k] = v;
    std::string why;
    a["valid"] = scene.validate(&why);
    if (!why.empty()) a["validate_error"] = why;
    out["accel"] = a;
    if (!json) {
      std::printf("\n%s: built in %.3f s over %llu primitives\n", opt.config_name().c_str(),
                  st.build_seconds, (unsigned long long)st.primitives);
      std::printf(
          "  memory: geometry %llu B, bvh %llu B, other %llu B, total %llu B = %.2f B/triangle\n",
          (unsigned long long)m.geometry_bytes, (unsigned long long)m.bvh_bytes,
          (unsigned long long)m.other_bytes, (unsigned long long)m.total(), m.bytes_per_triangle());
      for (const auto& [k, v] : st.details) std::printf("  %-24s %.6g\n", k.c_str(), v);
      std::printf("  validate: %s%s\n", why.empty() ? "ok" : "FAILED: ", why.c_str());
    }
    if (!why.empty()) {
      if (json) std::printf("%s\n", out.dump(2).c_str());
      return 1;
    }
  }
  if (pairs) info_pairs(mesh, json, repeat, out);
  if (costa) info_costa(mesh, json, out);
  if (grids) info_grids(mesh, json, out);
  if (clusters) {
    for (const char* config : {"cluster", "cluster-lossless"}) {
      BuildOptions opt = BuildOptions::from_config(config);
      opt.cluster_error = cluster_error;
      Scene scene = Scene::build(mesh, opt);
      const MemoryStats m = scene.memory();
      nlohmann::json c;
      c["triangles"] = m.triangles;
      c["build_s"] = scene.stats().build_seconds;
      c["bytes_per_triangle"] = m.bytes_per_triangle();
      for (const auto& [k, v] : scene.stats().details) c[k] = v;
      if (!json) {
        std::printf("\n%s: %.2f B/triangle (geometry %.2f, BVH %.2f)\n", config,
                    m.bytes_per_triangle(), double(m.geometry_bytes) / double(m.triangles),
                    double(m.bvh_bytes) / double(m.triangles));
        for (const auto& [k, v] : scene.stats().details)
          std::printf("  %-28s %.6g\n", k.c_str(), v);
      }
      out["clusters"][config] = c;
    }
  }
  if (json) std::printf("%s\n", out.dump(2).c_str());
  return 0;
}

}  // namespace slim::cli
