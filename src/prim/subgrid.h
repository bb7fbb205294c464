// Grid primitives, part 1 (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy Compressed
// Grid Primitives", Eurographics 2021 short papers):
//   - the per-grid side table (GridInfo) that maps a sub-grid cell back to the input face;
//   - the ray / 5x5 sub-grid kernel of section 5: a decompressed sub-grid (25 vertices) is moved
//     to ray space once, then the 8 triangles of one row are tested at a time with the 8-wide
//     watertight test (core/watertight.h), 4 rows at most;
//   - the uncompressed `grid` leaf (SubGrid, 16 B): a sub-grid that references the grid-ordered
//     float vertices, the counterpart of Embree's grid primitive (section 7).
// The lossy 128-byte sub-grid of section 4 is in prim/lossy_subgrid.h and uses the same kernel.
//
// Triangulation of a grid cell (x,y): triangle A = (p(x,y), p(x+1,y), p(x+1,y+1)) and triangle
// B = (p(x,y), p(x+1,y+1), p(x,y+1)): the c0-c2 diagonal of the cell, as mesh/grids.h lays cells
// out so that this is the fan triangulation of the input face.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "core/hash.h"
#include "core/ray.h"
#include "core/simd.h"
#include "core/simd_ext.h"
#include "core/watertight.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

// Sub-grid resolution in vertices (section 3: 5x5 vertices = 4x4 quads = 32 triangles).
constexpr uint32_t kSubGridRes = 5;
constexpr uint32_t kSubGridCells = kSubGridRes - 1;
// Sub-grids along a grid side of `res` vertices (the last one partial when res - 1 is not a
// multiple of kSubGridCells).
SLIM_INLINE uint32_t subgrids_along(uint32_t res) {
  return (res - 1 + kSubGridCells - 1) / kSubGridCells;
}

// ---- per-grid side table ---------------------------------------------------------------------

enum GridFlags : uint32_t {
  kGridFaceTable = 1,   // faces come from the face table, 2 entries per cell (A, B)
  kGridFaceTable1 = 2,  // faces come from the face table, 1 entry per cell (A = B)
};

// One grid of the scene, what a hit needs (28 B, read once per closest hit). The face of cell
// (x,y), triangle tri (0 = A, 1 = B) is
//   affine: face0 + x * face_dx + y * face_dy + tri * face_ab  (e.g. terrain: 0 + x + y * N)
//   table:  face_table[face0 + cell * 2 + tri] or face_table[face0 + cell]  (cell = y*(res_x-1)+x)
struct GridInfo {
  uint32_t geom = 0;                              // 4 B: input mesh (Hit::geomID)
  uint16_t res_x = 0, res_y = 0;                  // 4 B: vertices
  uint32_t flags = 0;                             // 4 B: GridFlags
  uint32_t face0 = 0;                             // 4 B
  int32_t face_dx = 0, face_dy = 0, face_ab = 0;  // 12 B
};
static_assert(sizeof(GridInfo) == 28, "grid side-table entry is 28 bytes");

// What the decoder of a sub-grid may need from its grid (16 B).
constexpr uint32_t kNoFlips = 0xffffffffu;
struct GridHot {
  uint32_t lattice_first = 0;  // shared-corner lossy layout: first corner of the grid's lattice
  uint32_t lattice_row = 0;    //   and corners per lattice row (= sub-grids per row + 1)
  uint32_t exact = 0;          // lossy: first of the grid's exact vertices
  uint32_t flips = kNoFlips;   // first of the grid's per-sub-grid flip masks, or kNoFlips
};
static_assert(sizeof(GridHot) == 16, "grid decoder entry is 16 bytes");

