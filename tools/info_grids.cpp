// `slimrt info --grids SCENE`: how the scene becomes vertex grids and what the lossy encodings cost
// in accuracy (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy Compressed Grid
// Primitives", Eurographics 2021 short papers, section 3 and Table 3).
// With --json the figures go into a "grids" object of the output.
#include <cstdio>

#include "commands.h"
#include "slimrt/grids.h"

namespace slim::cli {

namespace {

nlohmann::json error_json(const GridErrorStats& e) {
  return {{"rms", e.rms},
          {"max_error", e.max_error},
          {"diag_avg_pct", e.diag_avg_pct},
          {"diag_max_pct", e.diag_max_pct},
          {"vertices", e.vertices},
          {"subgrids", e.subgrids},
          {"exact_vertices", e.exact_vertices},
          {"leftovers", e.leftovers}};
}

}  // namespace

void info_grids(const PolyMesh& mesh, bool json, nlohmann::json& out) {
  const std::vector<const PolyMesh*> meshes{&mesh};
  const GridStats s = grid_stats(meshes);
  const GridErrorStats e1 = grid_error(meshes, 1);
  const GridErrorStats e2 = grid_error(meshes, 2);
  if (json) {
    out["grids"] = {{"triangles", s.triangles},
                    {"cells", s.cells},
                    {"paired_cells", s.paired_cells},
                    {"grids", s.grids},
                    {"grid_cells", s.grid_cells},
                    {"mean_grid_cells", s.mean_grid_cells},
                    {"largest_grid_cells", s.largest_grid_cells},
                    {"subgrids", s.subgrids},
                    {"full_subgrids", s.full_subgrids},
                    {"full_subgrid_triangle_pct", s.full_subgrid_triangle_pct},
                    {"leftover_cells", s.single_cells},
                    {"leftover_triangles", s.leftover_triangles},
                    {"leftovers_stored_as", e1.leftovers},
                    {"conversion_s", s.seconds},
                    {"error_e1", error_json(e1)},
                    {"error_e2", error_json(e2)}};
    return;
  }
  std::printf("\ngrids (lossy-compressed-grid-primitives, section 3)\n");
  std::printf("  cells (quads)          %llu (%llu of them paired triangles)\n",
              (unsigned long long)s.cells, (unsigned long long)s.paired_cells);
  std::printf("  grids                  %llu, %llu cells, mean %.1f cells, largest %llu\n",
              (unsigned long long)s.grids, (unsigned long long)s.grid_cells, s.mean_grid_cells,
              (unsigned long long)s.largest_grid_cells);
  std::printf("  5x5 sub-grids          %llu (%llu full)\n", (unsigned long long)s.subgrids,
              (unsigned long long)s.full_subgrids);
  std::printf("  triangles in full      %.2f %%\n", s.full_subgrid_triangle_pct);
  std::printf("  leftovers              %llu lone quads, %llu triangles, stored as %s\n",
              (unsigned long long)s.single_cells, (unsigned long long)s.leftover_triangles,
              e1.leftovers == "grids"       ? "2x2 sub-grids"
              : e1.leftovers == "triangles" ? "triangle leaves"
                                            : "-");
  std::printf("  conversion             %.3f s\n", s.seconds);
  std::printf("lossy error (paper Table 3)   RMS        max        diag avg %%  diag max %%\n");
  for (int k = 0; k < 2; ++k) {
    const GridErrorStats& e = k ? e2 : e1;
    std::printf(
        "  encoding %d                  %-10.3g %-10.3g %-11.4f %-10.4f (%llu exact vertices)\n",
        k + 1, e.rms, e.max_error, e.diag_avg_pct, e.diag_max_pct,
        (unsigned long long)e.exact_vertices);
  }
}

}  // namespace slim::cli
