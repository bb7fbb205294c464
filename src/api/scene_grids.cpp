// Grid formats: `grid`, `lossy-grid`, `lossy-grid-e2` (C. Benthin, K. Vaidyanathan, S. Woop,
// "Ray Tracing Lossy Compressed Grid Primitives", Eurographics 2021 short papers).
//
// Scene::build: the meshes become grids (mesh/grids.h, section 3), each grid is cut into 5x5
// sub-grids, and a BVH8 is built over the sub-grids, one sub-grid per leaf (section 5: "Each BVH
// leaf references a single sub-grid"):
//   grid           SubGridRef (16 B) referencing grid-ordered float vertices (prim/subgrid.h)
//   lossy-grid     lossy sub-grids (prim/lossy_subgrid.h), displacement encoding 1
//   lossy-grid-e2  the same with encoding 2
//   lossy-grid-shared  68-byte shared-corner sub-grids (section 9, Leaf::SharedLossyGrids)
// Leaf::LossyGrids is the 128-byte Listing 1 sub-grid under any node layout.
// Leftovers (lone quads, unpaired triangles) are stored either as 2x2 sub-grids in the same BVH or
// as Tri4v triangle leaves in a second BVH traversed after the first, whichever the estimate below
// says is smaller (stat_details() figure `leftover_triangle_leaves`). With the layouts above the
// triangle leaves always win (a lone quad costs ~116 B as triangles, 140-180 B as a sub-grid);
// BuildOptions::grid_leftovers forces one.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <string>

#include "api/scene_grids.h"

#include "api/bvh_scene.h"
#include "api/registry.h"
#include "core/hash.h"
#include "mesh/grids.h"
#include "prim/lossy_subgrid.h"
#include "prim/subgrid.h"
#include "prim/triangles.h"
#include "slimrt/grids.h"