// Flip mask of a sub-grid: bit 4*j + i set if cell (i, j) is triangulated along its anti-diagonal
// (mesh/grids.h: the cell keeps its input quad's fan diagonal).
// The flip table entry of sub-grid (sx, sy) of a grid with flips (h.flips != kNoFlips).
SLIM_INLINE uint32_t subgrid_flip_index(const GridHot& h, uint32_t sx, uint32_t sy,
                                        uint32_t subgrids_x) {
  return h.flips + sy * subgrids_x + sx;
}
SLIM_INLINE uint32_t subgrid_flips(const GridHot& h, const uint16_t* table, uint32_t sx,
                                   uint32_t sy, uint32_t subgrids_x) {
  return h.flips == kNoFlips ? 0u : table[subgrid_flip_index(h, sx, sy, subgrids_x)];
}

SLIM_INLINE bool grid_face_from_table(const GridInfo& g) {
  return (g.flags & (kGridFaceTable | kGridFaceTable1)) != 0;
}
// The face table entry of cell (x, y), triangle tri of a grid whose faces come from the table.
SLIM_INLINE uint64_t grid_face_index(const GridInfo& g, uint32_t x, uint32_t y, int tri) {
  const uint64_t cell = uint64_t(y) * (g.res_x - 1u) + x;
  return g.flags & kGridFaceTable ? g.face0 + 2 * cell + uint64_t(tri) : g.face0 + cell;
}
SLIM_INLINE uint32_t grid_face(const GridInfo& g, const uint32_t* table, uint32_t x, uint32_t y,
                               int tri) {
  if (grid_face_from_table(g)) return table[grid_face_index(g, x, y, tri)];
  return uint32_t(int64_t(g.face0) + int64_t(x) * g.face_dx + int64_t(y) * g.face_dy +
                  int64_t(tri) * g.face_ab);
}

// Element counts of the side tables the grid leaves' blocks index: what the structure check of
// scene files (OpenOptions::check_structure) bounds every reference by. Set from the section
// sizes when a scene file is written or opened (api/scene_grids.cpp).
struct GridTableSizes {
  uint64_t grids = 0, hot = 0, faces = 0, flips = 0;
  uint64_t vertices = 0;                  // `grid`: grid vertices
  uint64_t exact = 0;                     // lossy: exact vertices
  uint64_t corners = 0, corner_grid = 0;  // shared layout
};

// The structure check of a block whose cells [0, res_x-1) x [0, res_y-1) lie at (gx, gy) in grid
// `grid` (both table entries already checked): every face table entry a hit on them reads.
inline const char* check_grid_faces(const GridInfo& g, uint64_t faces, uint32_t gx, uint32_t gy,
                                    uint32_t res_x, uint32_t res_y) {
  if (!grid_face_from_table(g)) return nullptr;
  for (uint32_t j = 0; j + 1 < res_y; ++j)
    for (uint32_t i = 0; i + 1 < res_x; ++i)
      for (int tri = 0; tri < 2; ++tri)
        if (grid_face_index(g, gx + i, gy + j, tri) >= faces)
          return "face table entry of a cell beyond the face table (grid.faces)";
  return nullptr;
}
// Sub-grid resolutions the kernels take: 2..5 vertices per side.
SLIM_INLINE bool subgrid_res_ok(uint32_t res_x, uint32_t res_y) {
  return res_x >= 2 && res_x <= kSubGridRes && res_y >= 2 && res_y <= kSubGridRes;
}

// ---- the 5x5 kernel (section 5) --------------------------------------------------------------

// A decompressed sub-grid: vertex (i,j) of axis a at p[a][5*j + i]; 32 lanes (25 used) so that
// whole 8-lane groups can be processed.
struct alignas(32) SubGridVerts {
  float p[3][32];
};

// Where a ray hit a sub-grid: the cell, which of its two triangles, the cell-local coordinates
// (cu, cv) in [0,1]^2 and the geometric normal of that triangle.
struct SubGridHit {
  float t = 0, cu = 0, cv = 0;
  uint32_t cell_x = 0, cell_y = 0;
  int tri = 0;
  Vec3f Ng;
};

