// Mesh -> vertex grids: C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy Compressed Grid
// Primitives", Eurographics 2021 short papers, section 3 ("Conversion to Vertex Grids"), with the
// choices the paper leaves open made in grids.h. See grids.h for the rules.
//
// Memory (a 50 M triangle terrain must convert on a 24 GiB machine): quad faces are cells by their
// face index (no copy of their corners); only n-gon quads and triangle pairs are stored; the
// adjacency is 16 B per cell, built through a vertex -> corner table (4 B per corner), which is
// freed before the grids are filled. No triangle soup is made.
#include "mesh/grids.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <deque>
#include <string>
#include <unordered_map>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "mesh/pairing.h"

namespace slim {

namespace {

constexpr uint32_t kNone = 0xffffffffu;

// The cells of one mesh. Cell c < quad_count is the quad face quad_face(c); the others are in
// `extra` (n-gon quads and triangle pairs). Corners are face corners (indices into face_indices).
struct Cells {
  struct Extra {
    uint32_t corner[4];
    uint32_t face_a, face_b;  // faces of (c0,c1,c2) and (c0,c2,c3)
    bool pair;                // a triangle pair: its diagonal is the shared edge, never flipped
  };
  const MeshView* mesh = nullptr;
  bool identity_quads = false;       // quad cell c is face c
  bool all_quads = false;            // face f's corners are 4f..4f+3
  std::vector<uint32_t> quad_faces;  // otherwise: quad cell -> face
  std::vector<uint64_t> offsets;     // face offsets (empty if identity_quads)
  uint32_t quad_count = 0;
  std::vector<Extra> extra;

  uint32_t count() const { return quad_count + uint32_t(extra.size()); }
  uint32_t face_of_quad(uint32_t c) const { return identity_quads ? c : quad_faces[c]; }
  uint64_t corner(uint32_t c, int k) const {
    if (c < quad_count) {
      uint32_t f = face_of_quad(c);
      return (all_quads ? 4 * uint64_t(f) : offsets[f]) + uint32_t(k);
    }
    return extra[c - quad_count].corner[k];
  }
  uint32_t vertex(uint32_t c, int k) const { return mesh->face_indices[corner(c, k)]; }
  uint32_t face_a(uint32_t c) const {
    return c < quad_count ? face_of_quad(c) : extra[c - quad_count].face_a;
  }
  uint32_t face_b(uint32_t c) const {
    return c < quad_count ? face_of_quad(c) : extra[c - quad_count].face_b;
  }
  bool is_pair(uint32_t c) const { return c >= quad_count && extra[c - quad_count].pair; }
};

// Two corners of the same vertex carry the same attributes (no uv/normal seam between them).
SLIM_INLINE bool same_attributes(const MeshView& m, uint64_t c1, uint64_t c2) {
  if (!m.uv_indices.empty() && m.uv_indices[c1] != m.uv_indices[c2]) return false;
  if (!m.normal_indices.empty() && m.normal_indices[c1] != m.normal_indices[c2]) return false;
  return true;
}

// Edge adjacency of the cells: nb[4c + k] = 4c' + k' for the cell c' whose edge k' (corner k' ->
// k'+1) is edge k of c reversed, or kNone (mesh border, non-manifold or inconsistently oriented
// edge, attribute seam).
std::vector<uint32_t> cell_adjacency(const Cells& cells, uint64_t vertex_count) {
  const MeshView& m = *cells.mesh;
  const uint32_t n = cells.count();
  // Vertex -> (cell, corner) table.
  std::vector<uint32_t> start(vertex_count + 1, 0);
  for (uint32_t c = 0; c < n; ++c)
    for (int k = 0; k < 4; ++k) start[cells.vertex(c, k) + 1]++;
  for (uint64_t v = 0; v < vertex_count; ++v) start[v + 1] += start[v];
  std::vector<uint32_t> entries(start[vertex_count]);
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (uint32_t c = 0; c < n; ++c)
      for (int k = 0; k < 4; ++k) entries[fill[cells.vertex(c, k)]++] = 4 * c + uint32_t(k);
  }
  std::vector<uint32_t> nb(4 * uint64_t(n), kNone);
  // Each (cell, edge) is decided on its own (the decision is symmetric), so cells run in parallel.
  tbb::parallel_for(tbb::blocked_range<uint32_t>(0, n), [&](const tbb::blocked_range<uint32_t>& r) {
    for (uint32_t c = r.begin(); c != r.end(); ++c) {
      for (int k = 0; k < 4; ++k) {
        const uint32_t a = cells.vertex(c, k), b = cells.vertex(c, (k + 1) & 3);
        // The other cells with edge b -> a (opposite) or a -> b (same), found in the shorter of
        // a's and b's lists (a cell's four vertices are distinct, so it stands once in each),
        // stopping as soon as the edge cannot be an interior grid edge: a stack of coincident
        // cells or a vertex of high valence costs one pass over the short list, not valence^2.
        uint32_t found = kNone;
        int opposite = 0, same = 0;
        const bool from_b = start[b + 1] - start[b] <= start[a + 1] - start[a];
        const uint32_t v = from_b ? b : a;
        for (uint32_t e = start[v]; e < start[v + 1] && opposite <= 1 && same == 0; ++e) {
          const uint32_t c2 = entries[e] >> 2, k2 = entries[e] & 3;
          if (c2 == c) continue;
          const uint32_t next = cells.vertex(c2, int((k2 + 1) & 3));
          const uint32_t prev = cells.vertex(c2, int((k2 + 3) & 3));
          if (from_b ? next == a : prev == b) {  // b -> a in c2: b is corner (k2 or k2 - 1)
            opposite++;
            found = from_b ? entries[e] : 4 * c2 + ((k2 + 3) & 3);
          }
          if (from_b ? prev == a : next == b) same++;  // a -> b in c2
        }
        if (opposite != 1 || same != 0) continue;
        const uint32_t c2 = found >> 2, k2 = found & 3;
        // Corner of a in c is k, in c2 it is k2+1; corner of b in c is k+1, in c2 it is k2.
        if (!same_attributes(m, cells.corner(c, k), cells.corner(c2, int((k2 + 1) & 3))) ||
            !same_attributes(m, cells.corner(c, (k + 1) & 3), cells.corner(c2, int(k2))))
          continue;
        nb[4 * c + k] = found;
      }
    }
  });
  return nb;
}

// A cell placed in a grid: rotation r puts corner c_r at the cell's grid-frame (0,0), c_r+1 at
// (1,0), c_r+2 at (1,1), c_r+3 at (0,1). Grid-frame sides: 0 top, 1 right, 2 bottom, 3 left; side s
// is the cell's edge (r + s) mod 4.
struct Placed {
  uint32_t cell = kNone;
  uint8_t rot = 0;
};

class GridGrower {
 public:
  GridGrower(const Cells& cells, const std::vector<uint32_t>& nb, std::vector<uint8_t>& used,
             const GridBuildOptions& opt)
      : cells_(cells), nb_(nb), used_(used), opt_(opt) {}