namespace slim {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

enum class Layout { Uncompressed, Listing1, Shared };

Layout layout_of(const BuildOptions& opt) {
  if (opt.leaf == Leaf::Grids) return Layout::Uncompressed;
  return opt.leaf == Leaf::SharedLossyGrids ? Layout::Shared : Layout::Listing1;
}

uint32_t block_bytes(Layout l) {
  switch (l) {
    case Layout::Uncompressed:
      return sizeof(SubGridRef);
    case Layout::Listing1:
      return sizeof(LossySubGrid);
    default:
      return sizeof(LossySubGridShared);
  }
}

// The conversion and the leftover decision, shared by every grid format and the statistics.
struct Prepared {
  GridSet gs;
  bool tri_leaves = false;          // leftovers as Tri4v leaves (else as 2x2 sub-grids)
  std::vector<uint64_t> sub_start;  // per grid: first sub-grid (grids.size() + 1 entries)
  uint64_t leftover_cells = 0, leftover_tris = 0;
  uint64_t duplicates = 0;  // leftover triangles (and 1-cell grids' triangles) dropped before
                            // they became 2x2 sub-grids
  double seconds = 0;
};

// Marks the exact duplicates among n items: items are grouped by their key (key_of(i), a
// std::array of words, compared exactly after grouping by its hash) and visited in the order
// `before` within a group; an item whose key equals a kept item k's is marked gone when
// dominated(i, k) (else it stays, and is no reference for later ones); other items are kept.
// Returns one flag per item (1 = gone).
template <class KeyOf, class Before, class Dominated>
std::vector<uint8_t> exact_duplicates(size_t n, KeyOf&& key_of, Before&& before,
                                      Dominated&& dominated) {
  using Key = decltype(key_of(uint32_t(0)));
  std::vector<std::pair<uint64_t, uint32_t>> order(n);  // (hash of the key, item)
  for (size_t i = 0; i < n; ++i) {
    const Key w = key_of(uint32_t(i));
    order[i] = {nh_key(w.data(), sizeof(w)), uint32_t(i)};
  }
  std::sort(order.begin(), order.end(), [&](const auto& x, const auto& y) {
    return x.first != y.first ? x.first < y.first : before(x.second, y.second);
  });
  std::vector<uint8_t> gone(n, 0);
  std::vector<std::pair<Key, uint32_t>> kept;  // keys kept with the current hash, and their item
  for (size_t i = 0; i < order.size();) {
    size_t j = i;
    kept.clear();
    for (; j < order.size() && order[j].first == order[i].first; ++j) {
      const uint32_t c = order[j].second;
      const Key w = key_of(c);
      auto same =
          std::find_if(kept.begin(), kept.end(), [&](const auto& k) { return k.first == w; });
      if (same == kept.end())
        kept.emplace_back(w, c);
      else if (dominated(c, same->second))
        gone[c] = 1;
    }
    i = j;
  }
  return gone;
}

// Leftover triangles about to become 2x2 sub-grids: exact duplicates (the same positions in any
// rotation, as TriangleSourceOps) are dropped, the one of the lowest (mesh, face) kept, so that
// a stack of coincident triangles is one sub-grid and not a subtree that every ray through it
// walks to the bottom (the sub-grid BVH has no duplicate test of its own; Tri4v leaves have).
// Returns the number dropped. Sorts the leftovers' keys: only on this non-default path.
uint64_t drop_duplicate_leftovers(GridSet& gs, const MeshList& meshes) {
  std::vector<LeftoverTriangle>& tris = gs.triangles;
  auto rotation = [&](const LeftoverTriangle& t, int r) {
    std::array<uint32_t, 9> w;
    for (int k = 0; k < 3; ++k)
      std::memcpy(&w[3 * k], &meshes[t.geom]->positions[t.v[(k + r) % 3]], 12);
    return w;
  };
  auto canonical = [&](uint32_t i) {
    return std::min({rotation(tris[i], 0), rotation(tris[i], 1), rotation(tris[i], 2)});
  };
  auto lower_face = [&](uint32_t a, uint32_t b) {
    return tris[a].geom != tris[b].geom ? tris[a].geom < tris[b].geom : tris[a].face < tris[b].face;
  };
  const std::vector<uint8_t> gone =
      exact_duplicates(tris.size(), canonical, lower_face, [](uint32_t, uint32_t) { return true; });
  size_t out = 0;
  for (size_t i = 0; i < tris.size(); ++i)
    if (!gone[i]) tris[out++] = tris[i];
  const uint64_t dropped = tris.size() - out;
  tris.resize(out);
  return dropped;
}

// 1-cell grids about to become 2x2 sub-grids: a cell with exactly the corner positions (c00, c10,
// c11, c01, in that order) and the diagonal of one kept before it is dropped, the one of the
// lowest (mesh, face of A) kept, unless the dropped one's face of B were lower (then both stay),
// so that a stack of coincident quads is one sub-grid, as drop_duplicate_leftovers does for
// triangles. Compacts the 1-cell grids' vertices, corners, faces and flips (they are the last
// grids of the set). Returns the number of triangles dropped (two per cell).
uint64_t drop_duplicate_cells(GridSet& gs, const MeshList& meshes) {
  const size_t first = gs.multi_cell_grids, n = gs.grids.size() - first;
  if (n < 2) return 0;
  auto corners = [&](uint32_t i) {
    const VertexGrid& g = gs.grids[first + i];
    std::array<uint32_t, 13> w;
    const uint32_t v[4] = {gs.vertex(g, 0, 0), gs.vertex(g, 1, 0), gs.vertex(g, 1, 1),
                           gs.vertex(g, 0, 1)};
    for (int k = 0; k < 4; ++k) std::memcpy(&w[3 * k], &meshes[g.geom]->positions[v[k]], 12);
    w[12] = gs.flipped(g, 0, 0) ? 1 : 0;
    return w;
  };
  auto face = [&](uint32_t i, int tri) {
    const VertexGrid& g = gs.grids[first + i];
    return std::pair{g.geom, gs.cell_face(g, 0, 0, tri)};
  };
  const std::vector<uint8_t> gone = exact_duplicates(
      n, corners, [&](uint32_t a, uint32_t b) { return face(a, 0) < face(b, 0); },
      [&](uint32_t c, uint32_t k) { return face(c, 1) >= face(k, 1); });
  const uint64_t dropped = 2 * uint64_t(std::count(gone.begin(), gone.end(), uint8_t(1)));
  if (!dropped) return 0;
  // Rebuild the tail of the set from the kept 1-cell grids (4 vertices and 1 cell each).
  const std::vector<VertexGrid> tail(gs.grids.begin() + first, gs.grids.end());
  const uint64_t v0 = tail.front().vertex_offset, c0 = tail.front().cell_offset;
  const std::vector<uint32_t> verts(gs.vertices.begin() + v0, gs.vertices.end());
  const std::vector<uint32_t> corner_of(
      gs.corner_of_vertex.empty() ? gs.corner_of_vertex.end() : gs.corner_of_vertex.begin() + v0,
      gs.corner_of_vertex.end());
  const std::vector<uint32_t> faces(gs.cell_faces.begin() + 2 * c0, gs.cell_faces.end());
  const std::vector<uint8_t> flips(gs.cell_flip.begin() + c0, gs.cell_flip.end());
  gs.grids.resize(first);
  gs.vertices.resize(v0);
  if (!gs.corner_of_vertex.empty()) gs.corner_of_vertex.resize(v0);
  gs.cell_faces.resize(2 * c0);
  gs.cell_flip.resize(c0);
  for (size_t i = 0; i < n; ++i) {
    if (gone[i]) continue;
    VertexGrid g = tail[i];
    const uint64_t vo = g.vertex_offset - v0, co = g.cell_offset - c0;
    g.vertex_offset = gs.vertices.size();
    g.cell_offset = gs.cell_flip.size();
    gs.vertices.insert(gs.vertices.end(), verts.begin() + vo, verts.begin() + vo + 4);
    if (!corner_of.empty())
      gs.corner_of_vertex.insert(gs.corner_of_vertex.end(), corner_of.begin() + vo,
                                 corner_of.begin() + vo + 4);
    gs.cell_faces.insert(gs.cell_faces.end(), faces.begin() + 2 * co, faces.begin() + 2 * co + 2);
    gs.cell_flip.push_back(flips[co]);
    gs.grids.push_back(g);
  }
  return dropped;
}

Prepared prepare(const MeshList& meshes, const BuildOptions& opt) {
  const Layout layout = layout_of(opt);
  auto t0 = Clock::now();
  Prepared p;
  p.gs = make_grids(meshes);
  GridSet& gs = p.gs;
  p.leftover_cells = gs.grids.size() - gs.multi_cell_grids;
  p.leftover_tris = gs.triangles.size();
  // Bytes per leftover primitive. As a 2x2 sub-grid: its block, its side-table entry, its 4
  // vertices when they live outside the block, and about 24 B of BVH. As triangles: a quarter of
  // a 176 B Tri4v block plus about 8 B of BVH per triangle (a lone quad is 2 triangles).
  const double as_grid =
      double(block_bytes(layout)) + sizeof(GridInfo) + (layout == Layout::Listing1 ? 0 : 48) + 24;
  const double as_tri = 176.0 / 4 + 8;
  p.tri_leaves = double(2 * p.leftover_cells + p.leftover_tris) * as_tri <
                 double(p.leftover_cells + p.leftover_tris) * as_grid;
  if (opt.grid_leftovers == GridLeftovers::Grids) p.tri_leaves = false;
  if (opt.grid_leftovers == GridLeftovers::Triangles) p.tri_leaves = true;
  if (p.tri_leaves) {
    // 1-cell grids -> their two triangles A = (c00, c10, c11), B = (c00, c11, c01).
    for (size_t gi = gs.multi_cell_grids; gi < gs.grids.size(); ++gi) {
      const VertexGrid& g = gs.grids[gi];
      const uint32_t c00 = gs.vertex(g, 0, 0), c10 = gs.vertex(g, 1, 0);
      const uint32_t c01 = gs.vertex(g, 0, 1), c11 = gs.vertex(g, 1, 1);
      gs.triangles.push_back({g.geom, gs.cell_face(g, 0, 0, 0), {c00, c10, c11}, {}});
      gs.triangles.push_back({g.geom, gs.cell_face(g, 0, 0, 1), {c00, c11, c01}, {}});
    }
    if (gs.multi_cell_grids < gs.grids.size()) {
      const VertexGrid& first = gs.grids[gs.multi_cell_grids];
      gs.vertices.resize(first.vertex_offset);
      if (!gs.corner_of_vertex.empty()) gs.corner_of_vertex.resize(first.vertex_offset);
      gs.cell_faces.resize(2 * first.cell_offset);
      gs.cell_flip.resize(first.cell_offset);
      gs.grids.resize(gs.multi_cell_grids);
    }
  } else {
    p.duplicates = drop_duplicate_cells(gs, meshes) + drop_duplicate_leftovers(gs, meshes);
    append_triangle_grids(gs, /*with_corners=*/false);
    gs.triangles.clear();
  }
  p.sub_start.assign(gs.grids.size() + 1, 0);
  for (size_t gi = 0; gi < gs.grids.size(); ++gi) {
    const VertexGrid& g = gs.grids[gi];
    p.sub_start[gi + 1] =
        p.sub_start[gi] + uint64_t(subgrids_along(g.res_x)) * subgrids_along(g.res_y);
  }
  p.seconds = seconds_since(t0);
  return p;
}

// Side table entry of a grid: the input face of each cell, affine in (x, y) when it can be
// (procedural scenes: one entry for the whole grid), else a table.
GridInfo grid_info(const GridSet& gs, const VertexGrid& g, std::vector<uint32_t>& faces) {
  GridInfo info;
  info.geom = g.geom;
  info.res_x = uint16_t(g.res_x);
  info.res_y = uint16_t(g.res_y);
  const uint32_t w = g.res_x - 1, h = g.res_y - 1;
  const int64_t f0 = gs.cell_face(g, 0, 0, 0);
  const int64_t dx = w > 1 ? int64_t(gs.cell_face(g, 1, 0, 0)) - f0 : 0;
  const int64_t dy = h > 1 ? int64_t(gs.cell_face(g, 0, 1, 0)) - f0 : 0;
  const int64_t ab = int64_t(gs.cell_face(g, 0, 0, 1)) - f0;
  auto fits = [](int64_t v) { return v >= INT32_MIN && v <= INT32_MAX; };
  bool affine = fits(dx) && fits(dy) && fits(ab);
  bool same_ab = true;
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      const int64_t a = gs.cell_face(g, x, y, 0), b = gs.cell_face(g, x, y, 1);
      affine = affine && a == f0 + int64_t(x) * dx + int64_t(y) * dy && b == a + ab;
      same_ab = same_ab && a == b;
    }
  if (affine) {
    info.face0 = uint32_t(f0);
    info.face_dx = int32_t(dx);
    info.face_dy = int32_t(dy);
    info.face_ab = int32_t(ab);
    return info;
  }
  if (faces.size() + 2 * uint64_t(w) * h >= 0xffffffffull)
    throw Error("grids: face table larger than 2^32 entries");
  info.face0 = uint32_t(faces.size());
  info.flags = same_ab ? kGridFaceTable1 : kGridFaceTable;
  for (uint32_t y = 0; y < h; ++y)
    for (uint32_t x = 0; x < w; ++x) {
      faces.push_back(gs.cell_face(g, x, y, 0));
      if (!same_ab) faces.push_back(gs.cell_face(g, x, y, 1));
    }
  return info;
}