namespace detail {

SLIM_INLINE int closest_lane8(uint32_t m, const simd::vfloat8& t) {
  alignas(32) float tt[8];
  t.store(tt);
  int best = simd::pop_lowest(m);
  while (m) {
    int i = simd::pop_lowest(m);
    if (tt[i] < tt[best]) best = i;
  }
  return best;
}

SLIM_INLINE Vec3f subgrid_vertex(const SubGridVerts& w, int k) {
  return {w.p[0][k], w.p[1][k], w.p[2][k]};
}

// Fills h for a hit on triangle tri (0 = A, 1 = B) of cell (cx, cy), whose corners p(i,j),
// p(i+1,j), p(i,j+1), p(i+1,j+1) are at k00, k10, k01, k11 of the vertex rows px, py, pz,
// tested as below (intersect_subgrid_rows) with barycentrics (u, v) at distance t.
SLIM_INLINE void finish_cell_hit(const float* px, const float* py, const float* pz, int k00,
                                 int k10, int k01, int k11, uint32_t cx, uint32_t cy, int tri,
                                 bool flipped, float t, float u, float v, SubGridHit& h) {
  h.t = t;
  h.cell_x = cx;
  h.cell_y = cy;
  h.tri = tri;
  int c0, c1, c2;  // corners as tested: point = c0 + u (c1 - c0) + v (c2 - c0)
  if (tri == 0) {
    c0 = k00;
    c1 = k10;
    c2 = flipped ? k01 : k11;
    h.cu = flipped ? u : u + v;
    h.cv = v;
  } else {
    c0 = k11;
    c1 = k01;
    c2 = flipped ? k10 : k00;
    h.cu = flipped ? 1.0f - u : 1.0f - u - v;
    h.cv = 1.0f - v;
  }
  auto vert = [&](int k) { return Vec3f(px[k], py[k], pz[k]); };
  const Vec3f p0 = vert(c0), p1 = vert(c1), p2 = vert(c2);
  h.Ng = cross(p1 - p0, p2 - p0);
}

}  // namespace detail

// The 32 lanes of a decompressed sub-grid in ray space: core/watertight.h's to_ray_space, the
// same operations in the same order (so that a vertex a triangle leaf shares transforms to the
// same bits; GridKernel.RaySpaceMatchesCore checks it), with the per-ray scalars fetched once.
// Groups g0 .. g1-1 of 8 lanes only (a half sub-grid needs 2 or 3 of the 4).
SLIM_INLINE void subgrid_to_ray_space(const WatertightRay& wr, const SubGridVerts& w,
                                      float (*r)[32], int g0 = 0, int g1 = 4) {
  using namespace simd;
  const float* px = w.p[wr.kx];
  const float* py = w.p[wr.ky];
  const float* pz = w.p[wr.kz];
  const vfloat8 ox(wr.ox), oy(wr.oy), oz(wr.oz);
  const vfloat8 sx(wr.Sx), sy(wr.Sy), sz(wr.Sz);
  for (int g = g0; g < g1; ++g) {
    const vfloat8 ax = vfloat8::load(px + 8 * g) - ox;
    const vfloat8 ay = vfloat8::load(py + 8 * g) - oy;
    const vfloat8 az = vfloat8::load(pz + 8 * g) - oz;
    fnmadd(sx, az, ax).store(&r[0][8 * g]);
    fnmadd(sy, az, ay).store(&r[1][8 * g]);
    (sz * az).store(&r[2][8 * g]);
  }
}

