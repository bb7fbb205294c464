// slimrt command-line tool: info, render, bench.
#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

#include "commands.h"
#include "slimrt/error.h"
#include "slimrt/scene.h"

namespace {

void usage() {
  std::fprintf(stderr,
               "usage: slimrt <command> [args]\n"
               "  info SCENE [--json] [--accel CONFIG] [--pairs] [--costa]\n"
               "  render SCENE -o OUT.png|OUT.exr [--shade diffuse|sun|normals|kind] [--spp N] "
               "[--res WxH] [--config NAME]\n"
               "         [--up x|y|z] [--eye X,Y,Z] [--look-at X,Y,Z] [--fov DEG] [--quiet]\n"
               "  bench SCENE... [--config NAME...] [--threads N] [--repeat K] [--json FILE] "
               "[--plot FILE]\n"
               "SCENE is a mesh file (.obj .ply .gltf .glb, optionally .xz) or terrain:N, "
               "torus:N, canyon:N\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "-h") || !std::strcmp(argv[1], "--help")) {
    usage();
    return argc < 2 ? 2 : 0;
  }
  std::string cmd = argv[1];
  try {
    slim::check_cpu_isa();  // before any code compiled for the SIMD path runs
    if (cmd == "info") return slim::cli::cmd_info(argc - 1, argv + 1);
    if (cmd == "render") return slim::cli::cmd_render(argc - 1, argv + 1);
    if (cmd == "bench") return slim::cli::cmd_bench(argc - 1, argv + 1);
    if (cmd == "verify") return slim::cli::cmd_verify(argc - 1, argv + 1);
  } catch (const slim::Error& e) {
    std::fprintf(stderr, "slimrt: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "slimrt: error: %s\n", e.what());
    return 1;
  }
  std::fprintf(stderr, "slimrt: unknown command '%s'\n", cmd.c_str());
  usage();
  return 2;
}