  // Grows the largest rectangle it can from the seed; returns its cells row-major.
  void grow(uint32_t seed, std::vector<Placed>& out, uint32_t& w, uint32_t& h) {
    Placed s{seed, 0};
    used_[seed] = 1;
    top_.assign(1, s);
    bottom_.assign(1, s);
    left_.assign(1, s);
    right_.assign(1, s);
    for (bool grew = true; grew;) {
      grew = false;
      for (int side : {1, 2, 3, 0}) grew |= extend(side);
    }
    w = uint32_t(top_.size());
    h = uint32_t(left_.size());
    // Fill row by row, walking right from the left column (every horizontal pair was checked on
    // insertion); rows, not columns, so that meshes listed row by row are read in order.
    out.resize(uint64_t(w) * h);
    for (uint32_t y = 0; y < h; ++y) {
      Placed p = left_[y];
      for (uint32_t x = 0; x < w; ++x) {
        out[uint64_t(y) * w + x] = p;
        if (x + 1 < w) p = across(p, 1);
      }
    }
    // A grid closed on itself (a torus, a cylinder) can be cut anywhere around: cut it before the
    // cell of smallest face, so that a mesh listed row by row keeps an affine face numbering
    // (one side-table entry instead of a face table).
    auto same = [](Placed a, Placed b) { return a.cell == b.cell && a.rot == b.rot; };
    bool wrap_x = w > 1, wrap_y = h > 1;
    for (uint32_t y = 0; y < h && wrap_x; ++y)
      wrap_x = same(across(out[uint64_t(y) * w], 3), out[uint64_t(y) * w + w - 1]);
    for (uint32_t x = 0; x < w && wrap_y; ++x)
      wrap_y = same(across(out[x], 0), out[uint64_t(h - 1) * w + x]);
    if (wrap_x || wrap_y) {
      uint64_t best = 0;
      for (uint64_t i = 1; i < out.size(); ++i)
        if (cells_.face_a(out[i].cell) < cells_.face_a(out[best].cell)) best = i;
      const uint32_t sx = wrap_x ? uint32_t(best % w) : 0, sy = wrap_y ? uint32_t(best / w) : 0;
      std::vector<Placed> shifted(out.size());
      for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x)
          shifted[uint64_t(y) * w + x] = out[uint64_t((y + sy) % h) * w + (x + sx) % w];
      out.swap(shifted);
    }
  }

