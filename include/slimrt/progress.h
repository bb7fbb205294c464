// slimrt build progress: what Scene::build reports to BuildOptions::progress, and how a caller
// cancels a build.
//
//   opt.progress = [](const slim::BuildProgress& p) {
//     std::fprintf(stderr, "%s %.0f%%\r", p.phase.c_str(), 100 * p.fraction());
//     return true;  // false cancels: Scene::build throws slim::Cancelled
//   };
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace slim {

// Progress of Scene::build, passed to BuildOptions::progress. A build runs a few phases in
// order: "prepare" (the format's own work before the BVH: triangulation, pairing, grids, clusters,
// quantization), "bvh2" (the binary SAH BVH) and "collapse" (the 8-wide BVH and the leaf data);
// the grid formats with triangle leftovers add "bvh2 leftovers" and "collapse leftovers". Within
// a phase `done` only grows, from 0 to `total` (its last report has done == total); units are the
// phase's own (primitives placed in leaves, primitives encoded, steps of the preparation).
struct BuildProgress {
  std::string phase;
  uint64_t done = 0, total = 0;
  double fraction() const { return total ? double(done) / double(total) : 1.0; }
};
// Called a few hundred times per phase at most (about every percent), never per primitive, from
// any of the build's threads but never concurrently (the calls are serialized). Returning false
// cancels the build: Scene::build then throws slim::Cancelled (error.h) and keeps nothing.
using BuildProgressFn = std::function<bool(const BuildProgress&)>;

}  // namespace slim
