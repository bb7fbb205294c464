// Writes the seed corpus of the fuzz targets: make_seeds OUT_DIR creates OUT_DIR/<target>/ for
// obj, ply, gltf, glb and xz, each holding the seed files of its format (fuzz/seed_files.h), and
// for scene, pairing, quantized_mesh and lossy_subgrid, each holding inputs in the target's own
// byte layout (fuzz/binary_seeds.h), and for scene_file small scene files (Scene::save).
// Run by ./fuzz.sh before fuzzing; nothing it writes is kept in git.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "binary_seeds.h"
#include "seed_files.h"
#include "slimrt/scene.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seeds OUT_DIR\n");
    return 2;
  }
  namespace fs = std::filesystem;
  const fs::path out = argv[1];
  int n = 0;
  for (const slim::seeds::SeedFile& f : slim::seeds::all_seeds()) {
    std::string name = f.name, target;
    const bool xz = name.size() > 3 && name.substr(name.size() - 3) == ".xz";
    const std::string stem = xz ? name.substr(0, name.size() - 3) : name;
    const std::string ext = stem.substr(stem.rfind('.') + 1);
    target = xz ? "xz" : ext;
    fs::create_directories(out / target);
    std::ofstream(out / target / name, std::ios::binary) << f.bytes;
    ++n;
    // The xz target also gets the plain files compressed, so that it reaches every reader.
    if (!xz) {
      fs::create_directories(out / "xz");
      std::ofstream(out / "xz" / (name + ".xz"), std::ios::binary)
          << slim::seeds::xz_compress(f.bytes);
      ++n;
    }
  }
  // Hostile seeds: nesting just past the JSON depth limit (1000) and far past it
  // within -max_len, indices beyond 2^32 and floats beyond float's range.
  auto put = [&](const std::string& target, const std::string& name, const std::string& bytes) {
    fs::create_directories(out / target);
    std::ofstream(out / target / name, std::ios::binary) << bytes;
    ++n;
  };
  for (int depth : {999, 1001, 7000}) {
    put("gltf", "deep_array_" + std::to_string(depth) + ".gltf",
        "{\"asset\":{\"version\":\"2.0\"},\"extras\":" + std::string(depth, '[') +
            std::string(depth, ']') + "}");
    std::string obj;
    for (int i = 0; i < depth; ++i) obj += "{\"a\":";
    put("gltf", "deep_object_" + std::to_string(depth) + ".gltf",
        "{\"asset\":{\"version\":\"2.0\"},\"extras\":" + obj + "0" + std::string(depth, '}') + "}");
  }
  const std::string tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  put("obj", "index_2p32.obj", tri + "f 4294967297 4294967298 4294967299\n");
  put("obj", "index_2p31.obj", tri + "f 2147483648 -2147483649 1\n");
  put("obj", "float_1e39.obj", "v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n");
  put("ply", "double_1e300.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
      "property double z\nelement face 1\nproperty list uint uint vertex_indices\nend_header\n"
      "0 0 0\n1e300 0 0\n0 1 0\n3 0 1 4294967295\n");
  for (const slim::seeds::BinarySeed& b : slim::seeds::binary_seeds())
    put(b.target, b.name, b.bytes);
  // scene_file: small scene files (Scene::save) of the configurations the structure check walks,
  // and of two it does not (their sections are still parsed and their header checked).
  for (const char* config : {"bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "clbvh-compact",
                             "bvh8-pairs", "lossy-grid-shared", "costa-PFV"}) {
    const fs::path p = out / "scene_file" / (std::string(config) + ".slim");
    fs::create_directories(p.parent_path());
    slim::Scene::build(slim::make_terrain(3, 1), slim::BuildOptions::from_config(config))
        .save(p.string());
    ++n;
  }
  // A scene joined from chunk scenes (Scene::build_chunked): the join.* sections and c<i>.
  // prefixes.
  {
    slim::ChunkedBuildOptions chunking;
    chunking.max_chunk_triangles = 8;
    const fs::path p = out / "scene_file" / "joined-bvh8-tri4v.slim";
    slim::Scene::build_chunked("terrain:4", slim::BuildOptions::from_config("bvh8-tri4v"), chunking)
        .save(p.string());
    ++n;
  }
  std::printf("make_seeds: %d files in %s\n", n, out.c_str());
  return 0;
}
