#include "mesh/triangulate.h"

#include <string>

namespace slim {

TriangleMesh triangulate_fan(const std::vector<const PolyMesh*>& meshes) {
  TriangleMesh out;
  uint64_t nv = 0, nt = 0;
  for (const PolyMesh* m : meshes) {
    nv += m->positions.size();
    nt += m->fan_triangle_count();
    out.input_faces += m->face_count();
  }
  if (nv >= 0xffffffffull || nt >= 0xffffffffull)
    throw Error("scene too large: " + std::to_string(nv) + " vertices, " + std::to_string(nt) +
                " triangles (at most 2^32-1 of each)");
  out.input_triangles = nt;
  out.vertices.reserve(nv);
  out.tris.reserve(3 * nt);
  out.geom_ids.reserve(nt);
  out.prim_ids.reserve(nt);
  for (uint32_t g = 0; g < meshes.size(); ++g) {
    const PolyMesh& m = *meshes[g];
    uint32_t base = uint32_t(out.vertices.size());
    out.vertex_base.push_back(base);
    out.vertices.insert(out.vertices.end(), m.positions.begin(), m.positions.end());
    std::vector<uint8_t> finite(m.positions.size());
    for (size_t i = 0; i < m.positions.size(); ++i) finite[i] = is_finite(m.positions[i]);
    uint64_t c = 0;
    for (uint32_t f = 0; f < m.face_sizes.size(); ++f) {
      const uint32_t n = m.face_sizes[f];
      const uint32_t* idx = &m.face_indices[c];
      c += n;
      bool ok = true;
      for (uint32_t k = 0; k < n; ++k) ok = ok && finite[idx[k]];
      if (!ok) {
        out.skipped_faces++;
        continue;
      }
      for (uint32_t k = 1; k + 1 < n; ++k) {
        out.tris.push_back(base + idx[0]);
        out.tris.push_back(base + idx[k]);
        out.tris.push_back(base + idx[k + 1]);
        out.geom_ids.push_back(g);
        out.prim_ids.push_back(f);
      }
    }
  }
  return out;
}

}  // namespace slim
