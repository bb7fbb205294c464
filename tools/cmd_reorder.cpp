// slimrt reorder SCENE OUT.obj [--config cluster|cluster-lossless] [--order FILE] [build options]:
// writes SCENE's mesh with its faces in the order the cluster configuration stores them
// (cluster_face_order, slimrt/clusters.h), as an OBJ, and optionally that order (one input face
// number a line: line i, counting from 0, holds the input face that became face i), so that data
// kept per face can follow. The cluster scenes of the written mesh are smaller: their primIDs (the
// faces) come in the clusters' order.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <string>

#include "build_flags.h"
#include "commands.h"
#include "slimrt/clusters.h"
#include "slimrt/mesh.h"
#include "slimrt/output.h"

namespace slim::cli {

int cmd_reorder(int argc, char** argv) {
  CLI::App app{"slimrt reorder: write a mesh with its faces in the clusters' order"};
  std::string scene_name, output, order_file, config = "cluster";
  BuildOptions tuning;
  app.add_option("scene", scene_name, "mesh file or procedural scene")->required();
  app.add_option("output", output, "the mesh to write (FILE.obj)")->required();
  app.add_option("--config,--accel", config, "cluster or cluster-lossless")->capture_default_str();
  app.add_option("--order", order_file,
                 "also write the order: line i (from 0) holds the input face that became face i");
  add_build_options(app, tuning);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  const std::string suffix = output.size() < 4 ? "" : output.substr(output.size() - 4);
  if (suffix != ".obj" && suffix != ".OBJ") throw Error(output + ": expected a FILE.obj name");
  if (is_scene_file(scene_name))
    throw Error(scene_name + ": a scene file; reorder takes the mesh it was built from");
  const BuildOptions opt = build_options(config, tuning);  // throws on an unknown name
  if (opt.leaf != Leaf::Clusters && opt.leaf != Leaf::LosslessClusters)
    throw Error("--config " + config + ": reorder takes cluster or cluster-lossless");
  // The input is never written over (nor by the order).
  // The same file, also for names of files not yet written (x.obj and ./x.obj).
  auto same_file = [](const std::string& a, const std::string& b) {
    std::error_code ec;
    if (std::filesystem::equivalent(a, b, ec) && !ec) return true;
    const auto pa = std::filesystem::weakly_canonical(a, ec);
    if (ec) return false;
    const auto pb = std::filesystem::weakly_canonical(b, ec);
    return !ec && pa == pb;
  };
  for (const std::string& out : {output, order_file})
    if (!out.empty() && same_file(scene_name, out))
      throw Error(out + ": is the input " + scene_name + "; write to another file");
  if (!order_file.empty() && same_file(output, order_file))
    throw Error("--order " + order_file + ": is the output mesh; write to another file");
  check_output_path(output);
  if (!order_file.empty()) check_output_path(order_file);
  const PolyMesh mesh =
      out_of_memory_context("loading " + scene_name, [&] { return load(scene_name); });
  const std::vector<uint32_t> order = out_of_memory_context(
      "building " + scene_name + " as " + config, [&] { return cluster_face_order(mesh, opt); });
  uint64_t moved = 0;
  for (size_t i = 0; i < order.size(); ++i) moved += order[i] != i;
  save_obj(reorder_faces(mesh, order), output);
  if (!order_file.empty()) {
    std::string text;
    text.reserve(8 * order.size());
    for (const uint32_t f : order) text += std::to_string(f) + '\n';
    write_file_atomically(order_file, text);
  }
  std::printf("%s: %zu faces, %llu moved; wrote %s%s%s\n", scene_name.c_str(), order.size(),
              static_cast<unsigned long long>(moved), output.c_str(),
              order_file.empty() ? "" : " and ", order_file.c_str());
  return 0;
}

}  // namespace slim::cli
