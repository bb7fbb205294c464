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
#include "slimrt/mesh.h"

namespace slim {
namespace {

// Largest procedural N: terrain:16384 is 268M quads (about 9 GB as a PolyMesh).
constexpr int kMaxProceduralN = 16384;

const char* const kAccepted =
    "expected .obj, .ply, .gltf or .glb, optionally followed by .xz, or a procedural scene "
    "terrain:N, torus:N or canyon:N";

PolyMesh make_procedural(const std::string& spec) {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon), digits = spec.substr(colon + 1);
  // Strict: decimal digits only, no sign, blanks or leading zeros.
  bool ok = !digits.empty() && digits.size() <= 6 && digits[0] != '0' &&
            std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; });
  const int n = ok ? std::stoi(digits) : 0;
  // A torus needs N even and N/2 >= 3 (make_torus): one range stated, the one that holds.
  if (kind == "torus" && (!ok || n > kMaxProceduralN || n < 6 || n % 2 != 0))
    throw Error(spec + ": expected torus:N with N an even integer from 6 to " +
                std::to_string(kMaxProceduralN));
  if (!ok || n > kMaxProceduralN)
    throw Error(spec + ": expected " + kind + ":N with N an integer from 1 to " +
                std::to_string(kMaxProceduralN));
  PolyMesh mesh = kind == "terrain" ? make_terrain(n)
                  : kind == "torus" ? make_torus(n)
                                    : make_canyon(n);
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
