// Scene loading of the Costa quantized n-gon mesh (Costa et al., WSCG 2013, section 3.1):
// triangles, quads as 4-vertex fans, and GLU's tessellation of larger polygons into triangles,
// fans and strips. See tessellate.h for the rules, the COMBINE policy and the fallbacks.
#include "mesh/tessellate.h"

#include <GL/glu.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "core/assert.h"

namespace slim {

// ---- geometry helpers -------------------------------------------------------------------------

void newell_normal(const Vec3f* positions, const uint32_t* idx, uint32_t n, double normal[3]) {
  // Newell's method: sum over edges of (y_i - y_j)(z_i + z_j), ... (twice the vector area).
  // Vertices are taken relative to the first one to keep the products small.
  double nx = 0, ny = 0, nz = 0;
  const Vec3f& o = positions[idx[0]];
  for (uint32_t i = 0; i < n; ++i) {
    const Vec3f& a = positions[idx[i]];
    const Vec3f& b = positions[idx[i + 1 == n ? 0 : i + 1]];
    double ax = double(a.x) - o.x, ay = double(a.y) - o.y, az = double(a.z) - o.z;
    double bx = double(b.x) - o.x, by = double(b.y) - o.y, bz = double(b.z) - o.z;
    nx += (ay - by) * (az + bz);
    ny += (az - bz) * (ax + bx);
    nz += (ax - bx) * (ay + by);
  }
  normal[0] = nx, normal[1] = ny, normal[2] = nz;
}

double projected_cover_error(const Vec3f* positions, const uint32_t* tris, uint64_t tri_count,
                             const double normal[3]) {
  double len = std::sqrt(normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]);
  if (!(len > 0)) return 1.0;
  double nh[3] = {normal[0] / len, normal[1] / len, normal[2] / len};
  double area = 0.5 * len;  // the polygon's projected area (Newell)
  double sum = 0, sum_abs = 0;
  for (uint64_t t = 0; t < tri_count; ++t) {
    const Vec3f& a = positions[tris[3 * t]];
    const Vec3f& b = positions[tris[3 * t + 1]];
    const Vec3f& c = positions[tris[3 * t + 2]];
    double e1[3] = {double(b.x) - a.x, double(b.y) - a.y, double(b.z) - a.z};
    double e2[3] = {double(c.x) - a.x, double(c.y) - a.y, double(c.z) - a.z};
    double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                    e1[0] * e2[1] - e1[1] * e2[0]};
    double at = 0.5 * (cr[0] * nh[0] + cr[1] * nh[1] + cr[2] * nh[2]);
    sum += at;
    sum_abs += std::fabs(at);
  }
  return std::max(std::fabs(sum_abs - area), std::fabs(sum - area)) / area;
}

// ---- GLU tessellator --------------------------------------------------------------------------

struct PolygonTessellator::Impl {
  GLUtesselator* tess = nullptr;
  // The polygon being tessellated.
  const Vec3f* positions = nullptr;
  const uint32_t* idx = nullptr;
  uint32_t n = 0;
  std::vector<double> coords;  // projected 2D coordinates (z = 0), 3 per corner, for GLU
  Tessellation* out = nullptr;
  TessMode mode = TessMode::Triangles;
  uint32_t group_first = 0;
  bool intersecting = false, error = false;

  // GLU vertex data are corner positions + 1 (GLU treats a null data pointer as "no data").
  static void* tag(uint32_t corner) { return reinterpret_cast<void*>(uintptr_t(corner) + 1); }
  static uint32_t corner(void* p) { return uint32_t(reinterpret_cast<uintptr_t>(p) - 1); }