// Side tables of all grids: GridInfo, GridHot (flip masks; lattices and exact vertices are filled
// by the lossy builder) and the face and flip tables.
void grid_tables(const Prepared& p, std::vector<GridInfo>& info, std::vector<GridHot>& hot,
                 std::vector<uint32_t>& faces, std::vector<uint16_t>& flips) {
  const GridSet& gs = p.gs;
  const size_t ng = gs.grids.size();
  info.resize(ng);
  hot.assign(ng, GridHot{});
  for (size_t gi = 0; gi < ng; ++gi) {
    const VertexGrid& g = gs.grids[gi];
    info[gi] = grid_info(gs, g, faces);
    const uint64_t cells = uint64_t(g.res_x - 1) * (g.res_y - 1);
    const uint8_t* f = gs.cell_flip.data() + g.cell_offset;
    if (std::none_of(f, f + cells, [](uint8_t x) { return x != 0; })) continue;
    if (flips.size() + p.sub_start[gi + 1] - p.sub_start[gi] >= kNoFlips)
      throw Error("grids: flip table larger than 2^32 entries");
    hot[gi].flips = uint32_t(flips.size());
    const uint32_t nsx = subgrids_along(g.res_x), nsy = subgrids_along(g.res_y);
    for (uint32_t sy = 0; sy < nsy; ++sy)
      for (uint32_t sx = 0; sx < nsx; ++sx) {
        uint16_t m = 0;
        for (uint32_t j = 0; j < kSubGridCells; ++j)
          for (uint32_t i = 0; i < kSubGridCells; ++i) {
            const uint32_t x = kSubGridCells * sx + i, y = kSubGridCells * sy + j;
            if (x + 1 < g.res_x && y + 1 < g.res_y && gs.flipped(g, x, y))
              m |= uint16_t(1u << (4 * j + i));
          }
        flips.push_back(m);
      }
  }
}

// The two triangles of each cell of a decoded sub-grid (w: rx x ry vertices), split as the leaves
// split them (flipped(i, j): cell (i, j) takes the other diagonal, subgrid.h), each with its input
// mesh and face (face(i, j, tri)).
template <class Flipped, class Face>
void append_subgrid_triangles(const SubGridVerts& w, uint32_t rx, uint32_t ry, uint32_t geom,
                              Flipped&& flipped, Face&& face, DecodedTriangles& out) {
  auto vert = [&](uint32_t i, uint32_t j) { return detail::subgrid_vertex(w, int(5 * j + i)); };
  for (uint32_t j = 0; j + 1 < ry; ++j)
    for (uint32_t i = 0; i + 1 < rx; ++i) {
      if (flipped(i, j)) {
        out.vertices.insert(out.vertices.end(), {vert(i, j), vert(i + 1, j), vert(i, j + 1)});
        out.vertices.insert(out.vertices.end(),
                            {vert(i + 1, j + 1), vert(i, j + 1), vert(i + 1, j)});
      } else {
        out.vertices.insert(out.vertices.end(), {vert(i, j), vert(i + 1, j), vert(i + 1, j + 1)});
        out.vertices.insert(out.vertices.end(), {vert(i, j), vert(i + 1, j + 1), vert(i, j + 1)});
      }
      for (uint32_t tri = 0; tri < 2; ++tri) {
        out.geom.push_back(geom);
        out.face.push_back(face(i, j, tri));
      }
    }
}

// A stored sub-grid block: its grid, the position of its vertex (0, 0) in the grid, its vertices
// and flip mask (bit 4 j + i: cell (i, j) flipped), read with the leaf's own accessors.
struct BlockPlace {
  uint32_t grid = 0, gx = 0, gy = 0, rx = 0, ry = 0, flips = 0;
};
BlockPlace place_of(const SubGridLeaf::Context& ctx, const SubGridRef& b) {
  return {b.grid,
          b.grid_x,
          b.grid_y,
          b.res_x,
          b.res_y,
          subgrid_flips(ctx.hot[b.grid], ctx.flips, b.grid_x / kSubGridCells,
                        b.grid_y / kSubGridCells, (b.stride + kSubGridCells - 2) / kSubGridCells)};
}
template <int kEnc>
BlockPlace place_of(const LossyContext& ctx, const LossySubGrid& b) {
  const uint32_t g = LossyGridLeaf<kEnc>::grid(ctx, b);
  return {g,
          b.grid_x,
          b.grid_y,
          uint32_t(b.res & 15),
          uint32_t(b.res >> 4),
          LossyGridLeaf<kEnc>::flips(ctx, b, g)};
}
template <int kEnc>
BlockPlace place_of(const LossyContext& ctx, const LossySubGridShared& b) {
  const uint32_t g = LossySharedLeaf<kEnc>::grid(ctx, b);
  uint32_t sx = 0, sy = 0;
  LossySharedLeaf<kEnc>::position(ctx.hot[g], b, sx, sy);
  return {g,
          kSubGridCells * sx,
          kSubGridCells * sy,
          uint32_t(b.res & 15),
          uint32_t(b.res >> 4),
          LossySharedLeaf<kEnc>::flips(ctx, b, g)};
}

