// placeholder until the grids section lands
#include "commands.h"
#include "slimrt/error.h"

namespace slim::cli {
void info_grids(const PolyMesh&, bool, nlohmann::json&) { throw Error("info --grids: not implemented yet"); }
}  // namespace slim::cli