  static void GLAPIENTRY on_begin(GLenum type, void* self) {
    auto* s = static_cast<Impl*>(self);
    if (type == GL_TRIANGLE_FAN)
      s->mode = TessMode::Fan;
    else if (type == GL_TRIANGLE_STRIP)
      s->mode = TessMode::Strip;
    else if (type == GL_TRIANGLES)
      s->mode = TessMode::Triangles;
    else
      s->error = true;  // GL_LINE_LOOP only happens with GLU_TESS_BOUNDARY_ONLY
    s->group_first = uint32_t(s->out->indices.size());
  }
  static void GLAPIENTRY on_vertex(void* data, void* self) {
    auto* s = static_cast<Impl*>(self);
    s->out->indices.push_back(corner(data));
  }
  static void GLAPIENTRY on_end(void* self) {
    auto* s = static_cast<Impl*>(self);
    uint32_t count = uint32_t(s->out->indices.size()) - s->group_first;
    if (count >= 3) s->out->groups.push_back({s->mode, s->group_first, count});
  }
  // GLU wants a vertex at coords = sum weight[k] * data[k]. We accept it only when every source
  // vertex with a non-zero weight is the same 3D point (coincident vertices): the combined vertex
  // is then that vertex. Anything else is a crossing of the projected boundary (tessellate.h).
  static void GLAPIENTRY on_combine(GLdouble[3], void* data[4], GLfloat weight[4], void** out_data,
                                    void* self) {
    auto* s = static_cast<Impl*>(self);
    void* first = nullptr;
    for (int k = 0; k < 4; ++k) {
      if (!data[k] || !(weight[k] > 0.0f)) continue;
      if (!first) {
        first = data[k];
        continue;
      }
      if (s->positions[s->idx[corner(data[k])]] != s->positions[s->idx[corner(first)]])
        s->intersecting = true;
    }
    if (!first) {
      s->intersecting = true;
      first = data[0] ? data[0] : tag(0);
    }
    *out_data = first;
  }
  static void GLAPIENTRY on_error(GLenum, void* self) { static_cast<Impl*>(self)->error = true; }
};

PolygonTessellator::PolygonTessellator() : impl_(new Impl) {
  GLUtesselator* t = gluNewTess();
  if (!t) {
    delete impl_;
    throw Error("GLU: gluNewTess failed (out of memory)");
  }
  impl_->tess = t;
  gluTessCallback(t, GLU_TESS_BEGIN_DATA, reinterpret_cast<_GLUfuncptr>(&Impl::on_begin));
  gluTessCallback(t, GLU_TESS_VERTEX_DATA, reinterpret_cast<_GLUfuncptr>(&Impl::on_vertex));
  gluTessCallback(t, GLU_TESS_END_DATA, reinterpret_cast<_GLUfuncptr>(&Impl::on_end));
  gluTessCallback(t, GLU_TESS_COMBINE_DATA, reinterpret_cast<_GLUfuncptr>(&Impl::on_combine));
  gluTessCallback(t, GLU_TESS_ERROR_DATA, reinterpret_cast<_GLUfuncptr>(&Impl::on_error));
  // No GLU_TESS_EDGE_FLAG callback: with one, GLU emits only GL_TRIANGLES (we want fans and
  // strips, paper section 3.1).
  gluTessProperty(t, GLU_TESS_WINDING_RULE, GLU_TESS_WINDING_ODD);
  gluTessNormal(t, 0.0, 0.0, 1.0);  // the coordinates we pass are already projected
}

PolygonTessellator::~PolygonTessellator() {
  gluDeleteTess(impl_->tess);
  delete impl_;
}