// Block type and place of each grid leaf.
template <class Leaf>
struct GridBlock;
template <>
struct GridBlock<SubGridLeaf> {
  using Type = SubGridRef;
  static BlockPlace place(const SubGridLeaf::Context& ctx, const SubGridRef& b) {
    return place_of(ctx, b);
  }
};
template <int kEnc>
struct GridBlock<LossyGridLeaf<kEnc>> {
  using Type = LossySubGrid;
  static BlockPlace place(const LossyContext& ctx, const LossySubGrid& b) {
    return place_of<kEnc>(ctx, b);
  }
};
template <int kEnc>
struct GridBlock<LossySharedLeaf<kEnc>> {
  using Type = LossySubGridShared;
  static BlockPlace place(const LossyContext& ctx, const LossySubGridShared& b) {
    return place_of<kEnc>(ctx, b);
  }
};

// The grid formats' scene: a BVH over sub-grid blocks, the side tables the blocks refer to, and
// optionally a second BVH of leftover triangles.
template <class Leaf>
class GridScene final : public BvhScene<Leaf> {
 public:
  std::vector<GridInfo> grid_table;
  std::vector<GridHot> hot;
  std::vector<uint32_t> face_table;
  std::vector<uint16_t> flips;  // flip masks of the sub-grids of grids with flipped cells
  // Uncompressed: grid vertices; shared layout: corner lattices. On huge pages (a kept
  // LargeVector): a sub-grid reads 5 rows a whole grid row apart, and with 4 KB pages the page
  // walks of the 201 MB of canyon:4096's vertices made `grid` 4x slower than `lossy-grid` on
  // primary rays (2.8-3.1 MRays/s against 11.4).
  LargeVector<Vec3f, true> vertices;
  LargeVector<Vec3f, true> exact;     // lossy: exact vertices
  std::vector<uint32_t> corner_grid;  // shared layout: grid of each 16-corner chunk
  std::unique_ptr<BvhScene<Tri4v>> tris;
  // An opened scene's table sizes (its vectors stay empty, the context points into the mapping).
  std::array<uint64_t, 8> opened_count{};

  void intersect(TravRay& ray, HitRecord& hit) const override {
    BvhScene<Leaf>::intersect(ray, hit);
    if (tris) tris->intersect(ray, hit);
  }
  bool occluded(TravRay& ray) const override {
    return BvhScene<Leaf>::occluded(ray) || (tris && tris->occluded(ray));
  }
  void intersect_counted(TravRay& ray, HitRecord& hit, TraversalCounters& c) const override {
    BvhScene<Leaf>::intersect_counted(ray, hit, c);
    if (tris) tris->intersect_counted(ray, hit, c);
  }
  // Scene files: the sub-grid BVH, the side tables (an opened scene's context points into the
  // mapping; the vectors above stay empty) and the leftover triangles' BVH.
  void sections(SectionVisitor& v) override {
    this->bvh_sections(v, "");
    auto& c = this->ctx;
    size_t slot = 0;
    // Returns the table's element count (the structure check bounds the blocks' references by
    // these, GridTableSizes).
    auto table = [&](const std::string& name, const auto& vec, auto*& ptr) {
      using T = std::remove_cvref_t<decltype(*ptr)>;
      uint64_t& opened = opened_count.at(slot++);
      const T* d = vec.size() ? vec.data() : ptr;
      uint64_t n = vec.size() ? vec.size() : opened;
      v.array(name, d, n);
      if (!v.saving()) {
        ptr = d;
        opened = n;
      }
      return n;
    };
    GridTableSizes& n = c.sizes;
    n.grids = table("grid.table", grid_table, c.grids);
    n.hot = table("grid.hot", hot, c.hot);
    n.faces = table("grid.faces", face_table, c.faces);
    n.flips = table("grid.flips", flips, c.flips);
    if constexpr (std::is_same_v<typename Leaf::Context, LossyContext>) {
      n.exact = table("grid.exact", exact, c.exact);
      n.corners = table("grid.corners", vertices, c.corners);
      n.corner_grid = table("grid.corner_grid", corner_grid, c.corner_grid);
      struct {
        uint32_t grid_count;
        int32_t bias;
        uint32_t parts, reserved;
      } k{c.grid_count, c.bias, c.parts, 0};
      v.pod("grid.params", k);
      c.grid_count = k.grid_count;
      c.bias = k.bias;
      c.parts = k.parts;
    } else {
      n.vertices = table("grid.vertices", vertices, c.vertices);
    }
    uint32_t has_tris[2] = {tris ? 1u : 0u, 0};
    v.pod("grid.has_leftover_triangles", has_tris);
    if (!v.saving() && has_tris[0]) tris = std::make_unique<BvhScene<Tri4v>>();
    if (tris) tris->bvh_sections(v, "tris.");
  }
  // The leftover triangles' BVH, the grid parameters, then the sub-grid BVH with the blocks'
  // checks (prim/subgrid.h, prim/lossy_subgrid.h: every side-table entry a block reaches).
  void check_opened(bool deep) const override {
    if (tris) tris->check_bvh("tris.", deep);
    if constexpr (std::is_same_v<typename Leaf::Context, LossyContext>) {
      const LossyContext& c = this->ctx;
      if (deep && c.parts != 1 && c.parts != 2 && c.parts != 4)
        throw SectionFault{"grid.params", 8,
                           "sub-grid parts " + std::to_string(c.parts) + " (1, 2 or 4)"};
      if (deep && (c.grid_count > c.sizes.hot || c.grid_count > c.sizes.grids))
        throw SectionFault{"grid.params", 0,
                           "grid count " + std::to_string(c.grid_count) +
                               " beyond the grid tables (grid.table, grid.hot)"};
    }
    this->check_bvh("", deep);
  }

  bool validate(std::string* why) const override {
    if (!BvhScene<Leaf>::validate(why)) return false;
    if (tris && !tris->validate(why)) {
      if (why) *why = "leftover triangles: " + *why;
      return false;
    }
    return true;
  }