// Intersects the (res_x-1) x (res_y-1) cells of a decompressed sub-grid. Lanes 0-3 of a row hold
// triangles A of cells 0-3, lanes 4-7 triangles B, the latter with their corners rotated to
// (p11, p01, p00) so that all three corner vectors are two 4-float loads from the ray-space rows
// (the same directed edges, so the watertight edge functions are the ones a neighbour computes).
// Flipped cells (bit 4*j + i of `flips`) are A = (p00, p10, p01), B = (p11, p01, p10): only the
// third corner changes, and their outer edges keep their directions.
// Closest hit: lowers ray.tfar and fills h; any hit: returns at the first hit.
// intersect_subgrid_rows tests the cell rows j0 .. j1-1 only, from the ray-space vertices r of
// those rows (a half sub-grid, see prim/lossy_subgrid.h).
template <bool kAny, class Stats>
SLIM_INLINE bool intersect_subgrid_rows(const SubGridVerts& w, const float (*r)[32], uint32_t res_x,
                                        uint32_t j0, uint32_t j1, uint32_t flips, TravRay& ray,
                                        SubGridHit& h, Stats& st) {
  using namespace simd;
  const uint32_t cells = (1u << (res_x - 1)) - 1;
  const uint32_t valid = cells | (cells << 4);
  bool found = false;
  int best_row = 0, best_lane = 0;
  float best_u = 0, best_v = 0;

  for (uint32_t j = j0; j < j1; ++j) {
    const int a = int(5 * j);
    // V0: A p(i,j) | B p(i+1,j+1); V1: A p(i+1,j) | B p(i,j+1); V2: A p(i+1,j+1) | B p(i,j).
    RayVertex<vfloat8> V0{load2x4(&r[0][a], &r[0][a + 6]), load2x4(&r[1][a], &r[1][a + 6]),
                          load2x4(&r[2][a], &r[2][a + 6])};
    RayVertex<vfloat8> V1{load2x4(&r[0][a + 1], &r[0][a + 5]), load2x4(&r[1][a + 1], &r[1][a + 5]),
                          load2x4(&r[2][a + 1], &r[2][a + 5])};
    RayVertex<vfloat8> V2{swap_halves(V0.x), swap_halves(V0.y), swap_halves(V0.z)};
    if (const uint32_t f = (flips >> (4 * j)) & 15) {  // flipped: A p(i,j+1) | B p(i+1,j)
      const vbool8 m = lanes_from_bits(f | (f << 4));
      V2.x = select(m, load2x4(&r[0][a + 5], &r[0][a + 1]), V2.x);
      V2.y = select(m, load2x4(&r[1][a + 5], &r[1][a + 1]), V2.y);
      V2.z = select(m, load2x4(&r[2][a + 5], &r[2][a + 1]), V2.z);
    }
    if constexpr (!std::is_same_v<Stats, NoStats>) st.prims(2 * int(res_x - 1));
    vfloat8 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(V0, V1, V2, valid, ray.tnear, ray.tfar, t, u, v);
    if (!m) continue;
    if constexpr (kAny) return true;
    const int lane = detail::closest_lane8(m, t);
    ray.tfar = t[lane];
    best_row = int(j);
    best_lane = lane;
    best_u = u[lane];
    best_v = v[lane];
    found = true;
  }

  if constexpr (!kAny) {
    if (!found) return false;
    const int i = best_lane & 3, j = best_row;
    const int k00 = 5 * j + i;
    detail::finish_cell_hit(w.p[0], w.p[1], w.p[2], k00, k00 + 1, k00 + 5, k00 + 6, uint32_t(i),
                            uint32_t(j), best_lane >> 2, (flips >> (4 * j + i)) & 1, ray.tfar,
                            best_u, best_v, h);
  }
  return found;
}

template <bool kAny, class Stats>
SLIM_INLINE bool intersect_subgrid(const SubGridVerts& w, uint32_t res_x, uint32_t res_y,
                                   uint32_t flips, TravRay& ray, SubGridHit& h, Stats& st) {
  alignas(32) float r[3][32];
  subgrid_to_ray_space(ray.wt, w, r);
  return intersect_subgrid_rows<kAny>(w, r, res_x, 0, res_y - 1, flips, ray, h, st);
}

// Bounds of the vertices [i0, i1) x [j0, j1) of a decompressed sub-grid.
inline Box3f subgrid_vertex_bounds(const SubGridVerts& w, uint32_t i0, uint32_t i1, uint32_t j0,
                                   uint32_t j1) {
  Box3f b;
  for (uint32_t j = j0; j < j1; ++j)
    for (uint32_t i = i0; i < i1; ++i) b.extend(detail::subgrid_vertex(w, int(5 * j + i)));
  return b;
}
// Bounds of the res_x x res_y vertices of a decompressed sub-grid.
inline Box3f subgrid_bounds(const SubGridVerts& w, uint32_t res_x, uint32_t res_y) {
  return subgrid_vertex_bounds(w, 0, res_x, 0, res_y);
}

