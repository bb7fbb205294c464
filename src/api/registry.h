// The builder of each leaf format (the registry's "builder" column, src/api/registry.cpp).
#pragma once

#include <memory>
#include <vector>

#include "api/scene_impl.h"

namespace slim {

using SceneBuilder = std::unique_ptr<Scene::Impl> (*)(const std::vector<const PolyMesh*>& meshes,
                                                      const BuildOptions& opt);
// The builder of a leaf format; throws slim::Error for a value outside the enum.
SceneBuilder builder_of(Leaf leaf);

}  // namespace slim
