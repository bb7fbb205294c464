// slimrt CLI subcommands. Each returns the process exit code; errors are thrown as slim::Error
// and printed by main().
#pragma once

#include <new>
#include <nlohmann/json.hpp>
#include <string>

#include "slimrt/error.h"

#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim::cli {

int cmd_info(int argc, char** argv);
int cmd_render(int argc, char** argv);
int cmd_bench(int argc, char** argv);
int cmd_verify(int argc, char** argv);   // cmd_verify.cpp
int cmd_build(int argc, char** argv);    // cmd_build.cpp
int cmd_reorder(int argc, char** argv);  // cmd_reorder.cpp

// Scene files (cmd_build.cpp): a SCENE argument ending in .slim is a scene file (Scene::open),
// opened in `seconds`.
bool is_scene_file(const std::string& name);
Scene open_scene_file(const std::string& name, double* seconds = nullptr);

// Runs fn(); a std::bad_alloc becomes slim::Error "out of memory while <what>", so the user
// learns which step of which scene ran out (main() only knows the command).
template <class Fn>
auto out_of_memory_context(const std::string& what, Fn&& fn) -> decltype(fn()) {
  try {
    return fn();
  } catch (const std::bad_alloc&) {
    throw Error("out of memory while " + what);
  }
}

// `slimrt info` sections of the technique issues, each in its own file (info_*.cpp). Each
// prints a human-readable section to stdout, or fills `out` when json is true.
// info_pairs.cpp; repeat >= 2 also times repeat - 1 later calls of the pairing
void info_pairs(const PolyMesh& mesh, bool json, int repeat, nlohmann::json& out);
void info_costa(const PolyMesh& mesh, bool json, nlohmann::json& out);  // info_costa.cpp
void info_grids(const PolyMesh& mesh, bool json, nlohmann::json& out);  // info_grids.cpp

}  // namespace slim::cli