// ---- half and quarter sub-grids ---------------------------------------------------------------
// Under the compressed-leaf BVH, a multi-leaf may give each of its sub-grids 2 or 4 child boxes
// (its parts), all referring to the same block, so that a ray decodes and tests only the part
// whose box it enters (not in the paper, whose section 5 gives each BVH leaf one whole sub-grid):
//   halves:   half h = cell rows 2h, 2h+1 (vertex rows 2h .. 2h+2): 2 of the 3 code groups,
//             2-3 of the 4 ray-space groups, 2 of the 4 rows;
//   quarters: quarter q = cells (2qx .. 2qx+1, 2qy .. 2qy+1), qx = q & 1, qy = q >> 1: its 3x3
//             vertices are one sub-grid corner and 8 displacement codes, i.e. one 8-lane decode,
//             and its 8 triangles one 8-wide test (intersect_subgrid_quarter below).
// The part of a partial sub-grid may hold no cell.
SLIM_INLINE void subgrid_half_rows(uint32_t half, uint32_t res_y, uint32_t& j0, uint32_t& j1) {
  j0 = 2 * half;
  j1 = std::min<uint32_t>(2 * half + 2, res_y - 1);
}
// Cells [i0, i1) x [j0, j1) of part `part` of `parts` (1, 2 or 4).
SLIM_INLINE void subgrid_part_cells(uint32_t parts, uint32_t part, uint32_t res_x, uint32_t res_y,
                                    uint32_t& i0, uint32_t& i1, uint32_t& j0, uint32_t& j1) {
  i0 = 0;
  i1 = res_x - 1;
  j0 = 0;
  j1 = res_y - 1;
  if (parts == 2) subgrid_half_rows(part, res_y, j0, j1);
  if (parts == 4) {
    i0 = 2 * (part & 1);
    i1 = std::min<uint32_t>(i0 + 2, res_x - 1);
    j0 = 2 * (part >> 1);
    j1 = std::min<uint32_t>(j0 + 2, res_y - 1);
  }
}
// Bounds of part `part` of `parts` (empty if it holds no cell).
inline Box3f subgrid_part_bounds(const SubGridVerts& w, uint32_t res_x, uint32_t res_y,
                                 uint32_t parts, uint32_t part) {
  uint32_t i0, i1, j0, j1;
  subgrid_part_cells(parts, part, res_x, res_y, i0, i1, j0, j1);
  if (i0 >= i1 || j0 >= j1) return Box3f();
  return subgrid_vertex_bounds(w, i0, i1 + 1, j0, j1 + 1);  // cells [i0, i1): vertices to i1
}

// The 9 vertices of a quarter: p[axis][lane], lanes 0-7 the 8 vertices other than the sub-grid
// corner in row-major order, lane 8 that corner (lanes 9-15 unused).
struct alignas(32) QuarterVerts {
  float p[3][16];
};

// Lane tables of the quarter test (built once, prim/lossy_subgrid.cpp).
struct QuarterTables {
  // Vertex rows position (5x5 layout) of lane l of quarter q (lane 8 = the corner).
  uint8_t position[4][9];
  // lane[q][b][a]: lane of quarter q holding local vertex (a, b), a, b in 0..2 (position
  // 5 * (2qy + b) + 2qx + a).
  uint8_t lane[4][3][3];
  // Triangle corners of the 8 triangles (A of cells (0,0) (1,0) (0,1) (1,1), then B) as lanes
  // of the quarter: the permutation of lanes 0-7 and the mask of triangles whose corner is the
  // sub-grid corner (lane 8). Corner 2 has a second form for flipped cells.
  alignas(32) int32_t perm[4][4][8];  // [q][corner 0, 1, 2, 2 flipped][triangle]
  uint32_t corner_mask[4][4];
  QuarterTables();
};
extern const QuarterTables kQuarterTables;