 private:
  // The neighbour across grid side s of p, placed in the same frame (cell kNone if none).
  Placed across(Placed p, int s) const {
    uint32_t e = nb_[4 * p.cell + ((p.rot + s) & 3)];
    if (e == kNone) return {};
    uint32_t c2 = e >> 2, k2 = e & 3;
    // c2's side (s + 2) is its edge k2.
    return {c2, uint8_t((k2 - uint32_t(s + 2)) & 3)};
  }

  bool acceptable(Placed p) const { return p.cell != kNone && !used_[p.cell]; }

  // Adds one column (side 1 right, 3 left) or row (2 bottom, 0 top) if every cell fits.
  bool extend(int side) {
    const bool vertical = side == 1 || side == 3;  // a new column
    std::deque<Placed>& edge = side == 1 ? right_ : side == 3 ? left_ : side == 2 ? bottom_ : top_;
    const uint64_t cur = vertical ? top_.size() : left_.size();  // extent in the growth direction
    if (cur + 1 >= opt_.max_res) return false;
    // Along the new column, neighbours are linked by side 2 (down); along a new row by side 1.
    const int link = vertical ? 2 : 1;
    fresh_.clear();
    bool ok = true;
    for (size_t i = 0; i < edge.size(); ++i) {
      Placed n = across(edge[i], side);
      if (!acceptable(n)) {
        ok = false;
        break;
      }
      if (i > 0) {
        Placed link_n = across(fresh_.back(), link);
        if (link_n.cell != n.cell || link_n.rot != n.rot) {
          ok = false;
          break;
        }
      }
      used_[n.cell] = 1;  // a cell must not appear twice in the new column/row
      fresh_.push_back(n);
    }
    if (!ok) {
      for (const Placed& p : fresh_) used_[p.cell] = 0;
      return false;
    }
    edge.assign(fresh_.begin(), fresh_.end());
    switch (side) {
      case 1:
        top_.push_back(fresh_.front());
        bottom_.push_back(fresh_.back());
        break;
      case 3:
        top_.push_front(fresh_.front());
        bottom_.push_front(fresh_.back());
        break;
      case 2:
        left_.push_back(fresh_.front());
        right_.push_back(fresh_.back());
        break;
      default:
        left_.push_front(fresh_.front());
        right_.push_front(fresh_.back());
        break;
    }
    return true;
  }

  const Cells& cells_;
  const std::vector<uint32_t>& nb_;
  std::vector<uint8_t>& used_;
  const GridBuildOptions& opt_;
  std::deque<Placed> top_, bottom_, left_, right_;
  std::vector<Placed> fresh_;
};

