// save_obj (slimrt/mesh.h): a PolyMesh as a Wavefront OBJ that load() reads back.
#include <cmath>
#include <cstdio>
#include <string>

#include "slimrt/error.h"
#include "slimrt/mesh.h"
#include "slimrt/output.h"

namespace slim {

namespace {

// A name on one OBJ line: control characters (a line break would end the line) become '_'.
std::string one_line(std::string s) {
  for (char& c : s)
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) c = '_';
  return s;
}

// Throws naming the first NaN or Inf of `n` floats (OBJ has no text for them that load() reads).
void check_finite(const float* p, size_t n, size_t per, const char* what, const std::string& path) {
  for (size_t i = 0; i < n; ++i)
    if (!std::isfinite(p[i]))
      throw Error(path + ": cannot write " + what + " " + std::to_string(i / per) +
                  ": a NaN or Inf coordinate (OBJ holds finite numbers only)");
}

}  // namespace

void save_obj(const PolyMesh& m, const std::string& path) {
  check_mesh(m);
  check_finite(reinterpret_cast<const float*>(m.positions.data()), 3 * m.positions.size(), 3,
               "vertex", path);
  check_finite(reinterpret_cast<const float*>(m.normals.data()), 3 * m.normals.size(), 3, "normal",
               path);
  check_finite(reinterpret_cast<const float*>(m.uvs.data()), 2 * m.uvs.size(), 2, "uv", path);
  // Per-vertex attributes (an attribute array without indices) use the position's index.
  const bool normals = !m.normals.empty(), uvs = !m.uvs.empty();
  const bool normal_per_corner = !m.normal_indices.empty(), uv_per_corner = !m.uv_indices.empty();
  const bool objects = !m.face_object.empty() || !m.object_names.empty();
  write_atomically(path, [&](const std::string& tmp) {
    FILE* out = std::fopen(tmp.c_str(), "wb");
    if (!out) throw Error(path + ": cannot be written");
    bool ok = true;
    auto put = [&](int n) { ok = ok && n >= 0; };
    put(std::fprintf(out, "# %s, written by slimrt\n",
                     one_line(m.name.empty() ? "mesh" : m.name).c_str()));
    // %.9g: 9 significant digits give back every float exactly.
    for (const Vec3f& p : m.positions) put(std::fprintf(out, "v %.9g %.9g %.9g\n", p.x, p.y, p.z));
    for (const Vec2f& t : m.uvs) put(std::fprintf(out, "vt %.9g %.9g\n", t.x, t.y));
    for (const Vec3f& n : m.normals) put(std::fprintf(out, "vn %.9g %.9g %.9g\n", n.x, n.y, n.z));
    uint64_t c = 0;
    uint32_t object = ~0u;
    for (size_t face = 0; face < m.face_count() && ok; ++face) {
      const uint32_t o = m.face_object.empty() ? 0 : m.face_object[face];
      if (objects && o != object) {
        const std::string name = o < m.object_names.size() && !m.object_names[o].empty()
                                     ? m.object_names[o]
                                     : "object" + std::to_string(o);
        put(std::fprintf(out, "o %s\n", one_line(name).c_str()));
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
    ok = ok && std::fflush(out) == 0 && !std::ferror(out);
    ok = std::fclose(out) == 0 && ok;
    if (!ok) throw Error(path + ": write failed");
  });
}

}  // namespace slim