void PolygonTessellator::tessellate(const Vec3f* positions, const uint32_t* idx, uint32_t n,
                                    Tessellation& out, TessStats& stats) {
  out.groups.clear();
  out.indices.clear();
  out.fallback = false;
  stats.polygons++;
  auto fan = [&] {
    out.groups.clear();
    out.indices.clear();
    for (uint32_t k = 0; k < n; ++k) out.indices.push_back(k);
    out.groups.push_back({TessMode::Fan, 0, n});
    out.fallback = true;
  };

  // Project onto the plane perpendicular to the Newell normal (a right-handed frame e1, e2, N/|N|,
  // so that the polygon's boundary runs counter-clockwise in 2D).
  double N[3];
  newell_normal(positions, idx, n, N);
  double len = std::sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]);
  if (!(len > 0) || !std::isfinite(len)) {
    stats.fallback_degenerate++;
    return fan();
  }
  double w[3] = {N[0] / len, N[1] / len, N[2] / len};
  double h[3] = {1, 0, 0};  // any axis not parallel to w
  if (std::fabs(w[0]) > 0.6) h[0] = 0, h[1] = 1;
  double e1[3] = {h[1] * w[2] - h[2] * w[1], h[2] * w[0] - h[0] * w[2], h[0] * w[1] - h[1] * w[0]};
  double l1 = std::sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
  for (double& x : e1) x /= l1;
  double e2[3] = {w[1] * e1[2] - w[2] * e1[1], w[2] * e1[0] - w[0] * e1[2],
                  w[0] * e1[1] - w[1] * e1[0]};
  Impl& s = *impl_;
  s.positions = positions;
  s.idx = idx;
  s.n = n;
  s.out = &out;
  s.intersecting = s.error = false;
  s.coords.resize(3 * size_t(n));
  const Vec3f& o = positions[idx[0]];
  for (uint32_t k = 0; k < n; ++k) {
    const Vec3f& p = positions[idx[k]];
    double d[3] = {double(p.x) - o.x, double(p.y) - o.y, double(p.z) - o.z};
    // v = e1 x e2 = w: x along e1, y along e2 keeps the orientation about the normal.
    s.coords[3 * k] = d[0] * e1[0] + d[1] * e1[1] + d[2] * e1[2];
    s.coords[3 * k + 1] = d[0] * e2[0] + d[1] * e2[1] + d[2] * e2[2];
    s.coords[3 * k + 2] = 0.0;
  }
  gluTessBeginPolygon(s.tess, &s);
  gluTessBeginContour(s.tess);
  for (uint32_t k = 0; k < n; ++k) gluTessVertex(s.tess, &s.coords[3 * k], Impl::tag(k));
  gluTessEndContour(s.tess);
  gluTessEndPolygon(s.tess);

  if (s.intersecting) {
    stats.fallback_intersecting++;
    return fan();
  }
  if (s.error || out.groups.empty()) {
    stats.fallback_degenerate++;
    return fan();
  }
  // Acceptance: GLU's triangles cover the projected polygon exactly once.
  std::vector<uint32_t> tris;
  for (const TessGroup& g : out.groups) {
    const uint32_t* c = &out.indices[g.first];
    auto push = [&](uint32_t a, uint32_t b, uint32_t d) {
      tris.push_back(idx[a]);
      tris.push_back(idx[b]);
      tris.push_back(idx[d]);
    };
    if (g.mode == TessMode::Triangles) {
      for (uint32_t t = 0; t + 3 <= g.count; t += 3) push(c[t], c[t + 1], c[t + 2]);
    } else if (g.mode == TessMode::Fan) {
      for (uint32_t t = 1; t + 1 < g.count; ++t) push(c[0], c[t], c[t + 1]);
    } else {
      for (uint32_t t = 0; t + 2 < g.count; ++t)
        if (t & 1)
          push(c[t + 1], c[t], c[t + 2]);
        else
          push(c[t], c[t + 1], c[t + 2]);
    }
  }
  if (projected_cover_error(positions, tris.data(), tris.size() / 3, N) > 1e-4) {
    stats.fallback_area++;
    return fan();
  }
  stats.glu++;
}

// ---- loading (section 3.1) ----------------------------------------------------------------------

namespace {

constexpr uint64_t kMaxEntries = (uint64_t(1) << 31) - 1;

struct Loader {
  NgonMesh& m;

