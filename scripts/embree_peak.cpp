// The peak memory of an Embree `embree-tri` build (docs/results.md, "One billion triangles"):
// loads a mesh or procedural scene, builds it with the benchmark's EmbreeScene, traces one ray
// down through the middle of its box and prints Embree's build time and memory figures; run it
// under `/usr/bin/time -v` for the peak resident memory.
//
//   g++ -O2 -std=c++20 -mavx2 -mfma -Iinclude -Ibench scripts/embree_peak.cpp \
//       build/libslimrt_bench.a build/libslimrt.a -lembree3 -ltbb -lxxhash -lz -llzma -lGLU \
//       -lstb -o build/embree_peak
//   /usr/bin/time -v build/embree_peak terrain:8000
#include <cstdio>
#include <exception>
#include <vector>

#include "embree_scene.h"
#include "slimrt/slimrt.h"

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: embree_peak SCENE\n");
    return 2;
  }
  try {
    const slim::PolyMesh mesh = slim::load(argv[1]);
    const std::vector<const slim::PolyMesh*> meshes = {&mesh};
    const slim::bench::EmbreeScene scene(meshes, "embree-tri");
    const slim::Box3f b = scene.bounds();
    slim::Ray ray;
    ray.org = {(b.lo.x + b.hi.x) / 2, (b.lo.y + b.hi.y) / 2, b.hi.z + 1};
    ray.dir = {0, 0, -1};
    const slim::Hit hit = scene.intersect(ray);
    const slim::MemoryStats m = scene.memory();
    std::printf("%s: %llu triangles, Embree build %.1f s, scene %.2f GB, ray %s\n", argv[1],
                static_cast<unsigned long long>(m.triangles), scene.build_seconds(),
                double(m.geometry_bytes + m.bvh_bytes + m.other_bytes) / 1e9,
                hit.valid() ? "hit" : "missed");
  } catch (const std::exception& e) {
    std::fprintf(stderr, "embree_peak: %s\n", e.what());
    return 1;
  }
}
