// What the grid statistics (api/grid_stats.cpp) need of the grid builders (api/scene_grids.cpp):
// the same conversion and encoding as Scene::build, run to the error figures and, on request, the
// decoded triangles instead of a scene.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "slimrt/decoded.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim {

struct GridExtraction {
  double rms = 0, max_error = 0, diag_avg_pct = 0, diag_max_pct = 0;  // paper Table 3
  uint64_t vertices = 0, subgrids = 0;
  uint64_t exact_vertices = 0;  // vertices stored exactly (shared with another grid or leftover)
  std::string leftovers;        // "grids", "triangles" or "none"
};

// Runs the grid build of `opt` (a grid configuration, else slim::Error) over the meshes; fills
// `triangles` with the decoded triangles when given.
GridExtraction extract_grid_scene(const std::vector<const PolyMesh*>& meshes,
                                  const BuildOptions& opt, DecodedTriangles* triangles);

}  // namespace slim
