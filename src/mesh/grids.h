// Mesh -> vertex grids (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy Compressed Grid
// Primitives", Eurographics 2021 short papers, section 3 "Conversion to Vertex Grids").
//
// The faces of each input mesh become "cells" (quads with 4 corners c0..c3, triangulated as
// (c0,c1,c2) + (c0,c2,c3), i.e. along the c0-c2 diagonal as slimrt's fan triangulation does):
//   - every quad face (v0,v1,v2,v3) is one cell;
//   - an n-gon (n >= 5) gives the quads (v0, v_k, v_k+1, v_k+2) of its fan, k = 1, 3, ..., and a
//     last fan triangle when n is odd;
//   - triangle faces (and odd n-gon remainders) are paired by mesh/pairing.h (the edge-heuristic
//     of A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing"); a pair (a,b,c) + (a,c,d)
//     sharing a-c is the cell (a,b,c,d).
// Cells are merged greedily (section 3: "a locally greedy algorithm ... trying to maximize its
// size") into rectangles: a seed cell grows one row or column at a time, right, down, left, up in
// turn, while every new cell exists, is not used yet and shares its edges with its neighbours in
// the rectangle (manifold, consistently oriented, no uv/normal seam across the edge). A cell keeps
// its own diagonal: when its c0-c2 diagonal falls on the grid's anti-diagonal (x+1,y)-(x,y+1), the
// cell is "flipped" (GridSet::cell_flip) and the grid primitives triangulate it that way, so that
// every grid triangle is a fan triangle of the input (lossless grids agree with embree-tri hit for
// hit, also on non-planar quads). Grids never cross meshes. A grid that wraps around a closed
// surface (torus) repeats the seam vertices: the copies are the same input vertex, so they decode
// to the same bits.
//
// Cells left alone (1-cell grids) and unpaired triangles are the "leftovers": the scene builders
// store them as 2x2 grids or as triangle leaves, whichever takes less memory.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mesh/mesh_list.h"
#include "slimrt/mesh.h"

namespace slim {

struct GridBuildOptions {
  // Keep each quad's fan diagonal (c0-c2) by flipping cells whose diagonal is the grid's
  // anti-diagonal (costs a 16-bit mask per sub-grid of the grids that have such cells). Off: quads
  // are split along the grid's main diagonal (differs from the fan on non-planar quads only);
  // triangle pairs always keep their shared edge.
  bool match_fan_diagonal = true;
  // Largest grid side in vertices (Listing 1 stores gridResX/Y as 16 bits; the exact-vertex
  // index of the lossy format has 18 bits, so a grid's boundary must stay below 2^18 vertices).
  uint32_t max_res = 32768;
  // Pair triangle faces into cells (mesh/pairing.h) before growing grids.
  bool pair_triangles = true;
  // Fill GridSet::corner_of_vertex (needed for attribute lookups only).
  bool corners = false;
};

// One rectangular vertex grid (res_x x res_y vertices, (res_x-1) x (res_y-1) cells), row-major.
struct VertexGrid {
  uint32_t geom = 0;  // input mesh
  uint32_t res_x = 0, res_y = 0;
  uint64_t vertex_offset = 0;  // first entry in GridSet::vertices
  uint64_t cell_offset = 0;    // first cell in GridSet::cell_faces (2 entries per cell)
};

// A triangle left over (not in any cell): corners as vertex indices of mesh `geom`.
struct LeftoverTriangle {
  uint32_t geom = 0, face = 0;
  uint32_t v[3] = {0, 0, 0};
  uint32_t corner[3] = {0, 0, 0};  // face corners (indices into face_indices), for attributes
};

struct GridConversionFigures {
  uint64_t input_faces = 0, skipped_faces = 0;  // skipped: faces with a NaN/Inf vertex
  uint64_t triangles = 0;      // fan triangles of the input (skipped faces included)
  uint64_t cells = 0;          // quads formed (quad faces, n-gon quads, triangle pairs)
  uint64_t flipped_cells = 0;  // cells in grids triangulated along the anti-diagonal
  uint64_t paired_cells = 0;   // of which triangle pairs
  uint64_t grids = 0;          // grids of 2 cells or more
  uint64_t grid_cells = 0;     // cells in those grids
  uint64_t single_cells = 0;   // 1-cell grids (lone quads: leftovers)
  uint64_t leftover_triangles = 0;
  uint64_t largest_grid_cells = 0;
  double seconds = 0;
};

struct GridSet {
  std::vector<VertexGrid> grids;   // grids of >= 2 cells first, then the 1-cell grids
  uint64_t multi_cell_grids = 0;   // grids[0 .. multi_cell_grids) have 2 cells or more
  std::vector<uint32_t> vertices;  // grid-ordered vertex indices into the grid's mesh
  // Per cell, row-major per grid: the input faces of its two triangles, A then B, where A =
  // (c00, c10, c11), B = (c00, c11, c01), or for a flipped cell A = (c00, c10, c01), B = (c11, c01,
  // c10); and whether the cell is flipped.
  std::vector<uint32_t> cell_faces;
  std::vector<uint8_t> cell_flip;
  std::vector<uint32_t> corner_of_vertex;  // if GridBuildOptions::corners: grid-ordered, a face
                                           // corner (index into face_indices) of each grid vertex
  std::vector<LeftoverTriangle> triangles;
  GridConversionFigures figures;

