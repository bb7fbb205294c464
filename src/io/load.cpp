// Mesh loading entry point: placeholder until implemented.
#include "slimrt/mesh.h"

namespace slim {
PolyMesh load(const std::string& path) { throw Error(path + ": loading not implemented yet"); }
}  // namespace slim
