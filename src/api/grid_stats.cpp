// The grid statistics of slimrt/grids.h (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy
// Compressed Grid Primitives", Eurographics 2021 short papers): how the meshes become grids
// (section 3), the lossy error (Table 3) and the decoded triangles, by the same conversion and
// encoders as Scene::build.
#include <chrono>

#include "api/scene_grids.h"
#include "mesh/grids.h"
#include "prim/subgrid.h"
#include "slimrt/grids.h"

namespace slim {

GridStats grid_stats(const std::vector<const PolyMesh*>& meshes) {
  for (const PolyMesh* m : meshes) check_mesh(*m);
  const auto t0 = std::chrono::steady_clock::now();
  GridSet gs = make_grids(meshes);
  GridStats s;
  const GridConversionFigures& f = gs.figures;
  s.input_faces = f.input_faces;
  s.triangles = f.triangles;
  s.skipped_faces = f.skipped_faces;
  s.cells = f.cells;
  s.paired_cells = f.paired_cells;
  s.grids = f.grids;
  s.grid_cells = f.grid_cells;
  s.mean_grid_cells = f.grids ? double(f.grid_cells) / double(f.grids) : 0.0;
  s.largest_grid_cells = f.largest_grid_cells;
  for (size_t gi = 0; gi < gs.multi_cell_grids; ++gi) {
    const VertexGrid& g = gs.grids[gi];
    s.subgrids += uint64_t(subgrids_along(g.res_x)) * subgrids_along(g.res_y);
    s.full_subgrids += uint64_t((g.res_x - 1) / kSubGridCells) * ((g.res_y - 1) / kSubGridCells);
  }
  s.full_subgrid_triangle_pct =
      s.triangles ? 100.0 * double(s.full_subgrids) * 32.0 / double(s.triangles) : 0.0;
  s.single_cells = f.single_cells;
  s.leftover_triangles = f.leftover_triangles;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return s;
}

GridErrorStats grid_error(const std::vector<const PolyMesh*>& meshes, int encoding) {
  if (encoding != 1 && encoding != 2) throw Error("grid_error: encoding must be 1 or 2");
  return extract_grid_scene(
      meshes, BuildOptions::from_config(encoding == 1 ? "lossy-grid" : "lossy-grid-e2"), nullptr);
}

GridTriangles grid_triangles(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt) {
  GridTriangles t;
  extract_grid_scene(meshes, opt, &t);
  return t;
}
}  // namespace slim
