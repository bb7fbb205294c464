// placeholder until the pairs section lands
#include "commands.h"
#include "slimrt/error.h"

namespace slim::cli {
void info_pairs(const PolyMesh&, bool, nlohmann::json&) { throw Error("info --pairs: not implemented yet"); }
}  // namespace slim::cli
