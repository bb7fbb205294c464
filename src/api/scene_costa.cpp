// placeholder until the costa formats land
#include "api/scene_impl.h"

namespace slim {
std::unique_ptr<Scene::Impl> build_costa_scene(const std::vector<const PolyMesh*>&, const BuildOptions& opt) {
  throw Error(opt.config_name() + ": not implemented yet");
}
}  // namespace slim
