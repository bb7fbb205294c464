// PolyMesh helpers: placeholder until implemented.
#include "slimrt/mesh.h"

namespace slim {
uint64_t PolyMesh::fan_triangle_count() const {
  uint64_t n = 0;
  for (uint32_t s : face_sizes) n += s >= 3 ? s - 2 : 0;
  return n;
}
std::vector<uint64_t> PolyMesh::face_offsets() const {
  std::vector<uint64_t> off(face_sizes.size() + 1, 0);
  for (size_t i = 0; i < face_sizes.size(); ++i) off[i + 1] = off[i] + face_sizes[i];
  return off;
}
Box3f PolyMesh::bounds() const {
  Box3f b;
  for (const Vec3f& p : positions)
    if (is_finite(p)) b.extend(p);
  return b;
}
void check_mesh(const PolyMesh&) {}
MeshSummary summarize(const PolyMesh& m) {
  MeshSummary s;
  s.vertices = m.positions.size();
  s.faces = m.face_sizes.size();
  s.fan_triangles = m.fan_triangle_count();
  s.bounds = m.bounds();
  return s;
}
}  // namespace slim