  uint32_t vertex(const VertexGrid& g, uint32_t x, uint32_t y) const {
    return vertices[g.vertex_offset + uint64_t(y) * g.res_x + x];
  }
  uint32_t cell_face(const VertexGrid& g, uint32_t x, uint32_t y, int tri) const {
    return cell_faces[2 * (g.cell_offset + uint64_t(y) * (g.res_x - 1) + x) + tri];
  }
  bool flipped(const VertexGrid& g, uint32_t x, uint32_t y) const {
    return cell_flip[g.cell_offset + uint64_t(y) * (g.res_x - 1) + x] != 0;
  }
};

// Converts the meshes (mesh i = geom i) to grids. Faces with a NaN/Inf vertex are skipped.
// Throws slim::Error if a mesh has 2^30 cells or more.
GridSet make_grids(const MeshList& meshes, const GridBuildOptions& opt = {});

// Sub-grid lattice (section 3, 5x5 sub-grids): grid column x is a sub-grid border iff x is a
// multiple of 4 or the grid's last column; likewise for rows.
inline bool lattice_line(uint32_t x, uint32_t res) { return x % 4 == 0 || x + 1 == res; }

// Grid positions whose vertex a lossy format must store exactly, so that a vertex shared by two
// grids decodes to the same bits in both. A lossy decoder rebuilds a vertex from the sub-grid
// corners around it: corners are exact, a point on a sub-grid border depends on the two corners of
// that border only, an interior point on all four. A vertex used in several places (another grid,
// the same grid across a seam, a leftover triangle or 1-cell grid) decodes to the same bits
// everywhere only if every lossy use has the same border corners and offset (a torus grid's seam
// does), so all the others are listed here: positions y * res_x + x, ascending, per multi-cell
// grid.
// escape_boundary (a build with BuildOptions::lattice_box: a chunk of a larger mesh) also lists
// every vertex on a boundary edge of the meshes (an edge of one triangle or cell only, vertex
// identity as above): a chunk's cut is such an edge in both chunks, whose grids differ, so its
// vertices are stored exactly on both sides and decode to the input's bits in each. A cut along an
// edge of 3+ faces (non-manifold) that leaves 2 of them in one chunk is not a boundary there:
// that side may keep its vertices lossy.
struct ExactPositions {
  std::vector<uint64_t> start;  // grids.size() + 1 entries
  std::vector<uint32_t> pos;
  uint64_t count(size_t grid) const { return start[grid + 1] - start[grid]; }
};
ExactPositions find_exact_positions(const GridSet& gs, const MeshList& meshes,
                                    bool escape_boundary = false);

// Appends the leftover triangles of gs as 2x2 grids (a, b / c, c): A = (a, b, c), B = (a, c, c)
// degenerate; with_corners also extends gs.corner_of_vertex.
void append_triangle_grids(GridSet& gs, bool with_corners);

}  // namespace slim
