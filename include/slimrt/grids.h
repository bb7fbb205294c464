// slimrt grid statistics and grid attributes (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing
// Lossy Compressed Grid Primitives", Eurographics 2021 short papers).
//
//   slim::GridStats g = slim::grid_stats(meshes);                // how the meshes became grids
//   slim::GridErrorStats e = slim::grid_error(meshes, 1);        // paper Table 3, encoding 1
//
//   slim::GridAttributes ga = slim::GridAttributes::build(meshes);   // section 6
//   std::vector<slim::Vec2f> uv = ga.grid_ordered(0, mesh.uvs, mesh.uv_indices);
//   slim::Hit hit = scene.intersect(ray);                        // a grid format
//   if (hit.valid() && hit.kind == slim::PrimKind::Grid) slim::Vec2f t = ga.interpolate(uv, hit);
//
// The grids themselves are built inside Scene::build for the `grid`, `lossy-grid` and
// `lossy-grid-e2` configurations; this header reports what that conversion does and helps with
// per-vertex attributes, which the grid formats do not store.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "slimrt/decoded.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim {

// Mesh -> grid conversion (paper section 3) as Scene::build does it.
struct GridStats {
  uint64_t input_faces = 0, triangles = 0;  // triangles: fan triangles of the input
  uint64_t skipped_faces = 0;               // faces with a NaN/Inf vertex
  uint64_t cells = 0;                       // quads: quad faces, n-gon fan quads and triangle pairs
  uint64_t paired_cells = 0;                // cells made of two paired triangles
  uint64_t grids = 0;                       // grids of 2 cells or more
  uint64_t grid_cells = 0;                  // cells in those grids
  double mean_grid_cells = 0;               // grid_cells / grids
  uint64_t largest_grid_cells = 0;
  uint64_t subgrids = 0;                 // 5x5 sub-grids of those grids
  uint64_t full_subgrids = 0;            // with all 32 triangles
  double full_subgrid_triangle_pct = 0;  // % of the input triangles inside full sub-grids
  uint64_t single_cells = 0;             // leftover lone quads (1-cell grids)
  uint64_t leftover_triangles = 0;       // leftover triangles (unpaired)
  double seconds = 0;                    // conversion time
};
GridStats grid_stats(const std::vector<const PolyMesh*>& meshes);

// Lossy error (paper Table 3) of the sub-grids Scene::build makes for `lossy-grid` (encoding 1)
// or `lossy-grid-e2` (encoding 2), leftovers included as Scene::build stores them.
struct GridErrorStats {
  double rms = 0;           // RMS over all grid vertices of |decoded - input| (scene units)
  double max_error = 0;     // largest |decoded - input|
  double diag_avg_pct = 0;  // per sub-grid: largest vertex error / its box diagonal, in %,
  double diag_max_pct = 0;  //   averaged over the sub-grids / the largest
  uint64_t vertices = 0, subgrids = 0;
  uint64_t exact_vertices = 0;  // vertices stored exactly (shared with another grid or leftover)
  std::string leftovers;        // stored as "grids" (2x2 sub-grids), "triangles" (leaves) or "none"
};
GridErrorStats grid_error(const std::vector<const PolyMesh*>& meshes, int encoding = 1);

// The triangles a grid configuration (`grid`, `lossy-grid`, `lossy-grid-e2`, any Bvh) intersects,
// decoded exactly as its traversal decodes them, with the input face of each: to check a lossy
// format against a reference run on its own decompressed geometry. Grid cells give 2 triangles each
// (degenerate ones included); leftover triangles follow. Throws slim::Error for other
// configurations.
using GridTriangles = DecodedTriangles;
GridTriangles grid_triangles(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt);

// Per-vertex attributes of grid hits (paper section 6): attributes laid out in the same grid
// order as the vertices, looked up with the hit's per-grid u,v. Built by the same (deterministic)
// conversion as Scene::build, so it matches any grid-format scene of the same meshes.
class GridAttributes {
 public:
  GridAttributes();
  ~GridAttributes();
  GridAttributes(GridAttributes&&) noexcept;
  GridAttributes& operator=(GridAttributes&&) noexcept;

  static GridAttributes build(const std::vector<const PolyMesh*>& meshes);

  // Total grid vertices: the size of every grid-ordered array.
  uint64_t grid_vertex_count() const;

  // Grid-ordered copy of an attribute of mesh `geom` (the entries of other meshes' grids are left
  // zero): per corner through `indices` (parallel to face_indices), or per vertex if `indices` is
  // empty. The grids never cross a seam of uv_indices / normal_indices, so each grid vertex has
  // one value.
  std::vector<Vec2f> grid_ordered(uint32_t geom, const std::vector<Vec2f>& values,
                                  const std::vector<uint32_t>& indices) const;
  std::vector<Vec3f> grid_ordered(uint32_t geom, const std::vector<Vec3f>& values,
                                  const std::vector<uint32_t>& indices) const;

  // The attribute at a hit with hit.kind == PrimKind::Grid: the grid cell from the face and the
  // per-grid u,v, then the barycentric interpolation over the cell's triangle that was hit.
  // Returns false (and leaves `out`) for other hits: those carry the barycentric u,v of a fan
  // triangle, as in the triangle formats.
  bool interpolate(const std::vector<Vec2f>& grid_values, const Hit& hit, Vec2f& out) const;
  bool interpolate(const std::vector<Vec3f>& grid_values, const Hit& hit, Vec3f& out) const;

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace slim