// Collects the cells of one mesh; triangles that form no cell go to `leftover`.
void collect_cells(const MeshView& m, uint32_t geom, const GridBuildOptions& opt, Cells& cells,
                   std::vector<LeftoverTriangle>& leftover, GridConversionFigures& fig) {
  cells.mesh = &m;
  const size_t nf = m.face_count();
  std::vector<uint8_t> finite(m.positions.size());
  for (size_t i = 0; i < m.positions.size(); ++i) finite[i] = is_finite(m.positions[i]);
  bool all_quads = true;
  for (uint32_t s : m.face_sizes) all_quads = all_quads && s == 4;
  cells.all_quads = all_quads;
  if (!all_quads) cells.offsets = m.face_offsets();
  auto off = [&](uint32_t f) { return all_quads ? 4 * uint64_t(f) : cells.offsets[f]; };
  auto distinct4 = [&](uint32_t a, uint32_t b, uint32_t c, uint32_t d) {
    return a != b && a != c && a != d && b != c && b != d && c != d;
  };
  // Triangles to pair: corners (indices into face_indices) and their face.
  std::vector<uint64_t> tri_corners;
  std::vector<uint32_t> tri_faces;
  auto add_tri = [&](uint32_t f, uint64_t c0, uint64_t c1, uint64_t c2) {
    tri_corners.insert(tri_corners.end(), {c0, c1, c2});
    tri_faces.push_back(f);
  };
  // While every face so far is a valid quad, quad cell c is face c and quad_faces stays empty.
  bool identity = all_quads;
  auto break_identity = [&](uint32_t f) {
    if (!identity) return;
    identity = false;
    cells.quad_faces.resize(f);
    for (uint32_t i = 0; i < f; ++i) cells.quad_faces[i] = i;
  };
  for (uint32_t f = 0; f < nf; ++f) {
    const uint32_t n = m.face_sizes[f];
    const uint64_t o = off(f);
    const uint32_t* idx = &m.face_indices[o];
    fig.triangles += n - 2;
    bool ok = true;
    for (uint32_t k = 0; k < n; ++k) ok = ok && finite[idx[k]];
    if (!ok) {
      fig.skipped_faces++;
      break_identity(f);
      continue;
    }
    if (n == 4) {
      if (distinct4(idx[0], idx[1], idx[2], idx[3])) {
        if (!identity) cells.quad_faces.push_back(f);
      } else {
        break_identity(f);
        add_tri(f, o, o + 1, o + 2);
        add_tri(f, o, o + 2, o + 3);
      }
    } else if (n == 3) {
      add_tri(f, o, o + 1, o + 2);
    } else {
      // n-gon: quads (v0, v_k, v_k+1, v_k+2) of the fan, then the odd fan triangle.
      uint32_t k = 1;
      for (; k + 2 < n; k += 2) {
        uint32_t q[4] = {idx[0], idx[k], idx[k + 1], idx[k + 2]};
        if (distinct4(q[0], q[1], q[2], q[3]))
          cells.extra.push_back(
              {{uint32_t(o), uint32_t(o + k), uint32_t(o + k + 1), uint32_t(o + k + 2)},
               f,
               f,
               false});
        else {
          add_tri(f, o, o + k, o + k + 1);
          add_tri(f, o, o + k + 1, o + k + 2);
        }
      }
      if (k + 1 < n) add_tri(f, o, o + k, o + k + 1);
    }
  }
  if (m.face_indices.size() >= 0xffffffffull)
    throw Error(m.name + ": grids: more than 2^32 - 1 face corners");
  cells.identity_quads = identity;
  cells.quad_count = identity ? uint32_t(nf) : uint32_t(cells.quad_faces.size());
  std::vector<Cells::Extra> ngon_quads = std::move(cells.extra);
  cells.extra.clear();
  // Triangle pairs (mesh/pairing.h, the edge heuristic of Aman and Fenney) become cells.
  const uint64_t nt = tri_faces.size();
  std::vector<uint8_t> paired(nt, 0);
  if (opt.pair_triangles && nt >= 2) {
    std::vector<uint32_t> tv(3 * nt);
    for (uint64_t i = 0; i < 3 * nt; ++i) tv[i] = m.face_indices[tri_corners[i]];
    PairingInput in{m.positions.data(), m.positions.size(), tv.data(), nt, nullptr};
    PairingResult pr = pair_triangles(in);
    for (const TrianglePair& p : pr.pairs) {
      // a = (x, y, z) with the shared edge x -> y; b must hold it as y -> x: b = (y, x, w).
      const uint64_t* ca = &tri_corners[3 * uint64_t(p.a)];
      const uint64_t* cb = &tri_corners[3 * uint64_t(p.b)];
      uint64_t x = ca[p.ea], y = ca[(p.ea + 1) % 3], z = ca[(p.ea + 2) % 3];
      uint64_t by = cb[p.eb], bx = cb[(p.eb + 1) % 3], w = cb[(p.eb + 2) % 3];
      if (m.face_indices[by] != m.face_indices[y] || m.face_indices[bx] != m.face_indices[x])
        continue;  // same direction in both: inconsistent orientation, no cell
      if (!distinct4(m.face_indices[y], m.face_indices[z], m.face_indices[x], m.face_indices[w]))
        continue;
      // Cell (y, z, x, w): (c0,c1,c2) = a, (c0,c2,c3) = (y, x, w) = b; diagonal = shared edge.
      cells.extra.push_back({{uint32_t(y), uint32_t(z), uint32_t(x), uint32_t(w)},
                             tri_faces[p.a],
                             tri_faces[p.b],
                             true});
      paired[p.a] = paired[p.b] = 1;
      fig.paired_cells++;
    }
  }
  cells.extra.insert(cells.extra.end(), ngon_quads.begin(), ngon_quads.end());
  for (uint64_t t = 0; t < nt; ++t) {
    if (paired[t]) continue;
    LeftoverTriangle lt;
    lt.geom = geom;
    lt.face = tri_faces[t];
    for (int k = 0; k < 3; ++k) {
      lt.v[k] = m.face_indices[tri_corners[3 * t + k]];
      lt.corner[k] = uint32_t(tri_corners[3 * t + k]);
    }
    leftover.push_back(lt);
  }
  if (uint64_t(cells.count()) >= (1ull << 30))
    throw Error(m.name + ": grids: 2^30 cells or more in one mesh");
  fig.cells += cells.count();
}

}  // namespace