// Intersects the cells [i0, i1) x [j0, j1) of quarter q (subgrid_part_cells, not empty): the
// same triangles with the same corners in the same order as intersect_subgrid_rows, so the same
// bits for the same vertices. Closest hit: lowers ray.tfar and fills h; any hit: true at a hit.
template <bool kAny, class Stats>
SLIM_INLINE bool intersect_subgrid_quarter(const QuarterVerts& w, uint32_t q, uint32_t i0,
                                           uint32_t i1, uint32_t j0, uint32_t j1, uint32_t flips,
                                           TravRay& ray, SubGridHit& h, Stats& st) {
  using namespace simd;
  // Cells (c & 1, c >> 1) of the quarter that exist: lanes c (A) and c + 4 (B).
  const uint32_t cols = i1 - i0, rows = j1 - j0;  // 1 or 2 each (the part is not empty)
  const uint32_t cells = (cols == 2 ? 3u : 1u) * (rows == 2 ? 5u : 1u);
  const uint32_t valid = cells | (cells << 4);
  // Flip bits of the 4 cells, in lanes order.
  const uint32_t f4 = ((flips >> (4 * j0 + i0)) & 3) | (((flips >> (4 * j0 + 4 + i0)) & 3) << 2);
  // Ray space (core/watertight.h to_ray_space, the same operations as subgrid_to_ray_space).
  const WatertightRay& wr = ray.wt;
  const vfloat8 ox(wr.ox), oy(wr.oy), oz(wr.oz);
  const vfloat8 sx(wr.Sx), sy(wr.Sy), sz(wr.Sz);
  const vfloat8 ax = vfloat8::load(w.p[wr.kx]) - ox, ay = vfloat8::load(w.p[wr.ky]) - oy,
                az = vfloat8::load(w.p[wr.kz]) - oz;
  const vfloat8 rx = fnmadd(sx, az, ax), ry = fnmadd(sy, az, ay), rz = sz * az;
  const vfloat8 cx = vfloat8(w.p[wr.kx][8]) - ox, cy = vfloat8(w.p[wr.ky][8]) - oy,
                cz = vfloat8(w.p[wr.kz][8]) - oz;
  const vfloat8 crx = fnmadd(sx, cz, cx), cry = fnmadd(sy, cz, cy), crz = sz * cz;
  const QuarterTables& qt = kQuarterTables;
  auto corner = [&](int c) {
    const vint8 idx = vint8::loadu(qt.perm[q][c]);
    const vbool8 m = lanes_from_bits(qt.corner_mask[q][c]);
    return RayVertex<vfloat8>{select(m, crx, permute(rx, idx)), select(m, cry, permute(ry, idx)),
                              select(m, crz, permute(rz, idx))};
  };
  const RayVertex<vfloat8> V0 = corner(0), V1 = corner(1);
  RayVertex<vfloat8> V2 = corner(2);
  if (f4 & cells) {  // flipped cells: A p(i,j+1) | B p(i+1,j)
    const RayVertex<vfloat8> F = corner(3);
    const vbool8 m = lanes_from_bits(f4 | (f4 << 4));
    V2 = {select(m, F.x, V2.x), select(m, F.y, V2.y), select(m, F.z, V2.z)};
  }
  if constexpr (!std::is_same_v<Stats, NoStats>) st.prims(popcount(valid));
  vfloat8 t(0.0f), u(0.0f), v(0.0f);
  const uint32_t m = intersect_triangles(V0, V1, V2, valid, ray.tnear, ray.tfar, t, u, v);
  if (!m) return false;
  if constexpr (!kAny) {
    const int lane = detail::closest_lane8(m, t);
    ray.tfar = t[lane];
    const int c = lane & 3, a = c & 1, b = c >> 1;
    const auto& L = qt.lane[q];
    detail::finish_cell_hit(w.p[0], w.p[1], w.p[2], L[b][a], L[b][a + 1], L[b + 1][a],
                            L[b + 1][a + 1], i0 + uint32_t(a), j0 + uint32_t(b), lane >> 2,
                            (f4 >> c) & 1, ray.tfar, u[lane], v[lane], h);
  }
  return true;
}

