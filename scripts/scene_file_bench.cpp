// Scene file timings: open time, time to the first hit, and MRays/s of the
// mapped scene against the same scene built in memory, interleaved in one process.
//
//   g++ -O2 -std=c++20 -mavx2 -mfma -Iinclude scripts/scene_file_bench.cpp build/libslimrt.a \
//       -ltbb -lxxhash -lz -llzma -lGLU -lstb -o build/scene_file_bench
//   build/scene_file_bench FILE.slim [SCENE CONFIG ROUNDS]
//
// With FILE.slim alone: one open without checksums, the first hit, then one open with them
// (run after `sync; echo 3 > /proc/sys/vm/drop_caches` for the cold page cache). With SCENE and
// CONFIG: also builds SCENE in memory and renders 512x512 (1 spp, 2 diffuse bounces) from both
// scenes in alternation, ROUNDS times each, and prints the median MRays/s of each.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "slimrt/render.h"
#include "slimrt/slimrt.h"

using namespace slim;
using clk = std::chrono::steady_clock;
static double ms_since(clk::time_point t) {
  return std::chrono::duration<double, std::milli>(clk::now() - t).count();
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  const std::string file = argv[1];
  const double gb = double(std::filesystem::file_size(file)) / 1e9;
  {
    auto t0 = clk::now();
    OpenOptions o;
    o.verify_checksums = false;
    Scene s = Scene::open(file, o);
    const double open_ms = ms_since(t0);
    const Box3f b = s.bounds();
    Ray r;
    r.org = (b.lo + b.hi) * 0.5f + Vec3f(0, 0, 2 * (b.hi.z - b.lo.z) + 1);
    r.dir = Vec3f(0.01f, 0.02f, -1);
    const Hit h = s.intersect(r);
    const double first_ms = ms_since(t0);
    std::printf(
        "file %.3f GB | open (no checksums) %.2f ms | first hit %.2f ms after the open "
        "call (hit %d)\n",
        gb, open_ms, first_ms, int(h.valid()));
  }
  {
    auto t0 = clk::now();
    Scene s = Scene::open(file);
    const double ms = ms_since(t0);
    std::printf("open with checksums %.1f ms = %.0f ms/GB\n", ms, ms / gb);
  }
  if (argc < 4) return 0;
  const int rounds = argc > 4 ? std::atoi(argv[4]) : 5;
  Scene mapped = Scene::open(file);
  auto t0 = clk::now();
  Scene built = Scene::build(load(argv[2]), BuildOptions::from_config(argv[3]));
  std::printf("built %s as %s in %.1f s\n", argv[2], argv[3], ms_since(t0) / 1e3);
  RenderOptions ro;
  ro.width = ro.height = 512;
  ro.spp = 1;
  ro.max_bounces = 2;
  ViewOptions v;
  v.up = Axis::Z;
  const Camera cam = view_camera(built.bounds(), v, ro.width, ro.height);
  std::vector<double> m_mapped, m_built;
  for (int i = 0; i < rounds; ++i)
    for (int k = 0; k < 2; ++k) {
      const Scene& s = k == 0 ? mapped : built;
      RenderStats st;
      auto t = clk::now();
      render(s, cam, ro, &st);
      const double mr = double(st.rays) / (ms_since(t) * 1e3);
      (k == 0 ? m_mapped : m_built).push_back(mr);
    }
  auto med = [](std::vector<double> x) {
    std::sort(x.begin(), x.end());
    return x[x.size() / 2];
  };
  std::printf("MRays/s median of %d interleaved rounds: mapped %.2f, in memory %.2f (%.1f%%)\n",
              rounds, med(m_mapped), med(m_built), 100.0 * (med(m_mapped) / med(m_built) - 1));
  for (int i = 0; i < rounds; ++i)
    std::printf("  round %d: mapped %.2f, in memory %.2f\n", i, m_mapped[i], m_built[i]);
  return 0;
}