GridSet make_grids(const MeshList& meshes, const GridBuildOptions& opt) {
  auto t0 = std::chrono::steady_clock::now();
  GridSet gs;
  GridConversionFigures& fig = gs.figures;
  // 1-cell grids are collected apart and appended after the multi-cell grids.
  struct Single {
    uint32_t geom;
    uint32_t v[4];
    uint32_t corner[4];
    uint32_t face_a, face_b;
  };
  std::vector<Single> singles;
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    const MeshView& m = *meshes[g];
    fig.input_faces += m.face_count();
    Cells cells;
    collect_cells(m, g, opt, cells, gs.triangles, fig);
    const uint32_t n = cells.count();
    std::vector<uint32_t> nb = cell_adjacency(cells, m.positions.size());
    std::vector<uint8_t> used(n, 0);
    GridGrower grower(cells, nb, used, opt);
    std::vector<Placed> placed;
    for (uint32_t seed = 0; seed < n; ++seed) {
      if (used[seed]) continue;
      uint32_t w = 0, h = 0;
      grower.grow(seed, placed, w, h);
      // Rotation 0: A = (00,10,11) = (c0,c1,c2) (face_a), B = (00,11,01) = (c0,c2,c3) (face_b);
      // rotation 2 swaps them. Odd rotations put c0-c2 on the anti-diagonal: the cell is flipped,
      // A = (00,10,01), B = (11,01,10), which are (c0,c1,c2), (c0,c2,c3) for rotation 1 and swapped
      // for rotation 3.
      auto faces = [&](const Placed& p, uint32_t& fa, uint32_t& fb, uint8_t& flip) {
        fa = cells.face_a(p.cell);
        fb = cells.face_b(p.cell);
        if (p.rot >= 2) std::swap(fa, fb);
        flip = (p.rot & 1) && (opt.match_fan_diagonal || cells.is_pair(p.cell));
      };
      if (w * h == 1) {
        Single s;
        s.geom = g;
        for (int k = 0; k < 4; ++k) {
          s.v[k] = cells.vertex(seed, k);
          s.corner[k] = uint32_t(cells.corner(seed, k));
        }
        uint8_t flip = 0;
        faces(placed[0], s.face_a, s.face_b, flip);
        singles.push_back(s);
        continue;
      }
      VertexGrid vg;
      vg.geom = g;
      vg.res_x = w + 1;
      vg.res_y = h + 1;
      vg.vertex_offset = gs.vertices.size();
      vg.cell_offset = gs.cell_faces.size() / 2;
      const uint64_t nverts = uint64_t(vg.res_x) * vg.res_y;
      gs.vertices.resize(gs.vertices.size() + nverts);
      if (opt.corners) gs.corner_of_vertex.resize(gs.vertices.size());
      gs.cell_faces.resize(gs.cell_faces.size() + 2 * uint64_t(w) * h);
      gs.cell_flip.resize(gs.cell_flip.size() + uint64_t(w) * h);
      uint32_t* vout = &gs.vertices[vg.vertex_offset];
      uint32_t* cout = opt.corners ? &gs.corner_of_vertex[vg.vertex_offset] : nullptr;
      uint32_t* fout = &gs.cell_faces[2 * vg.cell_offset];
      for (uint32_t y = 0; y < h; ++y)
        for (uint32_t x = 0; x < w; ++x) {
          const Placed& p = placed[uint64_t(y) * w + x];
          static constexpr uint32_t dx[4] = {0, 1, 1, 0}, dy[4] = {0, 0, 1, 1};
          for (int q = 0; q < 4; ++q) {
            const int k = (p.rot + q) & 3;
            const uint64_t at = uint64_t(y + dy[q]) * vg.res_x + x + dx[q];
            vout[at] = cells.vertex(p.cell, k);
            if (cout) cout[at] = uint32_t(cells.corner(p.cell, k));
          }
          const uint64_t cell = uint64_t(y) * w + x;
          uint8_t& flip = gs.cell_flip[vg.cell_offset + cell];
          faces(p, fout[2 * cell], fout[2 * cell + 1], flip);
          fig.flipped_cells += flip;
        }
      gs.grids.push_back(vg);
      fig.grids++;
      fig.grid_cells += uint64_t(w) * h;
      fig.largest_grid_cells = std::max(fig.largest_grid_cells, uint64_t(w) * h);
    }
  }
  gs.multi_cell_grids = gs.grids.size();
  for (const Single& s : singles) {
    VertexGrid vg;
    vg.geom = s.geom;
    vg.res_x = vg.res_y = 2;
    vg.vertex_offset = gs.vertices.size();
    vg.cell_offset = gs.cell_faces.size() / 2;
    // Corners c0..c3 at (0,0), (1,0), (1,1), (0,1): row-major order c0, c1, c3, c2.
    for (int k : {0, 1, 3, 2}) {
      gs.vertices.push_back(s.v[k]);
      if (opt.corners) gs.corner_of_vertex.push_back(s.corner[k]);
    }
    gs.cell_faces.push_back(s.face_a);
    gs.cell_faces.push_back(s.face_b);
    gs.cell_flip.push_back(0);
    gs.grids.push_back(vg);
  }
  fig.single_cells = singles.size();
  fig.leftover_triangles = gs.triangles.size();
  fig.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return gs;
}

