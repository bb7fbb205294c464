// Triangle leaf formats (Embree's Triangle4v / Triangle4i counterparts):
//   Tri4v  176 B  4 triangles with pre-gathered vertices, SoA, + geomID/primID per triangle
//   Tri4i   80 B  4 triangles as 3 vertex indices into one shared vertex array + geomID/primID
// Both are tested 4 at a time with the watertight test (core/watertight.h). Blocks with fewer
// than 4 triangles repeat their last triangle (the duplicate gives the same hit, so no lane mask
// is needed on the hot path) with primID = kInvalidID.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "core/hash.h"
#include "core/ray.h"
#include "core/simd.h"
#include "core/watertight.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

// Triangles prepared from the input meshes (mesh/triangulate.h): the build-time source.
struct TriangleSource {
  const Vec3f* vertices = nullptr;
  const uint32_t* tris = nullptr;      // 3 vertex indices per triangle
  const uint32_t* geom_ids = nullptr;  // input mesh per triangle
  const uint32_t* prim_ids = nullptr;  // input face per triangle
};

// 64-bit key of a triangle (vertex bits + ids) for validate()'s "every triangle referenced once"
// fingerprint; never 0 (core/hash.h).
inline uint64_t triangle_key(const Vec3f& a, const Vec3f& b, const Vec3f& c, uint32_t geom,
                             uint32_t prim) {
  uint32_t w[11];
  std::memcpy(w, &a, 12);
  std::memcpy(w + 3, &b, 12);
  std::memcpy(w + 6, &c, 12);
  w[9] = geom;
  w[10] = prim;
  return nh_key(w, sizeof(w));
}

namespace detail {

// Ray-space transform of 4 vertices stored SoA as p[axis][lane].
SLIM_INLINE RayVertex<simd::vfloat4> to_ray_space4(const WatertightRay& r, const float (*p)[4]) {
  using namespace simd;
  vfloat4 ax = vfloat4::loadu(p[r.kx]) - vfloat4(r.ox);
  vfloat4 ay = vfloat4::loadu(p[r.ky]) - vfloat4(r.oy);
  vfloat4 az = vfloat4::loadu(p[r.kz]) - vfloat4(r.oz);
  return {fnmadd(vfloat4(r.Sx), az, ax), fnmadd(vfloat4(r.Sy), az, ay), vfloat4(r.Sz) * az};
}

// Number of lanes that hold real triangles (statistics and validation only): padding lanes repeat
// the last triangle with primID = kInvalidID. Their hits tie with the real lane's, and the closest
// lane search keeps the lowest lane on ties, so a padding lane is never reported.
SLIM_INLINE int distinct_lanes(const uint32_t* prim) {
  int n = 0;
  for (int i = 0; i < 4; ++i) n += prim[i] != kInvalidID;
  return n;
}

// Lane of m with the smallest t.
SLIM_INLINE int closest_lane(uint32_t m, const simd::vfloat4& t) {
  alignas(16) float tt[4];
  t.storeu(tt);
  int best = simd::pop_lowest(m);
  while (m) {
    int i = simd::pop_lowest(m);
    if (tt[i] < tt[best]) best = i;
  }
  return best;
}

// Fills the hit record from lane i (vertices p0, p1, p2 of that triangle).
SLIM_INLINE void record_hit(float t, float u, float v, Vec3f p0, Vec3f p1, Vec3f p2, uint32_t geom,
                            uint32_t prim, TravRay& ray, HitRecord& hit) {
  hit.t = t;
  hit.u = u;
  hit.v = v;
  hit.Ng = cross(p1 - p0, p2 - p0);
  hit.geomID = geom;
  hit.primID = prim;
  hit.kind = PrimKind::Triangle;
  ray.tfar = t;
}

}  // namespace detail

// Build-side helpers shared by the triangle leaf formats.
struct TriangleSourceOps {
  static Box3f source_bounds(const TriangleSource& s, uint32_t t) {
    Box3f b;
    for (int k = 0; k < 3; ++k) b.extend(s.vertices[s.tris[3 * t + k]]);
    return b;
  }
  static uint64_t source_key(const TriangleSource& s, uint32_t t) {
    const uint32_t* v = &s.tris[3 * t];
    return triangle_key(s.vertices[v[0]], s.vertices[v[1]], s.vertices[v[2]], s.geom_ids[t],
                        s.prim_ids[t]);
  }
  // Exact duplicates, which the BVH2 builder may drop (Bvh2BuildConfig::duplicate_key): the
  // same three vertex positions (bit for bit) in any rotation, i.e. the same surface facing the
  // same way. The key hashes the smallest of the three rotations, so duplicates share it.
  static std::array<uint32_t, 9> rotation(const TriangleSource& s, uint32_t t, int r) {
    std::array<uint32_t, 9> w;
    for (int k = 0; k < 3; ++k)
      std::memcpy(&w[3 * k], &s.vertices[s.tris[3 * t + (k + r) % 3]], 12);
    return w;
  }
  static uint64_t duplicate_key(const TriangleSource& s, uint32_t t) {
    const std::array<uint32_t, 9> w =
        std::min({rotation(s, t, 0), rotation(s, t, 1), rotation(s, t, 2)});
    return nh_key(w.data(), sizeof(w));
  }
  static bool same_surface(const TriangleSource& s, uint32_t a, uint32_t b) {
    const std::array<uint32_t, 9> wa = rotation(s, a, 0);
    for (int r = 0; r < 3; ++r)
      if (rotation(s, b, r) == wa) return true;
    return false;
  }
};