  // Every block the BVH's leaves hold (each once), decoded as the leaves decode it, in leaf order;
  // then the leftover triangles.
  std::optional<DecodedTriangles> decoded_triangles() const override {
    using Block = typename GridBlock<Leaf>::Type;
    const typename Leaf::Context& c = this->ctx;
    DecodedTriangles out;
    auto append = [&](const uint8_t* p) {
      const Block& b = *reinterpret_cast<const Block*>(p);
      const BlockPlace at = GridBlock<Leaf>::place(c, b);
      SubGridVerts w;
      Leaf::decode(c, b, w);
      append_subgrid_triangles(
          w, at.rx, at.ry, c.grids[at.grid].geom,
          [&](uint32_t i, uint32_t j) { return (at.flips >> (4 * j + i)) & 1; },
          [&](uint32_t i, uint32_t j, uint32_t tri) {
            return grid_face(c.grids[at.grid], c.faces, at.gx + i, at.gy + j, tri);
          },
          out);
    };
    // The walk of validate(): the boxes are filled in as it expects them.
    auto leaf = [&](const uint8_t* p, Box3f& bounds, std::string*) {
      Leaf::visit(c, p, [&](const Box3f& box, uint64_t) { bounds.extend(box); });
      append(p);
      return true;
    };
    MultiLeafValidator multi;
    if constexpr (HasMultiLeafLayout<Leaf>)
      multi = [&](const uint8_t* data, uint32_t k, uint32_t i, Box3f& bounds, std::string*) {
        Leaf::visit_in_multileaf(c, data, k, int(i),
                                 [&](const Box3f& box, uint64_t) { bounds.extend(box); });
        // A block split into several children (sub-grid parts) is decoded once.
        if (Leaf::primary_part(c, i)) append(data + uint64_t(i / c.parts) * Leaf::kBlockBytes);
        return true;
      };
    std::string why;
    if (!validate_bvh8(this->bvh, leaf, &why, multi))
      throw Error("grid scene: its leaves do not decode: " + why);
    if (tris) {
      auto tri_leaf = [&](const uint8_t* p, Box3f& bounds, std::string*) {
        Tri4v::visit(tris->ctx, p, [&](const Box3f& box, uint64_t) { bounds.extend(box); });
        const auto* b = reinterpret_cast<const Tri4vBlock*>(p);
        for (int l = 0; l < detail::distinct_lanes(b->prim); ++l) {
          for (int k = 0; k < 3; ++k)
            out.vertices.push_back(Vec3f(b->v[k][0][l], b->v[k][1][l], b->v[k][2][l]));
          out.geom.push_back(b->geom[l]);
          out.face.push_back(b->prim[l]);
        }
        return true;
      };
      if (!validate_bvh8(tris->bvh, tri_leaf, &why))
        throw Error("grid scene: its leftover triangles do not decode: " + why);
    }
    return out;
  }
};

std::unique_ptr<BvhScene<Tri4v>> build_leftover_triangles(const GridSet& gs, const MeshList& meshes,
                                                          const BuildOptions& opt) {
  const uint64_t n = gs.triangles.size();
  if (n == 0) return nullptr;
  if (3 * n >= 0xffffffffull) throw Error("grids: too many leftover triangles");
  std::vector<Vec3f> v(3 * n);
  std::vector<uint32_t> idx(3 * n), geom(n), prim(n);
  for (uint64_t t = 0; t < n; ++t) {
    const LeftoverTriangle& lt = gs.triangles[t];
    for (int k = 0; k < 3; ++k) {
      v[3 * t + k] = meshes[lt.geom]->positions[lt.v[k]];
      idx[3 * t + k] = uint32_t(3 * t + k);
    }
    geom[t] = lt.geom;
    prim[t] = lt.face;
  }
  auto s = std::make_unique<BvhScene<Tri4v>>();
  TriangleSource src{v.data(), idx.data(), geom.data(), prim.data()};
  BvhScene<Tri4v>::Bvh2Hooks hooks;  // after the grids' BVH: phases "bvh2 leftovers", ...
  hooks.ends_prepare = false;
  hooks.phase_suffix = " leftovers";
  s->build(src, uint32_t(n), opt, hooks);
  return s;
}

// Error figures of the lossy formats (paper Table 3), per sub-grid, reduced at the end.
struct SubGridError {
  double sum_sq = 0;   // squared errors of the grid vertices this sub-grid owns
  float max_err = 0;   // largest vertex error
  float diag_pct = 0;  // max_err / box diagonal, %
  uint32_t owned = 0;  // grid vertices owned (each grid vertex counted once over the grid)
};

struct ErrorTotals {
  double rms = 0, max_error = 0, diag_avg_pct = 0, diag_max_pct = 0;
  uint64_t vertices = 0, subgrids = 0;
};

// Instead of a scene: the error figures and, optionally, the decoded triangles.
struct Extract {
  ErrorTotals errors;
  GridTriangles* triangles = nullptr;
};

// Appends the triangles of every sub-grid (decoded by `decode`) and the leftover triangles.
template <class Decode>
void extract_triangles(const Prepared& p, const MeshList& meshes,
                       const std::vector<GridInfo>& table, const uint32_t* faces, Decode&& decode,
                       GridTriangles& out) {
  for (size_t gi = 0; gi < p.gs.grids.size(); ++gi) {
    const VertexGrid& g = p.gs.grids[gi];
    const uint32_t nsx = subgrids_along(g.res_x);
    for (uint64_t si = p.sub_start[gi]; si < p.sub_start[gi + 1]; ++si) {
      const uint32_t sx = uint32_t((si - p.sub_start[gi]) % nsx),
                     sy = uint32_t((si - p.sub_start[gi]) / nsx);
      const uint32_t gx = kSubGridCells * sx, gy = kSubGridCells * sy;
      const uint32_t rx = std::min(kSubGridRes, g.res_x - gx),
                     ry = std::min(kSubGridRes, g.res_y - gy);
      SubGridVerts w;
      decode(si, w);
      append_subgrid_triangles(
          w, rx, ry, g.geom,
          [&](uint32_t i, uint32_t j) { return p.gs.flipped(g, gx + i, gy + j); },
          [&](uint32_t i, uint32_t j, uint32_t tri) {
            return grid_face(table[gi], faces, gx + i, gy + j, tri);
          },
          out);
    }
  }
  for (const LeftoverTriangle& t : p.gs.triangles) {
    for (uint32_t v : t.v) out.vertices.push_back(meshes[t.geom]->positions[v]);
    out.geom.push_back(t.geom);
    out.face.push_back(t.face);
  }
}

ErrorTotals reduce_errors(const std::vector<SubGridError>& e) {
  ErrorTotals t;
  double sum_sq = 0, sum_pct = 0;
  for (const SubGridError& s : e) {
    sum_sq += s.sum_sq;
    t.vertices += s.owned;
    t.max_error = std::max(t.max_error, double(s.max_err));
    sum_pct += s.diag_pct;
    t.diag_max_pct = std::max(t.diag_max_pct, double(s.diag_pct));
  }
  t.subgrids = e.size();
  t.rms = t.vertices ? std::sqrt(sum_sq / double(t.vertices)) : 0.0;
  t.diag_avg_pct = e.empty() ? 0.0 : sum_pct / double(e.size());
  return t;
}

// Calls fn(sub-grid index, grid index, sx, sy) for every sub-grid, in parallel.
template <class F>
void for_each_subgrid(const Prepared& p, F&& fn) {
  const uint64_t n = p.sub_start.back();
  tbb::parallel_for(
      tbb::blocked_range<uint64_t>(0, n, 256), [&](const tbb::blocked_range<uint64_t>& r) {
        size_t gi = size_t(std::upper_bound(p.sub_start.begin(), p.sub_start.end(), r.begin()) -
                           p.sub_start.begin()) -
                    1;
        for (uint64_t s = r.begin(); s != r.end(); ++s) {
          while (s >= p.sub_start[gi + 1]) ++gi;
          const VertexGrid& g = p.gs.grids[gi];
          const uint64_t local = s - p.sub_start[gi];
          const uint32_t nsx = subgrids_along(g.res_x);
          fn(s, gi, uint32_t(local % nsx), uint32_t(local / nsx));
        }
      });
}

