// save_obj (slimrt/mesh.h): a PolyMesh as a Wavefront OBJ that load() reads back exactly.
#include <cstdio>
#include <memory>
#include <string>

#include "slimrt/error.h"
#include "slimrt/mesh.h"
#include "slimrt/output.h"

namespace slim {

void save_obj(const PolyMesh& m, const std::string& path) {
  check_mesh(m);
  // Per-vertex attributes (an attribute array without indices) use the position's index.
  const bool normals = !m.normals.empty(), uvs = !m.uvs.empty();
  const bool normal_per_corner = !m.normal_indices.empty(), uv_per_corner = !m.uv_indices.empty();
  write_atomically(path, [&](const std::string& tmp) {
    std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(tmp.c_str(), "wb"), std::fclose);
    if (!f) throw Error(path + ": cannot be written");
    FILE* out = f.get();
    auto put = [&](int n) {
      if (n < 0) throw Error(path + ": write failed");
    };
    put(std::fprintf(out, "# %s, written by slimrt\n", m.name.empty() ? "mesh" : m.name.c_str()));
    // %.9g: 9 significant digits give back every float exactly.
    for (const Vec3f& p : m.positions) put(std::fprintf(out, "v %.9g %.9g %.9g\n", p.x, p.y, p.z));
    for (const Vec2f& t : m.uvs) put(std::fprintf(out, "vt %.9g %.9g\n", t.x, t.y));
    for (const Vec3f& n : m.normals) put(std::fprintf(out, "vn %.9g %.9g %.9g\n", n.x, n.y, n.z));
    uint64_t c = 0;
    uint32_t object = ~0u;
    for (size_t face = 0; face < m.face_count(); ++face) {
      const uint32_t o = m.face_object.empty() ? 0 : m.face_object[face];
      if (o != object && !m.object_names.empty()) {
        const std::string name =
            o < m.object_names.size() ? m.object_names[o] : "object" + std::to_string(o);
        put(std::fprintf(out, "o %s\n", name.c_str()));
      }
      object = o;
      put(std::fputc('f', out) == EOF ? -1 : 0);
      for (uint32_t k = 0; k < m.face_sizes[face]; ++k, ++c) {
        const uint32_t v = m.face_indices[c] + 1;  // OBJ counts from 1
        put(std::fprintf(out, " %u", v));
        if (uvs) put(std::fprintf(out, "/%u", uv_per_corner ? m.uv_indices[c] + 1 : v));
        if (normals)
          put(std::fprintf(out, uvs ? "/%u" : "//%u",
                           normal_per_corner ? m.normal_indices[c] + 1 : v));
      }
      put(std::fputc('\n', out) == EOF ? -1 : 0);
    }
    if (std::fflush(out) != 0 || std::ferror(out)) throw Error(path + ": write failed");
  });
}

}  // namespace slim