struct Tri4vBlock {
  float v[3][3][4];  // 144 B: [corner][axis][lane]
  uint32_t geom[4];  // 16 B
  uint32_t prim[4];  // 16 B
};
static_assert(sizeof(Tri4vBlock) == 176, "Triangle4v block is 176 bytes");

// Leaf format: 4 pre-gathered triangles.
struct Tri4v : TriangleSourceOps {
  struct Context {};
  static constexpr uint32_t kBlockPrims = 4;
  static constexpr uint32_t kBlockBytes = sizeof(Tri4vBlock);

  // Scene files' structure check: a block refers to nothing outside itself.
  static const char* check_block(const Context&, const uint8_t*) { return nullptr; }

  static void encode(const TriangleSource& src, const uint32_t* prims, uint32_t n, uint8_t* out) {
    auto* b = reinterpret_cast<Tri4vBlock*>(out);
    for (uint32_t l = 0; l < 4; ++l) {
      uint32_t t = prims[l < n ? l : n - 1];
      for (int k = 0; k < 3; ++k) {
        const Vec3f& p = src.vertices[src.tris[3 * t + k]];
        b->v[k][0][l] = p.x;
        b->v[k][1][l] = p.y;
        b->v[k][2][l] = p.z;
      }
      b->geom[l] = src.geom_ids[t];
      b->prim[l] = l < n ? src.prim_ids[t] : kInvalidID;
    }
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context&, const uint8_t* p, TravRay& ray, HitRecord& hit,
                                    Stats& st) {
    using namespace simd;
    const auto* b = reinterpret_cast<const Tri4vBlock*>(p);
    if constexpr (!std::is_same_v<Stats, NoStats>) st.prims(detail::distinct_lanes(b->prim));
    RayVertex<vfloat4> A = detail::to_ray_space4(ray.wt, b->v[0]);
    RayVertex<vfloat4> B = detail::to_ray_space4(ray.wt, b->v[1]);
    RayVertex<vfloat4> C = detail::to_ray_space4(ray.wt, b->v[2]);
    vfloat4 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, 0xF, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    int i = detail::closest_lane(m, t);
    auto vert = [&](int k) { return Vec3f(b->v[k][0][i], b->v[k][1][i], b->v[k][2][i]); };
    detail::record_hit(t[i], u[i], v[i], vert(0), vert(1), vert(2), b->geom[i], b->prim[i], ray,
                       hit);
    return true;
  }

  // Bounds and key of each distinct triangle of a block (validation).
  template <class F>
  static void visit(const Context&, const uint8_t* p, F&& fn) {
    const auto* b = reinterpret_cast<const Tri4vBlock*>(p);
    int n = detail::distinct_lanes(b->prim);
    for (int i = 0; i < n; ++i) {
      Vec3f c[3];
      Box3f box;
      for (int k = 0; k < 3; ++k) {
        c[k] = Vec3f(b->v[k][0][i], b->v[k][1][i], b->v[k][2][i]);
        box.extend(c[k]);
      }
      fn(box, triangle_key(c[0], c[1], c[2], b->geom[i], b->prim[i]));
    }
  }
};

struct Tri4iBlock {
  uint32_t v[3][4];  // 48 B: [corner][lane] vertex indices into the shared vertex array
  uint32_t geom[4];  // 16 B
  uint32_t prim[4];  // 16 B
};
static_assert(sizeof(Tri4iBlock) == 80, "Triangle4i block is 80 bytes");

// Leaf format: 4 triangles as vertex indices into one shared vertex array.
struct Tri4i : TriangleSourceOps {
  struct Context {
    const Vec3f* vertices = nullptr;
    uint64_t vertex_count = 0;  // scene files: section size and structure check
  };
  static constexpr uint32_t kBlockPrims = 4;
  static constexpr uint32_t kBlockBytes = sizeof(Tri4iBlock);