// The original vertices of a sub-grid and, for the lossy formats, its exact-vertex indices.
void gather_subgrid(const Prepared& p, const MeshList& meshes, const ExactPositions* ex, size_t gi,
                    uint32_t sx, uint32_t sy, SubGridInput& in) {
  const VertexGrid& g = p.gs.grids[gi];
  const uint32_t gx = kSubGridCells * sx, gy = kSubGridCells * sy;
  in.res_x = std::min(kSubGridRes, g.res_x - gx);
  in.res_y = std::min(kSubGridRes, g.res_y - gy);
  const Vec3f* pos = meshes[g.geom]->positions.data();
  const uint32_t* ex_begin = nullptr;
  const uint32_t* ex_end = nullptr;
  if (ex && gi < ex->start.size() - 1 && ex->count(gi)) {
    ex_begin = ex->pos.data() + ex->start[gi];
    ex_end = ex->pos.data() + ex->start[gi + 1];
  }
  for (uint32_t j = 0; j < kSubGridRes; ++j)
    for (uint32_t i = 0; i < kSubGridRes; ++i) {
      const uint32_t k = 5 * j + i;
      in.exact[k] = kNotExact;
      if (i >= in.res_x || j >= in.res_y) {
        in.v[k] = in.v[5 * std::min(j, in.res_y - 1) + std::min(i, in.res_x - 1)];
        continue;
      }
      in.v[k] = pos[p.gs.vertex(g, gx + i, gy + j)];
      if (ex_begin) {
        const uint32_t at = (gy + j) * g.res_x + gx + i;
        const uint32_t* it = std::lower_bound(ex_begin, ex_end, at);
        if (it != ex_end && *it == at) in.exact[k] = uint32_t(it - ex_begin);
      }
    }
}

SubGridError measure_error(const SubGridInput& in, const SubGridVerts& w, const VertexGrid& g,
                           uint32_t gx, uint32_t gy) {
  SubGridError e;
  Box3f box;
  for (uint32_t j = 0; j < in.res_y; ++j)
    for (uint32_t i = 0; i < in.res_x; ++i) {
      const Vec3f& o = in.v[5 * j + i];
      box.extend(o);
      const double dx = double(w.p[0][5 * j + i]) - o.x, dy = double(w.p[1][5 * j + i]) - o.y,
                   dz = double(w.p[2][5 * j + i]) - o.z;
      const double sq = dx * dx + dy * dy + dz * dz;
      e.max_err = std::max(e.max_err, float(std::sqrt(sq)));
      // Each grid vertex once: a sub-grid owns its last column/row only at the grid's border.
      const bool own = (i + 1 < in.res_x || gx + i + 1 == g.res_x) &&
                       (j + 1 < in.res_y || gy + j + 1 == g.res_y);
      if (own) {
        e.sum_sq += sq;
        e.owned++;
      }
    }
  const float diag = length(box.size());
  e.diag_pct = diag > 0 ? 100.0f * e.max_err / diag : 0.0f;
  return e;
}

void add_grid_details(const Prepared& p, SceneStatsAndDetails& st, double encode_s) {
  const GridConversionFigures& f = p.gs.figures;
  uint64_t full = 0, subgrids = p.sub_start.back();
  for (size_t gi = 0; gi < p.gs.grids.size(); ++gi) {
    const VertexGrid& g = p.gs.grids[gi];
    full += uint64_t((g.res_x - 1) / kSubGridCells) * ((g.res_y - 1) / kSubGridCells);
  }
  auto& d = st.details;
  d.emplace_back("grids", double(f.grids));
  d.emplace_back("grid_cells", double(f.grid_cells));
  d.emplace_back("mean_grid_cells", f.grids ? double(f.grid_cells) / double(f.grids) : 0.0);
  d.emplace_back("largest_grid_cells", double(f.largest_grid_cells));
  d.emplace_back("paired_cells", double(f.paired_cells));
  d.emplace_back("subgrids", double(subgrids));
  d.emplace_back("full_subgrids", double(full));
  d.emplace_back("full_subgrid_triangle_pct",
                 f.triangles ? 100.0 * double(full) * 32.0 / double(f.triangles) : 0.0);
  d.emplace_back("leftover_cells", double(p.leftover_cells));
  d.emplace_back("leftover_triangles", double(p.leftover_tris));
  d.emplace_back("leftover_triangle_leaves", p.tri_leaves ? 1.0 : 0.0);
  d.emplace_back("conversion_s", p.seconds);
  d.emplace_back("encode_s", encode_s);
}

template <class Leaf>
void finish_scene(GridScene<Leaf>& s, const Prepared& p, const MeshList& meshes,
                  const BuildOptions& opt) {
  s.tris = build_leftover_triangles(p.gs, meshes, opt);
  // Exact duplicates among the leftover triangles, dropped by their BVH or before they became
  // 2x2 sub-grids.
  double duplicates = double(p.duplicates);
  if (s.tris)
    for (const auto& [k, v] : s.tris->stats.details)
      if (k == "duplicate_triangles") duplicates += v;
  s.stats.details.emplace_back("duplicate_triangles", duplicates);
  if (s.tris) {
    s.mem.bvh_bytes += s.tris->mem.bvh_bytes;
    s.mem.geometry_bytes += s.tris->mem.geometry_bytes;
    s.bounds = s.bvh.root ? merge(s.bounds, s.tris->bounds) : s.tris->bounds;
  }
  s.mem.other_bytes += s.grid_table.size() * sizeof(GridInfo) + s.hot.size() * sizeof(GridHot) +
                       s.face_table.size() * 4 + s.flips.size() * 2 +
                       s.corner_grid.size() * sizeof(uint32_t);
  s.stats.input_faces = p.gs.figures.input_faces;
  s.stats.triangles = p.gs.figures.triangles;
  s.stats.skipped_faces = p.gs.figures.skipped_faces;
  s.mem.triangles = p.gs.figures.triangles;
}

// One sub-grid per leaf (section 5).
BuildOptions subgrid_bvh_options(const BuildOptions& opt) {
  BuildOptions o = opt;
  o.max_leaf_size = 1;
  return o;
}

