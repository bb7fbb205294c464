// slimrt CLI subcommands. Each returns the process exit code; errors are printed by main().
#pragma once

namespace slim::cli {

int cmd_info(int argc, char** argv);
int cmd_render(int argc, char** argv);
int cmd_bench(int argc, char** argv);

}  // namespace slim::cli
