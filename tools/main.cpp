// slimrt command-line tool: info, render, bench, verify, build, reorder.
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <exception>
#include <new>
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
               "         under mpirun -np K: one image by K processes [--mpi-tile N] "
               "[--mpi-root render|coordinate]\n"
               "  bench SCENE... [--config NAME...] [--threads N] [--repeat K] [--json FILE] "
               "[--plot FILE]\n"
               "  build SCENE --config NAME -o FILE.slim [--threads N]\n"
               "  verify SCENE [--config NAME...] [--rays N]\n"
               "  reorder SCENE OUT.obj [--config cluster|cluster-lossless] [--order FILE]\n"
               "every command that builds also takes the build options (--threads, --collapse, "
               "--sah-bins, ...: slimrt COMMAND --help)\n"
               "SCENE is a mesh file (.obj .ply .gltf .glb, optionally .xz) or terrain:N, "
               "torus:N, canyon:N, or (info, render, bench, verify) a scene file FILE.slim\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "-h") || !std::strcmp(argv[1], "--help")) {
    usage();
    return argc < 2 ? 2 : 0;
  }
  std::string cmd = argv[1];
  // A file size limit (ulimit -f) makes writes fail with EFBIG, reported like a full disk,
  // instead of killing the process half-way through an output.
  std::signal(SIGXFSZ, SIG_IGN);
  // A reader that goes away (a pipe closed early) makes writes fail with EPIPE, reported as a
  // write error, instead of killing the process.
  std::signal(SIGPIPE, SIG_IGN);
  int rc = -1;
  try {
    slim::check_cpu_isa();  // before any code compiled for the SIMD path runs
    if (cmd == "info") rc = slim::cli::cmd_info(argc - 1, argv + 1);
    if (cmd == "render") rc = slim::cli::cmd_render(argc - 1, argv + 1);
    if (cmd == "bench") rc = slim::cli::cmd_bench(argc - 1, argv + 1);
    if (cmd == "verify") rc = slim::cli::cmd_verify(argc - 1, argv + 1);
    if (cmd == "build") rc = slim::cli::cmd_build(argc - 1, argv + 1);
    if (cmd == "reorder") rc = slim::cli::cmd_reorder(argc - 1, argv + 1);
  } catch (const slim::Error& e) {
    std::fprintf(stderr, "slimrt: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    // The commands wrap their phases with context (slim::cli::out_of_memory_context); this is the
    // rest.
    std::fprintf(stderr, "slimrt: error: out of memory in 'slimrt %s' (std::bad_alloc)\n",
                 cmd.c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "slimrt: error: %s\n", e.what());
    return 1;
  }
  if (rc >= 0) {
    // Results printed on stdout count as output: a full disk or closed pipe is an error.
    if (std::fflush(stdout) != 0 || std::ferror(stdout)) {
      std::fprintf(stderr, "slimrt: error: cannot write to standard output: %s\n",
                   std::strerror(errno));
      return 1;
    }
    return rc;
  }
  std::fprintf(stderr, "slimrt: unknown command '%s'\n", cmd.c_str());
  usage();
  return 2;
}