std::unique_ptr<Scene::Impl> build_uncompressed(Prepared& p, const MeshList& meshes,
                                                const BuildOptions& opt,
                                                Extract* extract = nullptr) {
  auto t0 = Clock::now();
  auto s = std::make_unique<GridScene<SubGridLeaf>>();
  const GridSet& gs = p.gs;
  const size_t ng = gs.grids.size();
  const uint64_t nv =
      ng ? gs.grids.back().vertex_offset + uint64_t(gs.grids.back().res_x) * gs.grids.back().res_y
         : 0;
  if (nv >= 0xffffffffull) throw Error("grid: more than 2^32 - 1 grid vertices");
  grid_tables(p, s->grid_table, s->hot, s->face_table, s->flips);
  s->vertices.resize(nv);
  for (const VertexGrid& g : gs.grids) {
    const Vec3f* pos = meshes[g.geom]->positions.data();
    for (uint64_t i = 0; i < uint64_t(g.res_x) * g.res_y; ++i)
      s->vertices[g.vertex_offset + i] = pos[gs.vertices[g.vertex_offset + i]];
  }
  s->ctx = {s->vertices.data(), s->grid_table.data(), s->hot.data(), s->face_table.data(),
            s->flips.data()};
  const uint64_t n = p.sub_start.back();
  std::vector<SubGridRef> blocks(n);
  std::vector<Box3f> bounds(n);
  for_each_subgrid(p, [&](uint64_t si, size_t gi, uint32_t sx, uint32_t sy) {
    const VertexGrid& g = gs.grids[gi];
    SubGridRef& b = blocks[si];
    const uint32_t gx = kSubGridCells * sx, gy = kSubGridCells * sy;
    b.vertex = uint32_t(g.vertex_offset + uint64_t(gy) * g.res_x + gx);
    b.grid = uint32_t(gi);
    b.grid_x = uint16_t(gx);
    b.grid_y = uint16_t(gy);
    b.stride = uint16_t(g.res_x);
    b.res_x = uint8_t(std::min(kSubGridRes, g.res_x - gx));
    b.res_y = uint8_t(std::min(kSubGridRes, g.res_y - gy));
    SubGridVerts w;
    SubGridLeaf::decode(s->ctx, b, w);
    bounds[si] = subgrid_bounds(w, b.res_x, b.res_y);
  });
  const double encode_s = seconds_since(t0);
  if (extract) {
    if (extract->triangles)
      extract_triangles(
          p, meshes, s->grid_table, s->face_table.data(),
          [&](uint64_t si, SubGridVerts& w) { SubGridLeaf::decode(s->ctx, blocks[si], w); },
          *extract->triangles);
    return nullptr;
  }
  SubGridLeaf::Source src{blocks.data(), bounds.data()};
  s->build(src, uint32_t(n), subgrid_bvh_options(opt));
  s->mem.geometry_bytes += s->vertices.size() * sizeof(Vec3f);
  add_grid_details(p, s->stats, encode_s);
  s->stats.details.emplace_back("grid_vertices", double(nv));
  finish_scene(*s, p, meshes, opt);
  return s;
}

// Lossy formats: the exact vertices, the blocks, their bounds and the error figures.
template <class Leaf, class Block>
std::unique_ptr<Scene::Impl> build_lossy(Prepared& p, const MeshList& meshes,
                                         const BuildOptions& opt, int enc, bool shared_corners,
                                         Extract* extract) {
  auto t0 = Clock::now();
  auto s = std::make_unique<GridScene<Leaf>>();
  const GridSet& gs = p.gs;
  const size_t ng = gs.grids.size();
  // BuildOptions::lattice_box: the bias of the whole input, and the chunk's boundary vertices
  // (its cuts among them) stored exactly, so that chunks built apart meet without a crack.
  const Box3f lattice_box = lattice_box_of(meshes, opt);
  Box3f scene_box = lattice_box;
  if (lattice_box.empty())
    for (const MeshView* m : meshes) scene_box.extend(m->bounds());
  const int bias = displacement_bias(scene_box.empty() ? 1.0f : length(scene_box.size()));
  const ExactPositions ex = find_exact_positions(gs, meshes, !lattice_box.empty());
  grid_tables(p, s->grid_table, s->hot, s->face_table, s->flips);
  s->exact.resize(ex.pos.size());
  for (size_t gi = 0; gi < ng; ++gi) {
    const VertexGrid& g = gs.grids[gi];
    if (ex.count(gi) > kMaxExactIndex + 1)
      throw Error("lossy grids: a grid with more than 2^18 shared vertices");
    s->hot[gi].exact = uint32_t(ex.start[gi]);
    const Vec3f* pos = meshes[g.geom]->positions.data();
    for (uint64_t e = ex.start[gi]; e < ex.start[gi + 1]; ++e) {
      const uint32_t at = ex.pos[e];
      s->exact[e] = pos[gs.vertex(g, at % g.res_x, at / g.res_x)];
    }
  }
  if (shared_corners) {
    uint64_t corners = 0;  // reserved exactly: the kept buffer is what the memory figures count
    for (const VertexGrid& g : gs.grids)
      corners += uint64_t(subgrids_along(g.res_x) + 1) * (subgrids_along(g.res_y) + 1);
    if (corners >= 0xffffffffull) throw Error("lossy grids: more than 2^32 - 1 sub-grid corners");
    s->vertices.reserve(corners);
    for (size_t gi = 0; gi < ng; ++gi) {
      const VertexGrid& g = gs.grids[gi];
      const uint32_t nsx = subgrids_along(g.res_x), nsy = subgrids_along(g.res_y);
      s->hot[gi].lattice_first = uint32_t(s->vertices.size());
      s->hot[gi].lattice_row = nsx + 1;
      const Vec3f* pos = meshes[g.geom]->positions.data();
      for (uint32_t ly = 0; ly <= nsy; ++ly)
        for (uint32_t lx = 0; lx <= nsx; ++lx)
          s->vertices.push_back(pos[gs.vertex(g, std::min(kSubGridCells * lx, g.res_x - 1),
                                              std::min(kSubGridCells * ly, g.res_y - 1))]);
    }
    // The grid of each chunk's first corner (LossySharedLeaf::grid): lattices lie in grid order.
    const uint64_t chunks = (s->vertices.size() >> kCornerChunkShift) + 1;
    s->corner_grid.resize(chunks);
    uint32_t gi = 0;
    for (uint64_t k = 0; k < chunks; ++k) {
      const uint64_t c = k << kCornerChunkShift;
      while (gi + 1 < ng && s->hot[gi + 1].lattice_first <= c) ++gi;
      s->corner_grid[k] = gi;
    }
    s->ctx.corner_grid = s->corner_grid.data();
    s->ctx.grid_count = uint32_t(ng);
  }
  s->ctx.grids = s->grid_table.data();
  s->ctx.hot = s->hot.data();
  s->ctx.faces = s->face_table.data();
  s->ctx.flips = s->flips.data();
  s->ctx.exact = s->exact.data();
  s->ctx.corners = s->vertices.data();
  s->ctx.bias = bias;

  const uint64_t n = p.sub_start.back();
  std::vector<Block> blocks(n);
  std::vector<Box3f> bounds(n);
  // Sub-grid parts as multi-leaf children under the compressed-leaf BVH (prim/subgrid.h):
  // quarters by default, for both layouts. Quarters are faster than halves (W2 / embree-tri on
  // torus:1024 0.96 against 0.81, terrain 1.18 / 1.14, canyon 1.02 / 1.00) and keep the 68-byte
  // layout at 4.4 bytes/triangle. BuildOptions::grid_parts sets another split.
  uint32_t parts = 1;
  if (opt.nodes == Nodes::CompressedLeaf) parts = opt.grid_parts ? uint32_t(opt.grid_parts) : 4;
  std::vector<Box3f> part_bounds(parts > 1 ? parts * n : 0);
  s->ctx.parts = parts;
  std::vector<SubGridError> errs(n);
  for_each_subgrid(p, [&](uint64_t si, size_t gi, uint32_t sx, uint32_t sy) {
    const VertexGrid& g = gs.grids[gi];
    SubGridInput in;
    gather_subgrid(p, meshes, &ex, gi, sx, sy, in);
    Block& b = blocks[si];
    b = Block{};
    if (enc == 1)
      encode_subgrid<1>(in, bias, b.displ);
    else
      encode_subgrid<2>(in, bias, b.displ);
    b.res = uint8_t(in.res_x | (in.res_y << 4));
    const uint32_t gx = kSubGridCells * sx, gy = kSubGridCells * sy;
    if constexpr (std::is_same_v<Block, LossySubGrid>) {
      const uint32_t rx = in.res_x, ry = in.res_y;
      b.corner[0] = in.v[0];
      b.corner[1] = in.v[rx - 1];
      b.corner[2] = in.v[5 * (ry - 1)];
      b.corner[3] = in.v[5 * (ry - 1) + rx - 1];
      b.object_id = g.geom;
      b.primitive_id = uint32_t(gi);
      b.grid_x = uint16_t(gx);
      b.grid_y = uint16_t(gy);
      b.grid_res_x = uint16_t(g.res_x);
      b.grid_res_y = uint16_t(g.res_y);
    } else {
      b.corner = s->hot[gi].lattice_first + sy * s->hot[gi].lattice_row + sx;
    }
    SubGridVerts w;
    Leaf::decode(s->ctx, b, w);
    bounds[si] = subgrid_bounds(w, in.res_x, in.res_y);
    if (parts > 1)
      for (uint32_t k = 0; k < parts; ++k)
        part_bounds[parts * si + k] = subgrid_part_bounds(w, in.res_x, in.res_y, parts, k);
    errs[si] = measure_error(in, w, g, gx, gy);
  });
  const double encode_s = seconds_since(t0);
  const ErrorTotals et = reduce_errors(errs);
  errs = {};
  if (extract) {
    extract->errors = et;
    if (extract->triangles)
      extract_triangles(
          p, meshes, s->grid_table, s->face_table.data(),
          [&](uint64_t si, SubGridVerts& w) { Leaf::decode(s->ctx, blocks[si], w); },
          *extract->triangles);
    return nullptr;
  }
  LossySource src{reinterpret_cast<const uint8_t*>(blocks.data()), sizeof(Block), bounds.data(),
                  parts, parts > 1 ? part_bounds.data() : nullptr};
  s->build(src, uint32_t(n), subgrid_bvh_options(opt));
  s->mem.geometry_bytes += (s->vertices.size() + s->exact.size()) * sizeof(Vec3f);
  add_grid_details(p, s->stats, encode_s);
  auto& d = s->stats.details;
  d.emplace_back("rms_error", et.rms);
  d.emplace_back("max_error", et.max_error);
  d.emplace_back("diag_avg_pct", et.diag_avg_pct);
  d.emplace_back("diag_max_pct", et.diag_max_pct);
  d.emplace_back("exact_vertices", double(s->exact.size()));
  d.emplace_back("shared_corners", double(s->vertices.size()));
  d.emplace_back("displacement_bias", double(bias));
  d.emplace_back("block_bytes", double(sizeof(Block)));
  d.emplace_back("subgrid_parts", double(parts));
  s->error_bound = et.max_error;
  finish_scene(*s, p, meshes, opt);
  return s;
}