namespace {

// How a lossy decoder rebuilds the vertex at one grid position (see ExactPositions).
struct DecodeKey {
  uint64_t a = 0, b = 0;  // the two corners of its sub-grid border (global vertex ids), a <= b
  uint8_t t = 0, n = 0;   // offset from a and the border's vertex count
  bool operator==(const DecodeKey& o) const { return a == o.a && b == o.b && t == o.t && n == o.n; }
};

enum PositionKind { kCornerPos, kBorderPos, kInteriorPos };

template <class Id>
PositionKind classify(const GridSet& gs, const VertexGrid& g, uint32_t x, uint32_t y, const Id& id,
                      DecodeKey& key) {
  const bool col = lattice_line(x, g.res_x), row = lattice_line(y, g.res_y);
  if (col && row) return kCornerPos;
  if (!col && !row) return kInteriorPos;
  uint32_t ax, ay, bx, by, t, n;
  if (col) {  // on a vertical border: corners above and below
    ay = y - y % 4;
    by = std::min(ay + 4, g.res_y - 1);
    ax = bx = x;
    t = y - ay;
    n = by - ay + 1;
  } else {
    ax = x - x % 4;
    bx = std::min(ax + 4, g.res_x - 1);
    ay = by = y;
    t = x - ax;
    n = bx - ax + 1;
  }
  uint64_t a = id(g.geom, gs.vertex(g, ax, ay)), b = id(g.geom, gs.vertex(g, bx, by));
  if (a > b) {
    std::swap(a, b);
    t = n - 1 - t;
  } else if (a == b) {
    t = std::min(t, n - 1 - t);
  }
  key = {a, b, uint8_t(t), uint8_t(n)};
  return kBorderPos;
}

}  // namespace

