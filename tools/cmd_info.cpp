#include "commands.h"
#include "slimrt/slimrt.h"

namespace slim::cli {
int cmd_info(int, char**) { throw Error("info: not implemented yet"); }
}  // namespace slim::cli
