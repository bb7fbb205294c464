// What the grid statistics (api/grid_stats.cpp) need of the grid builders (api/scene_grids.cpp):
// the same conversion and encoding as Scene::build, run to the error figures and, on request, the
// decoded triangles instead of a scene.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh_list.h"
#include "slimrt/decoded.h"
#include "slimrt/grids.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim {

// Runs the grid build of `opt` (a grid configuration, else slim::Error) over the meshes; fills
// `triangles` with the decoded triangles when given; returns the error figures (paper Table 3).
GridErrorStats extract_grid_scene(const MeshList& meshes, const BuildOptions& opt,
                                  DecodedTriangles* triangles);

}  // namespace slim