ExactPositions find_exact_positions(const GridSet& gs, const MeshList& meshes,
                                    bool escape_boundary) {
  std::vector<uint64_t> base(meshes.size() + 1, 0);
  for (size_t g = 0; g < meshes.size(); ++g) base[g + 1] = base[g] + meshes[g]->positions.size();
  if (base.back() >= 0xffffffffull) throw Error("lossy grids: more than 2^32 - 1 vertices");
  auto pos = [&](uint64_t v) {
    const size_t g = size_t(std::upper_bound(base.begin(), base.end(), v) - base.begin()) - 1;
    return meshes[g]->positions[v - base[g]];
  };
  // Vertex identity: vertices with bit-identical positions on grid borders are one vertex
  // (unwelded meshes, meshes that touch: the triangle formats close such seams, so the lossy ones
  // must too). Only positions on a grid's outer ring or in a leftover can meet another use
  // without sharing an index (adjacency stops there), so only those are matched by position:
  // canon[v] is the first ring/leftover vertex with v's position, or v.
  struct PosHash {
    size_t operator()(const Vec3f& p) const {
      uint32_t w[3];
      std::memcpy(w, &p, 12);
      uint64_t h = w[0] * 0x9E3779B97F4A7C15ull;
      h = (h ^ (h >> 29) ^ w[1]) * 0xBF58476D1CE4E5B9ull;
      h = (h ^ (h >> 32) ^ w[2]) * 0x94D049BB133111EBull;
      return size_t(h ^ (h >> 31));
    }
  };
  struct PosEq {
    bool operator()(const Vec3f& a, const Vec3f& b) const { return std::memcmp(&a, &b, 12) == 0; }
  };
  std::vector<uint32_t> canon(base.back());
  for (uint64_t v = 0; v < canon.size(); ++v) canon[v] = uint32_t(v);
  {
    std::unordered_map<Vec3f, uint32_t, PosHash, PosEq> ring;
    auto add_ring = [&](uint64_t v) {
      auto it = ring.emplace(pos(v), uint32_t(v)).first;
      canon[v] = it->second;
    };
    for (size_t gi = 0; gi < gs.grids.size(); ++gi) {
      const VertexGrid& g = gs.grids[gi];
      for (uint32_t y = 0; y < g.res_y; ++y) {
        const bool edge_row = y == 0 || y + 1 == g.res_y;
        for (uint32_t x = 0; x < g.res_x; x += (edge_row || x + 1 == g.res_x) ? 1 : g.res_x - 1)
          add_ring(base[g.geom] + gs.vertex(g, x, y));
      }
    }
    for (const LeftoverTriangle& t : gs.triangles)
      for (uint32_t v : t.v) add_ring(base[t.geom] + v);
  }
  auto id = [&](uint32_t geom, uint32_t v) { return canon[base[geom] + v]; };

  // Uses per vertex, saturating at 2: only vertices used twice or more can disagree.
  std::vector<uint8_t> uses(base.back(), 0);
  auto use = [&](uint32_t v) { uses[v] = uint8_t(std::min(2, uses[v] + 1)); };
  for (const VertexGrid& g : gs.grids)
    for (uint64_t i = 0; i < uint64_t(g.res_x) * g.res_y; ++i)
      use(id(g.geom, gs.vertices[g.vertex_offset + i]));
  for (const LeftoverTriangle& t : gs.triangles)
    for (uint32_t v : t.v) use(id(t.geom, v));

  enum : uint8_t { kExactSeen = 1, kHasKey = 2, kConflict = 4 };
  struct State {
    uint8_t flags = 0;
    DecodeKey key;
  };
  std::unordered_map<uint32_t, State> shared;
  for (size_t gi = 0; gi < gs.grids.size(); ++gi) {
    const VertexGrid& g = gs.grids[gi];
    for (uint32_t y = 0; y < g.res_y; ++y)
      for (uint32_t x = 0; x < g.res_x; ++x) {
        const uint32_t v = id(g.geom, gs.vertex(g, x, y));
        if (uses[v] < 2) continue;
        State& s = shared[v];
        DecodeKey key;
        switch (gi < gs.multi_cell_grids ? classify(gs, g, x, y, id, key) : kCornerPos) {
          case kCornerPos:
            s.flags |= kExactSeen;
            break;
          case kInteriorPos:
            s.flags |= kConflict;
            break;
          case kBorderPos:
            if (!(s.flags & kHasKey)) {
              s.flags |= kHasKey;
              s.key = key;
            } else if (!(s.key == key)) {
              s.flags |= kConflict;
            }
            break;
        }
      }
  }
  for (const LeftoverTriangle& t : gs.triangles)
    for (uint32_t v : t.v) {
      const uint32_t c = id(t.geom, v);
      if (uses[c] >= 2) shared[c].flags |= kExactSeen;
    }

  // escape_boundary: the vertices on an edge that one triangle or cell uses. Only a multi-cell
  // grid's non-corner positions decode lossily, and those on a boundary edge lie on its outer
  // ring (an inner edge has a cell of the grid on each side; an inner vertex used elsewhere is a
  // conflict above), so the edges counted are those with an end on such a ring: the rings of all
  // grids (each ring edge is one cell's) and the leftover triangles' edges.
  enum : uint8_t { kOnRing = 1, kOnBoundary = 2 };
  std::vector<uint8_t> boundary;
  bool any_boundary = false;
  if (escape_boundary) {
    boundary.assign(base.back(), 0);
    auto ring_edges = [&](const VertexGrid& g, auto&& edge) {
      const uint32_t w = g.res_x - 1, h = g.res_y - 1;
      auto v = [&](uint32_t x, uint32_t y) { return id(g.geom, gs.vertex(g, x, y)); };
      for (uint32_t x = 0; x < w; ++x) {
        edge(v(x, 0), v(x + 1, 0));
        edge(v(x, h), v(x + 1, h));
      }
      for (uint32_t y = 0; y < h; ++y) {
        edge(v(0, y), v(0, y + 1));
        edge(v(w, y), v(w, y + 1));
      }
    };
    for (size_t gi = 0; gi < gs.multi_cell_grids; ++gi)
      ring_edges(gs.grids[gi], [&](uint32_t a, uint32_t b) {
        boundary[a] |= kOnRing;
        boundary[b] |= kOnRing;
      });
    std::vector<uint64_t> edges;  // (smaller id << 32) | larger id, one entry per use
    auto add = [&](uint32_t a, uint32_t b) {
      if (a == b || !((boundary[a] | boundary[b]) & kOnRing)) return;
      edges.push_back(a < b ? (uint64_t(a) << 32) | b : (uint64_t(b) << 32) | a);
    };
    for (const VertexGrid& g : gs.grids) ring_edges(g, add);
    for (const LeftoverTriangle& t : gs.triangles) {
      const uint32_t a = id(t.geom, t.v[0]), b = id(t.geom, t.v[1]), c = id(t.geom, t.v[2]);
      add(a, b);
      add(b, c);
      add(c, a);
    }
    std::sort(edges.begin(), edges.end());
    for (size_t i = 0, j; i < edges.size(); i = j) {
      for (j = i + 1; j < edges.size() && edges[j] == edges[i];) ++j;
      if (j - i != 1) continue;
      boundary[edges[i] >> 32] |= kOnBoundary;
      boundary[uint32_t(edges[i])] |= kOnBoundary;
      any_boundary = true;
    }
  }

  ExactPositions ex;
  ex.start.assign(gs.grids.size() + 1, 0);
  for (size_t gi = 0; gi < gs.grids.size(); ++gi) {
    ex.start[gi] = ex.pos.size();
    if (gi >= gs.multi_cell_grids || (shared.empty() && !any_boundary)) continue;
    const VertexGrid& g = gs.grids[gi];
    for (uint32_t y = 0; y < g.res_y; ++y)
      for (uint32_t x = 0; x < g.res_x; ++x) {
        if (lattice_line(x, g.res_x) && lattice_line(y, g.res_y)) continue;
        const uint32_t v = id(g.geom, gs.vertex(g, x, y));
        if (!any_boundary || !(boundary[v] & kOnBoundary)) {
          if (uses[v] < 2) continue;
          const State& s = shared[v];
          if (!((s.flags & kConflict) || ((s.flags & kExactSeen) && (s.flags & kHasKey)))) continue;
        }
        ex.pos.push_back(y * g.res_x + x);
      }
  }
  ex.start[gs.grids.size()] = ex.pos.size();
  return ex;
}

// Appends the leftover triangles of gs as 2x2 grids (a, b / c, c): A = (a, b, c), B = (a, c, c)
// degenerate; with_corners also extends gs.corner_of_vertex.
void append_triangle_grids(GridSet& gs, bool with_corners) {
  for (const LeftoverTriangle& t : gs.triangles) {
    VertexGrid g;
    g.geom = t.geom;
    g.res_x = g.res_y = 2;
    g.vertex_offset = gs.vertices.size();
    g.cell_offset = gs.cell_faces.size() / 2;
    gs.vertices.insert(gs.vertices.end(), {t.v[0], t.v[1], t.v[2], t.v[2]});
    if (with_corners)
      gs.corner_of_vertex.insert(gs.corner_of_vertex.end(),
                                 {t.corner[0], t.corner[1], t.corner[2], t.corner[2]});
    gs.cell_faces.insert(gs.cell_faces.end(), {t.face, t.face});
    gs.cell_flip.push_back(0);
    gs.grids.push_back(g);
  }
}

}  // namespace slim
