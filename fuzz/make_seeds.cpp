// Writes the seed corpus of the fuzz targets: make_seeds OUT_DIR creates OUT_DIR/<target>/ for
// obj, ply, gltf, glb and xz, each holding the seed files of its format (fuzz/seed_files.h), and
// for scene, pairing, quantized_mesh and lossy_subgrid, each holding inputs in the target's own
// byte layout (fuzz/binary_seeds.h), for scene_file small scene files (Scene::save), and for
// cluster blocks made by the library's cluster encoder (cluster_seeds() below: they follow the
// block layout of src/prim/cluster.h whatever it becomes).
// Run by ./fuzz.sh before fuzzing; nothing it writes is kept in git.
#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "binary_seeds.h"
#include "prim/cluster.h"
#include "seed_files.h"
#include "slimrt/scene.h"

namespace {

// Seeds of fuzz_cluster (fuzz/fuzz_cluster.cpp): a mode byte (bits 0-2: children - 1, bit 3:
// lossless, bits 4-7: the round trip's triangles / 4), then one cluster block as
// cluster::encode() writes it for a real mesh (without the read slack), so that the first check
// of the target starts from blocks check() accepts and the decoders read in full. Triangles of
// the mesh's fan triangulation, in mesh order (neighbours, as the build's clusters hold), cut into
// children of the given sizes.
struct ClusterSeed {
  std::string name;
  std::string bytes;
};

std::vector<ClusterSeed> cluster_seeds() {
  using namespace slim;
  std::vector<ClusterSeed> out;
  struct Mesh {
    const char* name;
    PolyMesh mesh;
  };
  const Mesh meshes[] = {{"sphere1", make_sphere(1, 0.01f, 5)},  // 80 triangles, jittered
                         {"terrain4", make_terrain(4, 1)},       // 16 quads: 32 triangles
                         {"torus8", make_torus(8, 1)}};          // 32 quads: 64 triangles
  // Children sizes: one triangle; one full child; an uneven cut; 8 full children (64 triangles).
  const std::vector<std::vector<uint32_t>> cuts = {
      {1}, {8}, {5, 8, 2}, {3, 7, 1, 8, 6}, {8, 8, 8, 8, 8, 8, 8, 8}};
  for (const Mesh& m : meshes) {
    std::vector<uint32_t> tris, prim;
    uint64_t c = 0;
    for (uint32_t f = 0; f < m.mesh.face_sizes.size(); ++f) {
      const uint32_t n = m.mesh.face_sizes[f];
      for (uint32_t k = 1; k + 1 < n; ++k) {
        tris.insert(tris.end(), {m.mesh.face_indices[c], m.mesh.face_indices[c + k],
                                 m.mesh.face_indices[c + k + 1]});
        prim.push_back(f);
      }
      c += n;
    }
    const uint32_t ntris = uint32_t(prim.size());
    const std::vector<uint32_t> geom(ntris, 0);
    for (bool lossless : {false, true}) {
      const cluster::Quantized q = cluster::quantize(
          m.mesh.positions.data(), m.mesh.positions.size(), tris.data(), ntris, 1e-5, lossless);
      ClusterSource src;
      src.vertices = q.decoded.data();
      src.codes = q.codes.data();
      src.tris = tris.data();
      src.geom_ids = geom.data();
      src.prim_ids = prim.data();
      src.lossless = lossless;
      // The default lattice's 24-bit anchors: the target's first check reads lossy blocks so.
      src.lattice = ClusterLattice{};
      for (const std::vector<uint32_t>& cut : cuts) {
        uint32_t total = 0;
        for (uint32_t n : cut) total += n;
        if (total > ntris) continue;
        std::vector<uint32_t> order(total);
        for (uint32_t t = 0; t < total; ++t) order[t] = t;
        const uint32_t* prims[8];
        uint32_t counts[8];
        uint32_t pos = 0;
        for (size_t k = 0; k < cut.size(); ++k) {
          prims[k] = &order[pos];
          counts[k] = cut[k];
          pos += cut[k];
        }
        const std::vector<uint8_t> block =
            cluster::encode(src, prims, counts, int(cut.size()), false);
        // The target's first check starts from blocks check() accepts (with the read slack the
        // target adds past the block).
        std::vector<uint8_t> padded = block;
        padded.resize(block.size() + kClusterReadSlack, 0);
        std::string why;
        if (!cluster::check(padded.data(), block.size(), uint32_t(cut.size()), src.lattice,
                            lossless, &why))
          throw Error(std::string("make_seeds: cluster::check() refuses the encoder's block of ") +
                      m.name + ": " + why);
        const uint8_t mode = uint8_t((cut.size() - 1) | (lossless ? 8 : 0) |
                                     (std::min<uint32_t>(15, total / 4) << 4));
        std::string bytes(1, char(mode));
        bytes.append(reinterpret_cast<const char*>(block.data()), block.size());
        out.push_back({std::string(m.name) + (lossless ? "_lossless_" : "_lossy_") +
                           std::to_string(cut.size()) + "x" + std::to_string(total),
                       bytes});
      }
    }
  }
  return out;
}

}  // namespace

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
  // scene_file: a small scene file (Scene::save) of every configuration of the registry (the
  // structure check covers them all), over a terrain and a few loose triangles (the grid formats'
  // leftover triangles).
  {
    std::vector<slim::PolyMesh> meshes{slim::make_terrain(3, 1)};
    slim::PolyMesh soup = slim::make_sphere(1, 0.05f, 1);
    soup.face_sizes.resize(4);
    soup.face_indices.resize(12);
    meshes.push_back(soup);
    for (const std::string& config : slim::all_config_names()) {
      const fs::path p = out / "scene_file" / (config + ".slim");
      fs::create_directories(p.parent_path());
      slim::Scene::build(meshes, slim::BuildOptions::from_config(config)).save(p.string());
      ++n;
    }
  }
  // Scenes joined from chunk scenes (Scene::build_chunked): the join.* sections and c<i>.
  // prefixes, over chunks of a few formats.
  for (const char* config : {"bvh8-tri4v", "lossy-grid-shared", "costa-PFV", "cluster"}) {
    slim::ChunkedBuildOptions chunking;
    chunking.max_chunk_triangles = 8;
    const fs::path p = out / "scene_file" / ("joined-" + std::string(config) + ".slim");
    slim::Scene::build_chunked("terrain:4", slim::BuildOptions::from_config(config), chunking)
        .save(p.string());
    ++n;
  }
  for (const ClusterSeed& seed : cluster_seeds()) put("cluster", seed.name, seed.bytes);
  std::printf("make_seeds: %d files in %s\n", n, out.c_str());
  return 0;
}