  // Scene files: the shared vertex array; the structure check of a block (indices in range).
  template <class V>
  static void context_sections(V& v, const std::string& p, Context& c) {
    v.array(p + "tri4i.vertices", c.vertices, c.vertex_count);
  }
  static const char* check_block(const Context& ctx, const uint8_t* p) {
    Tri4iBlock b;
    std::memcpy(&b, p, sizeof b);
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 4; ++l)
        if (b.v[k][l] >= ctx.vertex_count) return "vertex index beyond the vertex array";
    return nullptr;
  }

  static void encode(const TriangleSource& src, const uint32_t* prims, uint32_t n, uint8_t* out) {
    auto* b = reinterpret_cast<Tri4iBlock*>(out);
    for (uint32_t l = 0; l < 4; ++l) {
      uint32_t t = prims[l < n ? l : n - 1];
      for (int k = 0; k < 3; ++k) b->v[k][l] = src.tris[3 * t + k];
      b->geom[l] = src.geom_ids[t];
      b->prim[l] = l < n ? src.prim_ids[t] : kInvalidID;
    }
  }

  static SLIM_INLINE void gather(const Context& ctx, const Tri4iBlock* b, float (*out)[3][4]) {
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 4; ++l) {
        const Vec3f& p = ctx.vertices[b->v[k][l]];
        out[k][0][l] = p.x;
        out[k][1][l] = p.y;
        out[k][2][l] = p.z;
      }
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect(const Context& ctx, const uint8_t* p, TravRay& ray,
                                    HitRecord& hit, Stats& st) {
    using namespace simd;
    const auto* b = reinterpret_cast<const Tri4iBlock*>(p);
    alignas(16) float vv[3][3][4];
    gather(ctx, b, vv);
    if constexpr (!std::is_same_v<Stats, NoStats>) st.prims(detail::distinct_lanes(b->prim));
    RayVertex<vfloat4> A = detail::to_ray_space4(ray.wt, vv[0]);
    RayVertex<vfloat4> B = detail::to_ray_space4(ray.wt, vv[1]);
    RayVertex<vfloat4> C = detail::to_ray_space4(ray.wt, vv[2]);
    vfloat4 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, 0xF, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    int i = detail::closest_lane(m, t);
    detail::record_hit(t[i], u[i], v[i], ctx.vertices[b->v[0][i]], ctx.vertices[b->v[1][i]],
                       ctx.vertices[b->v[2][i]], b->geom[i], b->prim[i], ray, hit);
    return true;
  }

  template <class F>
  static void visit(const Context& ctx, const uint8_t* p, F&& fn) {
    const auto* b = reinterpret_cast<const Tri4iBlock*>(p);
    alignas(16) float vv[3][3][4];
    gather(ctx, b, vv);
    int n = detail::distinct_lanes(b->prim);
    for (int i = 0; i < n; ++i) {
      const Vec3f& a = ctx.vertices[b->v[0][i]];
      const Vec3f& c1 = ctx.vertices[b->v[1][i]];
      const Vec3f& c2 = ctx.vertices[b->v[2][i]];
      Box3f box;
      box.extend(a);
      box.extend(c1);
      box.extend(c2);
      fn(box, triangle_key(a, c1, c2, b->geom[i], b->prim[i]));
    }
  }
};

struct Tri4iCompactBlock {
  uint8_t v[3][4];   // 12 B: [corner][lane] indices into the multi-leaf's vertex dictionary
  uint32_t geom[4];  // 16 B
  uint32_t prim[4];  // 16 B
};
static_assert(sizeof(Tri4iCompactBlock) == 44, "compact Triangle4i block is 44 bytes");

// clbvh-compact (C. Benthin, I. Wald, S. Woop, A. T. Afra, "Compressed-Leaf Bounding Volume
// Hierarchies", HPG 2018, section 4.5 "Compressing Leaf Data"): inside a multi-leaf, every distinct
// 32-bit vertex index is stored once in a dictionary behind the children's blocks, and the blocks
// hold 8-bit indices into it. Multi-leaf data: k x Tri4iCompactBlock, then the dictionary (uint32
// each). Isolated leaves keep plain Tri4i blocks.
struct Tri4iCompact : Tri4i {
  static constexpr bool kMultiLeafLayout = true;

  // Scene files' structure check of a multi-leaf's data (k blocks, then the dictionary), `avail`
  // bytes from `data` to the end of the leaf arena.
  static const char* check_multileaf(const Context& ctx, const uint8_t* data, uint32_t k,
                                     uint64_t avail) {
    const uint64_t dict = uint64_t(k) * sizeof(Tri4iCompactBlock);
    if (dict > avail) return "multi-leaf blocks beyond the leaf arena";
    for (uint32_t c = 0; c < k; ++c) {
      Tri4iCompactBlock b;
      std::memcpy(&b, data + c * sizeof(Tri4iCompactBlock), sizeof b);
      for (int j = 0; j < 3; ++j)
        for (int l = 0; l < 4; ++l) {
          if (dict + 4 * uint64_t(b.v[j][l]) + 4 > avail)
            return "vertex dictionary entry beyond the leaf arena";
          uint32_t vi;
          std::memcpy(&vi, data + dict + 4 * b.v[j][l], 4);
          if (vi >= ctx.vertex_count) return "vertex index beyond the vertex array";
        }
    }
    return nullptr;
  }