  void too_large() {
    throw Error("costa: scene too large: " + std::to_string(m.vertices.size()) + " vertices, " +
                std::to_string(m.faces.size()) +
                " face entries (at most 2^31 - 1 of each: face entries hold vertex << 1 | flag)");
  }
  // One primitive of k vertices v[0..k) (global indices); flag 1 = strip (used for k >= 5).
  void add(const uint32_t* v, uint32_t k, uint32_t flag, uint32_t face) {
    if (m.faces.size() + k > kMaxEntries) too_large();
    for (uint32_t j = 0; j < k; ++j)
      m.faces.push_back(j == 0 && k >= kFanStripFlagMin ? (v[0] << 1) | flag : v[j]);
    m.prim_offsets.push_back(uint32_t(m.faces.size()));
    m.prim_face.push_back(face);
    if (k == 3)
      m.triangles++;
    else if (k == 4)
      m.quads++;
    else if (flag)
      m.strips++;
    else
      m.fans++;
  }
};

}  // namespace

NgonMesh load_ngon_mesh(const MeshList& meshes) {
  NgonMesh m;
  Loader L{m};
  uint64_t nv = 0;
  for (const MeshView* p : meshes) {
    nv += p->positions.size();
    m.input_faces += p->face_count();
    m.input_triangles += p->fan_triangle_count();
  }
  if (nv > kMaxEntries) L.too_large();
  if (m.input_faces >= 0xffffffffull)
    throw Error("costa: scene too large: " + std::to_string(m.input_faces) +
                " faces (at most 2^32 - 2)");
  m.vertices.reserve(nv);
  m.prim_offsets.push_back(0);
  PolygonTessellator tess;
  Tessellation t;
  std::vector<uint32_t> gidx;
  uint32_t face_id = 0;
  for (const MeshView* p : meshes) {
    const MeshView& pm = *p;
    const uint32_t base = uint32_t(m.vertices.size());
    m.face_base.push_back(face_id);
    m.vertices.insert(m.vertices.end(), pm.positions.begin(), pm.positions.end());
    std::vector<uint8_t> finite(pm.positions.size());
    for (size_t i = 0; i < pm.positions.size(); ++i) finite[i] = is_finite(pm.positions[i]);
    uint64_t c = 0;
    for (uint32_t f = 0; f < pm.face_sizes.size(); ++f, ++face_id) {
      const uint32_t n = pm.face_sizes[f];
      const uint32_t* idx = &pm.face_indices[c];
      c += n;
      bool ok = true;
      for (uint32_t k = 0; k < n; ++k) ok = ok && finite[idx[k]];
      if (!ok) {
        m.skipped_faces++;
        continue;
      }
      gidx.resize(n);
      for (uint32_t k = 0; k < n; ++k) gidx[k] = base + idx[k];
      if (n <= 4) {  // triangle, or quad as a 4-vertex fan
        L.add(gidx.data(), n, 0, face_id);
        continue;
      }
      tess.tessellate(m.vertices.data(), gidx.data(), n, t, m.tess);
      uint32_t v[4];
      for (const TessGroup& g : t.groups) {
        const uint32_t* cc = &t.indices[g.first];
        if (g.mode == TessMode::Triangles) {
          for (uint32_t k = 0; k + 3 <= g.count; k += 3) {
            for (int j = 0; j < 3; ++j) v[j] = gidx[cc[k + j]];
            L.add(v, 3, 0, face_id);
          }
          continue;
        }
        if (g.count == 4 && g.mode == TessMode::Strip) {
          // A 4-vertex strip (v0,v1,v2), (v2,v1,v3) is the quad (v1, v3, v2, v0): same
          // triangles, same orientation, so 4 vertices always mean "quad" (Listing 5).
          v[0] = gidx[cc[1]], v[1] = gidx[cc[3]], v[2] = gidx[cc[2]], v[3] = gidx[cc[0]];
          L.add(v, 4, 0, face_id);
          continue;
        }
        std::vector<uint32_t> vv(g.count);
        for (uint32_t k = 0; k < g.count; ++k) vv[k] = gidx[cc[k]];
        L.add(vv.data(), g.count, g.mode == TessMode::Strip ? 1 : 0, face_id);
      }
    }
  }
  m.face_base.push_back(face_id);
  return m;
}

