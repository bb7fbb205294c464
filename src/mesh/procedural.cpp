// Procedural scenes (BENCHMARK.md): placeholder until implemented.
#include "slimrt/mesh.h"

namespace slim {
bool is_procedural(const std::string& name) {
  auto c = name.find(':');
  if (c == std::string::npos) return false;
  std::string k = name.substr(0, c);
  return k == "terrain" || k == "torus" || k == "canyon";
}
PolyMesh make_terrain(int, uint32_t) { throw Error("terrain: not implemented yet"); }
PolyMesh make_torus(int, uint32_t) { throw Error("torus: not implemented yet"); }
PolyMesh make_canyon(int, uint32_t) { throw Error("canyon: not implemented yet"); }
}  // namespace slim
