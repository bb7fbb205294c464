// Writes the seed corpus of the fuzz targets: make_seeds OUT_DIR creates OUT_DIR/<target>/ for
// obj, ply, gltf, glb and xz, each holding the seed files of its format (fuzz/seed_files.h).
// Run by ./fuzz.sh before fuzzing; nothing it writes is kept in git.
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "seed_files.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: make_seeds OUT_DIR\n");
    return 2;
  }
  namespace fs = std::filesystem;
  const fs::path out = argv[1];
  int n = 0;
  for (const slim::seeds::SeedFile& f : slim::seeds::all_seeds()) {
    std::string name = f.name, target;
    const bool xz = name.size() > 3 && name.substr(name.size() - 3) == ".xz";
    const std::string stem = xz ? name.substr(0, name.size() - 3) : name;
    const std::string ext = stem.substr(stem.rfind('.') + 1);
    target = xz ? "xz" : ext;
    fs::create_directories(out / target);
    std::ofstream(out / target / name, std::ios::binary) << f.bytes;
    ++n;
    // The xz target also gets the plain files compressed, so that it reaches every reader.
    if (!xz) {
      fs::create_directories(out / "xz");
      std::ofstream(out / "xz" / (name + ".xz"), std::ios::binary)
          << slim::seeds::xz_compress(f.bytes);
      ++n;
    }
  }
  std::printf("make_seeds: %d files in %s\n", n, out.c_str());
  return 0;
}
