// PolyMesh and MeshView helpers: offsets, bounds, validation (check_mesh) and statistics
// (summarize).
#include <algorithm>

#include "slimrt/mesh.h"

namespace slim {

MeshView::MeshView(const PolyMesh& m)
    : name(m.name),
      positions(m.positions),
      face_sizes(std::span<const uint32_t>(m.face_sizes)),
      face_indices(m.face_indices),
      normals(m.normals),
      normal_indices(m.normal_indices),
      uvs(m.uvs),
      uv_indices(m.uv_indices),
      face_object(m.face_object),
      object_names(m.object_names) {}

MeshView MeshView::triangles(const Vec3f* positions, size_t vertex_count, const uint32_t* indices,
                             size_t triangle_count, std::string name) {
  MeshView v;
  v.name = std::move(name);
  v.positions = {positions, vertex_count};
  v.face_sizes = FaceSizes::uniform(3, triangle_count);
  v.face_indices = {indices, 3 * triangle_count};
  return v;
}

uint64_t MeshView::fan_triangle_count() const {
  if (!face_sizes.data()) {
    const uint32_t s = face_sizes.uniform_size();
    return s >= 3 ? uint64_t(s - 2) * face_sizes.size() : 0;
  }
  uint64_t n = 0;
  for (uint32_t s : face_sizes) n += s >= 3 ? s - 2 : 0;
  return n;
}

std::vector<uint64_t> MeshView::face_offsets() const {
  std::vector<uint64_t> off(face_sizes.size() + 1, 0);
  for (size_t i = 0; i < face_sizes.size(); ++i) off[i + 1] = off[i] + face_sizes[i];
  return off;
}

Box3f MeshView::bounds() const {
  Box3f b;
  for (const Vec3f& p : positions)
    if (is_finite(p)) b.extend(p);
  return b;
}

uint64_t PolyMesh::fan_triangle_count() const { return MeshView(*this).fan_triangle_count(); }

std::vector<uint64_t> PolyMesh::face_offsets() const { return MeshView(*this).face_offsets(); }

Box3f PolyMesh::bounds() const { return MeshView(*this).bounds(); }

namespace {

std::string label(const std::string& name) { return name.empty() ? std::string("mesh") : name; }
std::string label(const MeshView& m) { return label(m.name); }

[[noreturn]] void bad_face(const MeshView& m, uint64_t f, const std::string& what) {
  throw Error(label(m) + ": face " + std::to_string(f) + ": " + what);
}

// The first corner c of `index` with index[c] >= limit, or index.size(). A plain linear scan (no
// per-face offsets array: the check runs on every build and is a stream over the corners).
uint64_t first_out_of_range(std::span<const uint32_t> index, size_t limit) {
  const uint32_t* p = index.data();
  const uint64_t n = index.size();
  if (limit > 0xffffffffull) return n;  // every uint32 index is in range
  const uint32_t lim = uint32_t(limit);
  constexpr uint64_t kBlock = 4096;
  for (uint64_t b = 0; b < n; b += kBlock) {
    const uint64_t e = std::min(n, b + kBlock);
    uint32_t mx = 0;
    for (uint64_t c = b; c < e; ++c) mx = std::max(mx, p[c]);
    if (mx >= lim)
      for (uint64_t c = b; c < e; ++c)
        if (p[c] >= lim) return c;
  }
  return n;
}

// The face of corner c (face sizes add up to the corner count).
uint64_t face_of_corner(const MeshView& m, uint64_t c) {
  if (const uint32_t s = m.face_sizes.uniform_size())
    return std::min<uint64_t>(c / s, m.face_sizes.size());
  uint64_t k = 0;
  for (size_t f = 0; f < m.face_sizes.size(); ++f) {
    k += m.face_sizes[f];
    if (c < k) return f;
  }
  return m.face_sizes.size();
}

// Checks a per-corner attribute: either index array parallel to face_indices, or per vertex.
void check_attribute(const MeshView& m, const char* attr, size_t attr_count,
                     std::span<const uint32_t> index) {
  const std::string name = attr;
  if (index.empty()) {
    if (attr_count != 0 && attr_count != m.positions.size())
      throw Error(label(m) + ": " + name + " has " + std::to_string(attr_count) +
                  " entries and no " + name + " indices; expected one per vertex (" +
                  std::to_string(m.positions.size()) + ")");
    return;
  }
  if (index.size() != m.face_indices.size())
    throw Error(label(m) + ": " + name + " index array has " + std::to_string(index.size()) +
                " entries; expected one per corner (" + std::to_string(m.face_indices.size()) +
                ")");
  const uint64_t c = first_out_of_range(index, attr_count);
  if (c < index.size())
    bad_face(m, face_of_corner(m, c),
             name + " index " + std::to_string(index[c]) + " out of range (" +
                 std::to_string(attr_count) + " " + name + ")");
}

// A view's array that claims entries but has no data (a PolyMesh's never does).
void check_not_null(const MeshView& m, const char* field, const void* data, size_t n) {
  if (!data && n)
    throw Error(label(m) + ": " + field + " is null but has " + std::to_string(n) + " entries");
}

}  // namespace

void check_mesh(const PolyMesh& m) { check_mesh(MeshView(m)); }

void check_mesh(const MeshView& m) {
  check_not_null(m, "positions", m.positions.data(), m.positions.size());
  check_not_null(m, "face_indices", m.face_indices.data(), m.face_indices.size());
  check_not_null(m, "normals", m.normals.data(), m.normals.size());
  check_not_null(m, "normal_indices", m.normal_indices.data(), m.normal_indices.size());
  check_not_null(m, "uvs", m.uvs.data(), m.uvs.size());
  check_not_null(m, "uv_indices", m.uv_indices.data(), m.uv_indices.size());
  check_not_null(m, "face_object", m.face_object.data(), m.face_object.size());
  check_not_null(m, "object_names", m.object_names.data(), m.object_names.size());
  uint64_t corners = 0;
  for (size_t f = 0; f < m.face_sizes.size(); ++f) {
    if (m.face_sizes[f] < 3)
      bad_face(m, f, "has " + std::to_string(m.face_sizes[f]) + " vertices; expected at least 3");
    corners += m.face_sizes[f];
  }
  if (corners != m.face_indices.size())
    throw Error(label(m) + ": face sizes add up to " + std::to_string(corners) +
                " corners but face_indices has " + std::to_string(m.face_indices.size()));
  const size_t nv = m.positions.size();
  const uint64_t c = first_out_of_range(m.face_indices, nv);
  if (c < m.face_indices.size())
    bad_face(m, face_of_corner(m, c),
             "vertex index " + std::to_string(m.face_indices[c]) + " out of range (" +
                 std::to_string(nv) + " vertices)");
  check_attribute(m, "normals", m.normals.size(), m.normal_indices);
  check_attribute(m, "uvs", m.uvs.size(), m.uv_indices);
  if (!m.face_object.empty()) {
    if (m.face_object.size() != m.face_sizes.size())
      throw Error(label(m) + ": face_object has " + std::to_string(m.face_object.size()) +
                  " entries; expected one per face (" + std::to_string(m.face_sizes.size()) + ")");
    if (!m.object_names.empty())
      for (size_t f = 0; f < m.face_object.size(); ++f)
        if (m.face_object[f] >= m.object_names.size())
          bad_face(m, f,
                   "object id " + std::to_string(m.face_object[f]) + " out of range (" +
                       std::to_string(m.object_names.size()) + " object names)");
  }
}

namespace {

// A face is degenerate if it repeats a vertex index or all its fan triangles have zero area
// (cross products in double, so float positions give an exact zero test).
bool is_degenerate(const Vec3f* p, const uint32_t* idx, uint32_t k) {
  if (k <= 16) {
    for (uint32_t i = 0; i < k; ++i)
      for (uint32_t j = i + 1; j < k; ++j)
        if (idx[i] == idx[j]) return true;
  } else {
    std::vector<uint32_t> s(idx, idx + k);
    std::sort(s.begin(), s.end());
    if (std::adjacent_find(s.begin(), s.end()) != s.end()) return true;
  }
  const Vec3f a = p[idx[0]];
  double area = 0;
  for (uint32_t i = 1; i + 1 < k; ++i) {
    const Vec3f b = p[idx[i]], c = p[idx[i + 1]];
    const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
    const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
    const double cx = uy * vz - uz * vy, cy = uz * vx - ux * vz, cz = ux * vy - uy * vx;
    area += std::sqrt(cx * cx + cy * cy + cz * cz);
  }
  return area == 0;  // NaN (non-finite corner) is not counted as zero area
}

}  // namespace

MeshSummary summarize(const PolyMesh& m) {
  MeshSummary s;
  s.vertices = m.positions.size();
  s.faces = m.face_sizes.size();
  s.fan_triangles = m.fan_triangle_count();
  for (const Vec3f& p : m.positions) s.nonfinite_vertices += is_finite(p) ? 0 : 1;
  uint64_t c = 0;
  for (uint32_t k : m.face_sizes) {
    if (k == 3)
      ++s.triangles;
    else if (k == 4)
      ++s.quads;
    else if (k > 4)
      ++s.ngons;
    // Tolerates malformed meshes (summaries are printed for diagnosis): skip what check_mesh
    // rejects.
    bool valid = k >= 3 && c + k <= m.face_indices.size();
    for (uint32_t i = 0; valid && i < k; ++i) valid = m.face_indices[c + i] < m.positions.size();
    if (valid && is_degenerate(m.positions.data(), m.face_indices.data() + c, k))
      ++s.degenerate_faces;
    c += k;
  }
  s.bounds = m.bounds();
  return s;
}

PolyMesh reorder_faces(const PolyMesh& m, std::span<const uint32_t> order) {
  check_mesh(m);
  const size_t nf = m.face_count();
  const std::string name = m.name.empty() ? std::string("mesh") : m.name;
  if (order.size() != nf)
    throw Error("reorder_faces: " + name + " has " + std::to_string(nf) + " faces, the order " +
                std::to_string(order.size()));
  std::vector<bool> seen(nf);
  for (size_t i = 0; i < nf; ++i) {
    const uint32_t f = order[i];
    if (f >= nf || seen[f])
      throw Error("reorder_faces: order[" + std::to_string(i) + "] = " + std::to_string(f) +
                  (f >= nf ? " is not a face of " : " comes twice for ") + name);
    seen[f] = true;
  }
  const std::vector<uint64_t> off = m.face_offsets();
  PolyMesh r;
  r.name = m.name;
  r.positions = m.positions;
  r.normals = m.normals;
  r.uvs = m.uvs;
  r.object_names = m.object_names;
  r.face_sizes.reserve(nf);
  r.face_indices.reserve(m.face_indices.size());
  const bool normals = !m.normal_indices.empty(), uvs = !m.uv_indices.empty();
  if (normals) r.normal_indices.reserve(m.normal_indices.size());
  if (uvs) r.uv_indices.reserve(m.uv_indices.size());
  if (!m.face_object.empty()) r.face_object.reserve(nf);
  for (const uint32_t f : order) {
    r.face_sizes.push_back(m.face_sizes[f]);
    auto copy = [&](const std::vector<uint32_t>& from, std::vector<uint32_t>& to) {
      to.insert(to.end(), from.begin() + ptrdiff_t(off[f]), from.begin() + ptrdiff_t(off[f + 1]));
    };
    copy(m.face_indices, r.face_indices);
    if (normals) copy(m.normal_indices, r.normal_indices);
    if (uvs) copy(m.uv_indices, r.uv_indices);
    if (!m.face_object.empty()) r.face_object.push_back(m.face_object[f]);
  }
  return r;
}

}  // namespace slim
