#include "commands.h"
#include "slimrt/slimrt.h"

namespace slim::cli {
int cmd_render(int, char**) { throw Error("render: not implemented yet"); }
}  // namespace slim::cli
