// The builder of each leaf format and its empty scene for Scene::open (the registry's "builder"
// column, src/api/registry.cpp).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "api/scene_impl.h"

namespace slim {

using SceneBuilder = std::unique_ptr<Scene::Impl> (*)(const MeshList& meshes,
                                                      const BuildOptions& opt);
using EmptySceneMaker = std::unique_ptr<Scene::Impl> (*)(const BuildOptions& opt);
struct SceneFormat {
  SceneBuilder build;     // builds the scene from meshes
  EmptySceneMaker empty;  // the scene's type, unfilled, for Scene::open (api/scene_file.cpp)
};
// The functions of a leaf format; throws slim::Error for a value outside the enum.
SceneFormat format_of(Leaf leaf);

// Whether `value` is the Leaf of some registry row (a scene file's stored leaf is checked with it).
bool is_registered_leaf(uint8_t value);

// BuildOptions::lattice_box as a lossy format's builder takes it: the empty box when none is
// given (the format then derives its scene-wide quantities from the meshes), else the box, after
// checking that it contains every finite vertex of the meshes (slim::Error naming the mesh, the
// vertex and the box otherwise: a vertex outside would fall off the lattice).
Box3f lattice_box_of(const MeshList& meshes, const BuildOptions& opt);

}  // namespace slim