  static std::vector<uint8_t> encode_multileaf(const TriangleSource& src,
                                               const uint32_t* const* prims, const uint32_t* counts,
                                               int k) {
    std::vector<uint32_t> dict;
    std::vector<uint8_t> out(size_t(k) * sizeof(Tri4iCompactBlock));
    auto index_of = [&](uint32_t v) {
      for (size_t i = 0; i < dict.size(); ++i)
        if (dict[i] == v) return uint8_t(i);
      dict.push_back(v);
      return uint8_t(dict.size() - 1);
    };
    for (int c = 0; c < k; ++c) {
      auto* b = reinterpret_cast<Tri4iCompactBlock*>(out.data() + c * sizeof(Tri4iCompactBlock));
      uint32_t n = counts[c];  // <= 4: the collapse makes multi-leaves of one-block leaves only
      for (uint32_t l = 0; l < 4; ++l) {
        uint32_t t = prims[c][l < n ? l : n - 1];
        for (int j = 0; j < 3; ++j) b->v[j][l] = index_of(src.tris[3 * t + j]);
        b->geom[l] = src.geom_ids[t];
        b->prim[l] = l < n ? src.prim_ids[t] : kInvalidID;
      }
    }
    size_t base = out.size();
    out.resize(base + dict.size() * sizeof(uint32_t));
    std::memcpy(out.data() + base, dict.data(), dict.size() * sizeof(uint32_t));
    return out;
  }

  static SLIM_INLINE void gather_compact(const Context& ctx, const Tri4iCompactBlock* b,
                                         const uint8_t* dict, float (*out)[3][4]) {
    for (int k = 0; k < 3; ++k)
      for (int l = 0; l < 4; ++l) {
        uint32_t vi;
        std::memcpy(&vi, dict + 4 * b->v[k][l], 4);
        const Vec3f& p = ctx.vertices[vi];
        out[k][0][l] = p.x;
        out[k][1][l] = p.y;
        out[k][2][l] = p.z;
      }
  }

  template <bool kAny, class Stats>
  static SLIM_INLINE bool intersect_in_multileaf(const Context& ctx, const uint8_t* data,
                                                 uint32_t children, int i, TravRay& ray,
                                                 HitRecord& hit, Stats& st) {
    using namespace simd;
    const auto* b = reinterpret_cast<const Tri4iCompactBlock*>(data) + i;
    const uint8_t* dict = data + children * sizeof(Tri4iCompactBlock);
    alignas(16) float vv[3][3][4];
    gather_compact(ctx, b, dict, vv);
    if constexpr (!std::is_same_v<Stats, NoStats>) st.prims(detail::distinct_lanes(b->prim));
    RayVertex<vfloat4> A = detail::to_ray_space4(ray.wt, vv[0]);
    RayVertex<vfloat4> B = detail::to_ray_space4(ray.wt, vv[1]);
    RayVertex<vfloat4> C = detail::to_ray_space4(ray.wt, vv[2]);
    vfloat4 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, 0xF, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    int l = detail::closest_lane(m, t);
    auto vert = [&](int k) { return Vec3f(vv[k][0][l], vv[k][1][l], vv[k][2][l]); };
    detail::record_hit(t[l], u[l], v[l], vert(0), vert(1), vert(2), b->geom[l], b->prim[l], ray,
                       hit);
    return true;
  }

  template <class F>
  static void visit_in_multileaf(const Context& ctx, const uint8_t* data, uint32_t children, int i,
                                 F&& fn) {
    const auto* b = reinterpret_cast<const Tri4iCompactBlock*>(data) + i;
    const uint8_t* dict = data + children * sizeof(Tri4iCompactBlock);
    alignas(16) float vv[3][3][4];
    gather_compact(ctx, b, dict, vv);
    int n = detail::distinct_lanes(b->prim);
    for (int l = 0; l < n; ++l) {
      Vec3f c[3];
      Box3f box;
      for (int k = 0; k < 3; ++k) {
        c[k] = Vec3f(vv[k][0][l], vv[k][1][l], vv[k][2][l]);
        box.extend(c[k]);
      }
      fn(box, triangle_key(c[0], c[1], c[2], b->geom[l], b->prim[l]));
    }
  }
};

}  // namespace slim
