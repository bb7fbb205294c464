// Per-vertex attributes of grid hits (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy
// Compressed Grid Primitives", Eurographics 2021 short papers, section 6): attributes in the grid
// order of the vertices, looked up with a hit's per-grid u,v (slimrt/grids.h GridAttributes).
#include <memory>

#include "mesh/grids.h"
#include "slimrt/grids.h"

namespace slim {

struct GridAttributes::Impl {
  GridSet gs;
  // Per mesh, per face: the cells of that face as (grid, x, y) in a CSR layout.
  struct CellRef {
    uint32_t grid, x, y;
  };
  std::vector<std::vector<uint64_t>> face_start;  // [geom][face] -> first entry in cells[geom]
  std::vector<std::vector<CellRef>> cells;
};

GridAttributes::GridAttributes() = default;
GridAttributes::~GridAttributes() = default;
GridAttributes::GridAttributes(GridAttributes&&) noexcept = default;
GridAttributes& GridAttributes::operator=(GridAttributes&&) noexcept = default;

GridAttributes GridAttributes::build(const std::vector<const PolyMesh*>& meshes) {
  for (const PolyMesh* m : meshes) check_mesh(*m);
  GridAttributes a;
  a.impl_ = std::make_unique<Impl>();
  Impl& im = *a.impl_;
  GridBuildOptions gopt;
  gopt.corners = true;
  im.gs = make_grids(meshes, gopt);
  GridSet& gs = im.gs;
  // Leftover triangles as the 2x2 grids (a, b / c, c) Scene::build makes of them in its 2x2 mode.
  append_triangle_grids(gs, /*with_corners=*/true);
  im.face_start.resize(meshes.size());
  im.cells.resize(meshes.size());
  for (size_t g = 0; g < meshes.size(); ++g)
    im.face_start[g].assign(meshes[g]->face_count() + 1, 0);
  auto for_each_cell = [&](auto&& fn) {
    for (size_t gi = 0; gi < gs.grids.size(); ++gi) {
      const VertexGrid& g = gs.grids[gi];
      for (uint32_t y = 0; y + 1 < g.res_y; ++y)
        for (uint32_t x = 0; x + 1 < g.res_x; ++x) {
          const uint32_t fa = gs.cell_face(g, x, y, 0), fb = gs.cell_face(g, x, y, 1);
          fn(g.geom, fa, uint32_t(gi), x, y);
          if (fb != fa) fn(g.geom, fb, uint32_t(gi), x, y);
        }
    }
  };
  for_each_cell([&](uint32_t geom, uint32_t f, uint32_t, uint32_t, uint32_t) {
    im.face_start[geom][f + 1]++;
  });
  for (size_t g = 0; g < meshes.size(); ++g) {
    auto& fs = im.face_start[g];
    for (size_t f = 0; f + 1 < fs.size(); ++f) fs[f + 1] += fs[f];
    im.cells[g].resize(fs.back());
  }
  std::vector<std::vector<uint64_t>> fill(meshes.size());
  for (size_t g = 0; g < meshes.size(); ++g)
    fill[g].assign(im.face_start[g].begin(), im.face_start[g].end() - 1);
  for_each_cell([&](uint32_t geom, uint32_t f, uint32_t gi, uint32_t x, uint32_t y) {
    im.cells[geom][fill[geom][f]++] = {gi, x, y};
  });
  return a;
}

uint64_t GridAttributes::grid_vertex_count() const { return impl_ ? impl_->gs.vertices.size() : 0; }

namespace {

template <class T>
std::vector<T> grid_ordered_impl(const GridSet& gs, uint32_t geom, const std::vector<T>& values,
                                 const std::vector<uint32_t>& indices, const PolyMesh* /*unused*/) {
  std::vector<T> out(gs.vertices.size());
  for (const VertexGrid& g : gs.grids) {
    if (g.geom != geom) continue;
    for (uint64_t i = 0; i < uint64_t(g.res_x) * g.res_y; ++i) {
      const uint64_t at = g.vertex_offset + i;
      const uint64_t idx = indices.empty() ? gs.vertices[at] : indices[gs.corner_of_vertex[at]];
      if (idx < values.size()) out[at] = values[idx];
    }
  }
  return out;
}

template <class T>
T lerp3(const T& a, const T& b, const T& c, float u, float v);
template <>
Vec2f lerp3(const Vec2f& a, const Vec2f& b, const Vec2f& c, float u, float v) {
  const float w = 1.0f - u - v;
  return {w * a.x + u * b.x + v * c.x, w * a.y + u * b.y + v * c.y};
}
template <>
Vec3f lerp3(const Vec3f& a, const Vec3f& b, const Vec3f& c, float u, float v) {
  return a * (1.0f - u - v) + b * u + c * v;
}

template <class T>
bool interpolate_impl(const GridAttributes::Impl& im, const std::vector<T>& values, const Hit& hit,
                      T& out) {
  if (!hit.valid() || hit.kind != PrimKind::Grid || hit.geomID >= im.cells.size()) return false;
  const auto& fs = im.face_start[hit.geomID];
  if (hit.primID + 1 >= fs.size()) return false;
  const GridSet& gs = im.gs;
  for (uint64_t e = fs[hit.primID]; e < fs[hit.primID + 1]; ++e) {
    const GridAttributes::Impl::CellRef& c = im.cells[hit.geomID][e];
    const VertexGrid& g = gs.grids[c.grid];
    const float gu = hit.u * float(g.res_x - 1), gv = hit.v * float(g.res_y - 1);
    const float cu = gu - float(c.x), cv = gv - float(c.y);
    // The hit's cell (allowing for rounding at the cell's borders).
    const float tol = 1e-3f;
    if (cu < -tol || cu > 1 + tol || cv < -tol || cv > 1 + tol) continue;
    const float u = std::clamp(cu, 0.0f, 1.0f), v = std::clamp(cv, 0.0f, 1.0f);
    if (values.size() < g.vertex_offset + uint64_t(g.res_x) * g.res_y) return false;
    auto at = [&](uint32_t dx, uint32_t dy) {
      return values[g.vertex_offset + uint64_t(c.y + dy) * g.res_x + c.x + dx];
    };
    if (gs.flipped(g, c.x, c.y)) {
      // A = (p00, p10, p01) holds u + v <= 1: p = p00 + u (p10 - p00) + v (p01 - p00);
      // B = (p11, p01, p10): p = p11 + (1 - u)(p01 - p11) + (1 - v)(p10 - p11).
      if (u + v <= 1.0f)
        out = lerp3(at(0, 0), at(1, 0), at(0, 1), u, v);
      else
        out = lerp3(at(1, 1), at(0, 1), at(1, 0), 1.0f - u, 1.0f - v);
    } else {
      // A = (p00, p10, p11) holds v <= u: p = p00 + (u - v)(p10 - p00) + v (p11 - p00);
      // B = (p00, p11, p01): p = p00 + u (p11 - p00) + (v - u)(p01 - p00).
      if (v <= u)
        out = lerp3(at(0, 0), at(1, 0), at(1, 1), u - v, v);
      else
        out = lerp3(at(0, 0), at(1, 1), at(0, 1), u, v - u);
    }
    return true;
  }
  return false;
}

}  // namespace

std::vector<Vec2f> GridAttributes::grid_ordered(uint32_t geom, const std::vector<Vec2f>& values,
                                                const std::vector<uint32_t>& indices) const {
  if (!impl_) return {};
  return grid_ordered_impl(impl_->gs, geom, values, indices, nullptr);
}
std::vector<Vec3f> GridAttributes::grid_ordered(uint32_t geom, const std::vector<Vec3f>& values,
                                                const std::vector<uint32_t>& indices) const {
  if (!impl_) return {};
  return grid_ordered_impl(impl_->gs, geom, values, indices, nullptr);
}
bool GridAttributes::interpolate(const std::vector<Vec2f>& grid_values, const Hit& hit,
                                 Vec2f& out) const {
  return impl_ && interpolate_impl(*impl_, grid_values, hit, out);
}
bool GridAttributes::interpolate(const std::vector<Vec3f>& grid_values, const Hit& hit,
                                 Vec3f& out) const {
  return impl_ && interpolate_impl(*impl_, grid_values, hit, out);
}

}  // namespace slim