// Fills the public hit from a sub-grid hit: per-grid u,v (section 5:
// grid_u = (triangle_u + gridX) / (gridResX - 1)), the input face, PrimKind::Grid.
SLIM_INLINE void record_grid_hit(const SubGridHit& h, const GridInfo& g, const uint32_t* faces,
                                 uint32_t grid_x, uint32_t grid_y, HitRecord& hit) {
  hit.t = h.t;
  hit.u = (float(grid_x + h.cell_x) + h.cu) / float(g.res_x - 1u);
  hit.v = (float(grid_y + h.cell_y) + h.cv) / float(g.res_y - 1u);
  hit.Ng = h.Ng;
  hit.geomID = g.geom;
  hit.primID = grid_face(g, faces, grid_x + h.cell_x, grid_y + h.cell_y, h.tri);
  hit.kind = PrimKind::Grid;
}

// 64-bit key of a sub-grid block for validate()'s "every primitive once" fingerprint; never 0.
inline uint64_t subgrid_key(const uint8_t* block, uint32_t bytes) { return nh_key(block, bytes); }

// ---- the uncompressed grid leaf (`grid`) -----------------------------------------------------

// A 5x5 sub-grid of a grid stored as float vertices (grid-ordered, row-major per grid): 16 B.
struct SubGridRef {
  uint32_t vertex;          // 4 B: index of the sub-grid's vertex (0,0) in the vertex array
  uint32_t grid;            // 4 B: GridInfo index
  uint16_t grid_x, grid_y;  // 4 B: position of vertex (0,0) in the grid
  uint16_t stride;          // 2 B: the grid's res_x (vertices per grid row)
  uint8_t res_x, res_y;     // 2 B: vertices of this sub-grid (2..5; < 5 at the right/bottom)
};
static_assert(sizeof(SubGridRef) == 16, "uncompressed sub-grid reference is 16 bytes");

// Leaf format: one SubGridRef per block (BvhScene, kBlockPrims = 1).
struct SubGridLeaf {
  struct Context {
    const Vec3f* vertices = nullptr;  // grid-ordered vertices of every grid
    const GridInfo* grids = nullptr;
    const GridHot* hot = nullptr;
    const uint32_t* faces = nullptr;  // face table
    const uint16_t* flips = nullptr;  // flip masks
    GridTableSizes sizes;             // scene files' structure check
  };
  static constexpr uint32_t kBlockPrims = 1;
  static constexpr uint32_t kBlockBytes = sizeof(SubGridRef);

  // Scene files' structure check: the grid, its vertex rows, flip mask and face table entries.
  static const char* check_block(const Context& ctx, const uint8_t* p) {
    SubGridRef b;
    std::memcpy(&b, p, sizeof b);
    if (!subgrid_res_ok(b.res_x, b.res_y)) return "sub-grid resolution outside 2..5";
    if (b.grid >= ctx.sizes.grids || b.grid >= ctx.sizes.hot)
      return "grid index beyond the grid tables (grid.table, grid.hot)";
    // decode() reads res_x vertices of rows 0 .. res_y-1, `stride` vertices apart.
    if (uint64_t(b.vertex) + uint64_t(b.res_y - 1) * b.stride + b.res_x > ctx.sizes.vertices)
      return "sub-grid vertices beyond the vertex array (grid.vertices)";
    const GridHot& h = ctx.hot[b.grid];
    if (h.flips != kNoFlips &&
        subgrid_flip_index(h, b.grid_x / kSubGridCells, b.grid_y / kSubGridCells,
                           (b.stride + kSubGridCells - 2) / kSubGridCells) >= ctx.sizes.flips)
      return "flip mask index beyond the flip table (grid.flips)";
    return check_grid_faces(ctx.grids[b.grid], ctx.sizes.faces, b.grid_x, b.grid_y, b.res_x,
                            b.res_y);
  }

