// placeholder until the costa section lands
#include "commands.h"
#include "slimrt/error.h"

namespace slim::cli {
void info_costa(const PolyMesh&, bool, nlohmann::json&) { throw Error("info --costa: not implemented yet"); }
}  // namespace slim::cli
