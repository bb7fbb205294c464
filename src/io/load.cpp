// slim::load(): picks the reader by file extension (.obj .ply .gltf .glb, each optionally .xz) or
// makes a procedural scene ("terrain:N", "torus:N", "canyon:N"). Every result passes check_mesh().
#include <algorithm>
#include <filesystem>
#include <new>
#include <stdexcept>

#include "io/gltf.h"
#include "io/obj.h"
#include "io/ply.h"
#include "io/xz.h"
#include "mesh/procedural.h"
#include "slimrt/mesh.h"

namespace slim {
namespace {

// Largest procedural N: terrain:16384 is 268M quads (about 9 GB as a PolyMesh).
constexpr int kMaxProceduralN = 16384;

const char* const kAccepted =
    "expected .obj, .ply, .gltf or .glb, optionally followed by .xz, or a procedural scene "
    "terrain:N, torus:N or canyon:N";

PolyMesh make_procedural(const std::string& spec) {
  const detail::ProceduralSpec p = detail::parse_procedural(spec, kMaxProceduralN);
  PolyMesh mesh = p.kind == "terrain" ? make_terrain(p.n)
                  : p.kind == "torus" ? make_torus(p.n)
                                      : make_canyon(p.n);
  if (mesh.name.empty()) mesh.name = spec;
  return mesh;
}

std::string lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

PolyMesh load_file(const std::string& path) {
  std::string stem = path;
  if (detail::has_xz_suffix(stem)) stem.resize(stem.size() - 3);
  const std::string file = std::filesystem::path(stem).filename().string();
  const size_t dot = file.rfind('.');
  const std::string ext = dot == std::string::npos ? "" : lower(file.substr(dot));
  if (ext != ".obj" && ext != ".ply" && ext != ".gltf" && ext != ".glb") {
    std::string what = path + ": ";
    if (ext.empty())
      what += "no file extension";
    else
      what.append("unknown extension '").append(ext).append("'");
    throw Error(what.append("; ").append(kAccepted));
  }

  const detail::FileBytes bytes = detail::read_file(path);
  const std::string_view data = bytes.view();
  if (ext == ".obj") return detail::read_obj(path, data);
  if (ext == ".ply") return detail::read_ply(path, data);
  std::filesystem::path base_dir = std::filesystem::path(path).parent_path();
  if (base_dir.empty()) base_dir = std::filesystem::path(".");
  return detail::read_gltf(path, data, ext == ".glb", base_dir.string());
}

}  // namespace

PolyMesh load(const std::string& path_or_scene) {
  PolyMesh mesh;
  try {
    if (is_procedural(path_or_scene)) {
      mesh = make_procedural(path_or_scene);
    } else {
      mesh = load_file(path_or_scene);
      mesh.name = path_or_scene;
    }
  } catch (const std::bad_alloc&) {
    throw Error(path_or_scene + ": out of memory while loading");
  } catch (const std::length_error&) {
    throw Error(path_or_scene + ": mesh too large to hold in memory");
  }
  check_mesh(mesh);
  return mesh;
}

}  // namespace slim