  // Build-time source: the blocks, already encoded, and their bounds.
  struct Source {
    const SubGridRef* blocks = nullptr;
    const Box3f* bounds = nullptr;
  };
  static Box3f source_bounds(const Source& s, uint32_t i) { return s.bounds[i]; }
  static uint64_t source_key(const Source& s, uint32_t i) {
    return subgrid_key(reinterpret_cast<const uint8_t*>(&s.blocks[i]), kBlockBytes);
  }
  static void encode(const Source& s, const uint32_t* prims, uint32_t n, uint8_t* out) {
    std::memcpy(out, &s.blocks[prims[0]], kBlockBytes);
  }

  // Gathers the sub-grid's vertices (unused positions of partial sub-grids repeat the last
  // valid row/column, so that every lane holds a finite vertex).
  static SLIM_INLINE void decode(const Context& ctx, const SubGridRef& b, SubGridVerts& w) {
    // The 5 rows lie res_x * 12 bytes apart: start fetching all of them at once.
    for (uint32_t j = 0; j < b.res_y; ++j) {
      const Vec3f* row = ctx.vertices + b.vertex + uint64_t(j) * b.stride;
      simd::prefetch(row);
      simd::prefetch(reinterpret_cast<const uint8_t*>(row) + 59);
    }
    if (b.res_x == kSubGridRes) {
      // Whole rows: 15 floats each, deinterleaved in registers. A row's 8-lane store spills 3
      // lanes into the next row, which the next store overwrites (rows in ascending order).
      static_assert(sizeof(Vec3f) == 12, "rows are 15 packed floats");
      for (uint32_t j = 0; j < kSubGridRes; ++j) {
        const Vec3f* row =
            ctx.vertices + b.vertex + uint64_t(j < b.res_y ? j : b.res_y - 1) * b.stride;
        simd::vfloat8 x, y, z;
        simd::load_xyz5(&row->x, x, y, z);
        x.storeu(&w.p[0][5 * j]);
        y.storeu(&w.p[1][5 * j]);
        z.storeu(&w.p[2][5 * j]);
      }
      for (int k = 25; k < 32; ++k) w.p[0][k] = w.p[1][k] = w.p[2][k] = 0.0f;
      return;
    }
    for (uint32_t j = 0; j < kSubGridRes; ++j) {
      const Vec3f* row =
          ctx.vertices + b.vertex + uint64_t(j < b.res_y ? j : b.res_y - 1) * b.stride;
      for (uint32_t i = 0; i < kSubGridRes; ++i) {
        const Vec3f& p = row[i < b.res_x ? i : b.res_x - 1];
        w.p[0][5 * j + i] = p.x;
        w.p[1][5 * j + i] = p.y;
        w.p[2][5 * j + i] = p.z;
      }
    }
    for (int k = 25; k < 32; ++k) w.p[0][k] = w.p[1][k] = w.p[2][k] = 0.0f;
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context& ctx, const uint8_t* p, TravRay& ray,
                                    HitRecord& hit, Stats& st) {
    const auto& b = *reinterpret_cast<const SubGridRef*>(p);
    SubGridVerts w;
    decode(ctx, b, w);
    SubGridHit h;
    const uint32_t flips =
        subgrid_flips(ctx.hot[b.grid], ctx.flips, b.grid_x / kSubGridCells,
                      b.grid_y / kSubGridCells, (b.stride + kSubGridCells - 2) / kSubGridCells);
    if (!intersect_subgrid<kAny>(w, b.res_x, b.res_y, flips, ray, h, st)) return false;
    if constexpr (!kAny) record_grid_hit(h, ctx.grids[b.grid], ctx.faces, b.grid_x, b.grid_y, hit);
    return true;
  }

  template <class F>
  static void visit(const Context& ctx, const uint8_t* p, F&& fn) {
    const auto& b = *reinterpret_cast<const SubGridRef*>(p);
    SubGridVerts w;
    decode(ctx, b, w);
    fn(subgrid_bounds(w, b.res_x, b.res_y), subgrid_key(p, kBlockBytes));
  }
};

}  // namespace slim
