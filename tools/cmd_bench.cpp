#include "commands.h"
#include "slimrt/slimrt.h"

namespace slim::cli {
int cmd_bench(int, char**) { throw Error("bench: not implemented yet"); }
}  // namespace slim::cli