void primitive_triangles(const NgonMesh& m, size_t i, std::vector<uint32_t>& tris) {
  const uint32_t o = m.prim_offsets[i], n = m.prim_size(i);
  const uint32_t* f = &m.faces[o];
  auto push = [&](uint32_t a, uint32_t b, uint32_t c) {
    tris.push_back(a);
    tris.push_back(b);
    tris.push_back(c);
  };
  if (n < kFanStripFlagMin) {  // triangle or quad: a fan
    for (uint32_t k = 1; k + 1 < n; ++k) push(f[0], f[k], f[k + 1]);
    return;
  }
  const uint32_t v0 = f[0] >> 1;
  if ((f[0] & 1) == 0) {
    for (uint32_t k = 1; k + 1 < n; ++k) push(v0, f[k], f[k + 1]);
    return;
  }
  for (uint32_t t = 0; t + 2 < n; ++t) {
    uint32_t a = t == 0 ? v0 : f[t], b = f[t + 1], c = f[t + 2];
    if (t & 1)
      push(b, a, c);
    else
      push(a, b, c);
  }
}

void renumber_vertices(NgonMesh& m) {
  constexpr uint32_t kNone = 0xffffffffu;
  const size_t nv = m.vertices.size();
  std::vector<uint32_t> to(nv, kNone);
  uint32_t next = 0;
  auto take = [&](uint32_t v) {  // indices are in range: load_ngon_mesh checked the meshes
    SLIM_ASSERT(v < nv);
    if (to[v] == kNone) to[v] = next++;
  };
  for (size_t i = 0; i < m.prim_count(); ++i)
    if (m.prim_size(i) >= kFanStripFlagMin) take(m.faces[m.prim_offsets[i]] >> 1);
  for (size_t i = 0; i < m.prim_count(); ++i) {
    const uint32_t o0 = m.prim_offsets[i], o1 = m.prim_offsets[i + 1];
    for (uint32_t j = o0; j < o1; ++j)
      take(j == o0 && o1 - o0 >= kFanStripFlagMin ? m.faces[j] >> 1 : m.faces[j]);
  }
  for (size_t v = 0; v < nv; ++v) take(uint32_t(v));
  std::vector<Vec3f> moved(nv);
  for (size_t v = 0; v < nv; ++v) moved[to[v]] = m.vertices[v];
  m.vertices = std::move(moved);
  for (size_t i = 0; i < m.prim_count(); ++i) {
    const uint32_t o0 = m.prim_offsets[i], o1 = m.prim_offsets[i + 1];
    for (uint32_t j = o0; j < o1; ++j) {
      uint32_t& f = m.faces[j];
      if (j == o0 && o1 - o0 >= kFanStripFlagMin)
        f = (to[f >> 1] << 1) | (f & 1);
      else
        f = to[f];
    }
  }
}

NgonMesh triangulate_ngon_mesh(const NgonMesh& in) {
  NgonMesh m;
  m.vertices = in.vertices;
  m.face_base = in.face_base;
  m.input_faces = in.input_faces;
  m.skipped_faces = in.skipped_faces;
  m.input_triangles = in.input_triangles;
  m.tess = in.tess;
  uint64_t tri_count = in.triangle_count();
  m.faces.reserve(3 * tri_count);
  m.prim_offsets.reserve(tri_count + 1);
  m.prim_face.reserve(tri_count);
  m.prim_offsets.push_back(0);
  std::vector<uint32_t> tris;
  for (size_t i = 0; i < in.prim_count(); ++i) {
    tris.clear();
    primitive_triangles(in, i, tris);
    for (size_t k = 0; k < tris.size(); ++k) {
      m.faces.push_back(tris[k]);
      if (k % 3 == 2) {
        m.prim_offsets.push_back(uint32_t(m.faces.size()));
        m.prim_face.push_back(in.prim_face[i]);
      }
    }
  }
  m.triangles = m.prim_count();
  return m;
}

}  // namespace slim