std::unique_ptr<Scene::Impl> build_lossy_any(Prepared& p, const MeshList& meshes,
                                             const BuildOptions& opt, int enc, Layout layout,
                                             Extract* extract = nullptr) {
  if (layout == Layout::Shared)
    return enc == 1 ? build_lossy<LossySharedLeaf<1>, LossySubGridShared>(p, meshes, opt, 1, true,
                                                                          extract)
                    : build_lossy<LossySharedLeaf<2>, LossySubGridShared>(p, meshes, opt, 2, true,
                                                                          extract);
  return enc == 1 ? build_lossy<LossyGridLeaf<1>, LossySubGrid>(p, meshes, opt, 1, false, extract)
                  : build_lossy<LossyGridLeaf<2>, LossySubGrid>(p, meshes, opt, 2, false, extract);
}

}  // namespace

std::unique_ptr<Scene::Impl> empty_grid_scene(const BuildOptions& opt) {
  const Layout layout = layout_of(opt);
  const bool e1 = opt.grid_encoding == GridEncoding::Octahedral;
  if (layout == Layout::Uncompressed) return std::make_unique<GridScene<SubGridLeaf>>();
  if (layout == Layout::Shared)
    return e1 ? std::unique_ptr<Scene::Impl>(std::make_unique<GridScene<LossySharedLeaf<1>>>())
              : std::make_unique<GridScene<LossySharedLeaf<2>>>();
  return e1 ? std::unique_ptr<Scene::Impl>(std::make_unique<GridScene<LossyGridLeaf<1>>>())
            : std::make_unique<GridScene<LossyGridLeaf<2>>>();
}

std::unique_ptr<Scene::Impl> build_grid_scene(const MeshList& meshes, const BuildOptions& opt) {
  const Layout layout = layout_of(opt);
  Prepared p = prepare(meshes, opt);
  if (layout == Layout::Uncompressed) return build_uncompressed(p, meshes, opt);
  return build_lossy_any(p, meshes, opt, int(opt.grid_encoding), layout);
}

GridErrorStats extract_grid_scene(const MeshList& meshes, const BuildOptions& opt,
                                  DecodedTriangles* triangles) {
  for (const MeshView* m : meshes) {
    if (!m) throw Error("grid statistics: null mesh");
    check_mesh(*m);
  }
  if (opt.leaf != Leaf::Grids && opt.leaf != Leaf::LossyGrids && opt.leaf != Leaf::SharedLossyGrids)
    throw Error("grid statistics: " + opt.config_name() + " is not a grid configuration");
  opt.check();
  const Layout layout = layout_of(opt);
  Prepared p = prepare(meshes, opt);
  Extract x;
  x.triangles = triangles;
  if (layout == Layout::Uncompressed)
    build_uncompressed(p, meshes, opt, &x);
  else
    build_lossy_any(p, meshes, opt, int(opt.grid_encoding), layout, &x);
  GridErrorStats e;
  const ErrorTotals& et = x.errors;
  e.rms = et.rms;
  e.max_error = et.max_error;
  e.diag_avg_pct = et.diag_avg_pct;
  e.diag_max_pct = et.diag_max_pct;
  e.vertices = et.vertices;
  e.subgrids = et.subgrids;
  e.exact_vertices =
      find_exact_positions(p.gs, meshes, layout != Layout::Uncompressed && !opt.lattice_box.empty())
          .pos.size();
  e.leftovers = p.leftover_cells + p.leftover_tris == 0 ? "none"
                : p.tri_leaves                          ? "triangles"
                                                        : "grids";
  return e;
}

}  // namespace slim
