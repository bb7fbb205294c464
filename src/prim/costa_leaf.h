// Leaf format of the Costa quantized n-gon mesh (V. Costa, J. M. Pereira, J. A. Jorge, "Fast
// Compression of Meshes for GPU Ray-Tracing", WSCG 2013, section 3.3 "Intersection Testing"):
// a leaf block is a RANGE of primitives of the store (prim/quantized_mesh.h). The store's
// primitives are reordered in BVH leaf order at build, so the leaves need no index array.
//
//   CostaBlock  8 B  first primitive (4 B) + primitive count (4 B)
//
// Intersection (Listing 5, TESTPRIMITIVE): every primitive is decoded from the store in O(1)
// (two offsets, then its face entries, then its vertices) and tested as triangles with the
// watertight test (core/watertight.h; the paper uses Moller-Trumbore):
//   3 vertices   triangle (v0, v1, v2)
//   4 vertices   quad = 4-vertex fan: (v0, v1, v2), (v0, v2, v3) -- the diagonal v0-v2 of slimrt's
//                fan triangulation, so hits agree bit for bit with the triangle formats
//   5+, flag 0   fan (v0, v_j, v_j+1); each vertex is decoded once for all its triangles
//   5+, flag 1   strip: triangle t is (v_t, v_t+1, v_t+2), odd t flipped to (v_t+1, v_t, v_t+2)
// The triangles of a block are gathered 8 at a time and tested with 8-wide SIMD. A hit reports
// the INPUT face (through the primitive -> face map) and the u, v of the triangle hit.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "core/ray.h"
#include "core/simd.h"
#include "core/watertight.h"
#include "prim/quantized_mesh.h"
#include "slimrt/ray.h"

namespace slim {

struct CostaBlock {
  uint32_t first;  // first primitive of the range (an index into the store)
  uint32_t count;  // primitives in the range, 1 .. kBlockPrims
};
static_assert(sizeof(CostaBlock) == 8, "Costa leaf block is 8 bytes");

// Order-independent validation key of one primitive: its decoded vertices in face-array order,
// its size, fan/strip flag, mesh and input face. Never 0.
struct CostaKey {
  uint64_t h = 0x2545F4914F6CDD1DULL;
  static uint64_t mix(uint64_t h, uint64_t x) {
    h ^= x + 0x9E3779B97F4A7C15ULL + (h << 6) + (h >> 2);
    return h * 0xFF51AFD7ED558CCDULL;
  }
  void add(const Vec3f& p) {
    uint32_t w[3];
    std::memcpy(w, &p, 12);
    for (uint32_t x : w) h = mix(h, x);
  }
  uint64_t finish(uint32_t n, uint32_t flag, uint32_t geom, uint32_t face) const {
    uint64_t k = mix(mix(mix(mix(h, n), flag), geom), face);
    return k | 1;
  }
};

// Input face of a primitive: a global face id from the bit-packed map, split into (mesh, face)
// by the per-mesh first face ids.
struct CostaFaceMap {
  const uint8_t* bits = nullptr;
  uint32_t width = 0;
  const uint32_t* face_base = nullptr;  // mesh_count + 1 entries
  uint32_t mesh_count = 0;

  SLIM_INLINE void lookup(uint32_t prim, uint32_t& geom, uint32_t& face) const {
    const uint32_t g = bit_read(bits, width, prim);
    uint32_t m = 0;
    if (mesh_count > 1)
      m = uint32_t(std::upper_bound(face_base, face_base + mesh_count + 1, g) - face_base) - 1;
    geom = m;
    face = g - face_base[m];
  }
};

// A Costa scene file's section costa.params (api/scene_costa.cpp): the store's scalars.
struct CostaParams {
  double avg;
  int64_t residual_min;
  VertexQuantizer quant;
  uint32_t residual_bits, face_bits, face_width, mesh_count, prim_count, reserved;
};
static_assert(sizeof(CostaParams) == 64, "costa.params is 64 bytes");

template <bool P, bool F, bool V>
struct CostaLeaf {
  struct Context {
    CostaView<P, F, V> view;
    CostaFaceMap faces;
    uint32_t prim_count = 0;
    // Scene files' structure check: the element counts of the store's arrays and of the face map
    // (bytes) and face_base (entries), from the section sizes (api/scene_costa.cpp).
    QuantizedMesh::Counts counts{};
    uint64_t face_map_bytes = 0, face_base_count = 0;
  };
  static constexpr uint32_t kBlockPrims = 4;
  static constexpr uint32_t kBlockBytes = sizeof(CostaBlock);
  // Blocks are read with memcpy, multi-leaf boxes (MultiLeaf8: floats) at 4-byte multiples: the
  // collapse packs leaves and multi-leaves at 8-byte multiples (traverse.h leaf_align), which
  // their sizes are.
  static constexpr uint32_t kLeafAlign = 8;

  // What check_store found wrong: the section and byte offset of the field, and what.
  struct StoreFault {
    const char* section = nullptr;
    uint64_t offset = 0;
    const char* what = nullptr;
  };
  // Scene files' structure check (OpenOptions::check_structure) of the store's parameters: bit
  // widths the readers take, a linear predictor whose sums fit int64 (predict_offset), a face
  // map whose mesh search stays inside face_base. The fields' offsets are CostaParams'.
  static StoreFault check_params(const Context& ctx) {
    auto param = [](uint64_t offset, const char* what) {
      return StoreFault{"costa.params", offset, what};
    };
    const auto& r = ctx.view.r;
    if constexpr (P) {
      if (r.residual_bits > 32)
        return param(offsetof(CostaParams, residual_bits), "offset residual width beyond 32 bits");
      const double avg = r.avg;
      const int64_t min = r.residual_min, lim = int64_t(1) << 60;
      if (!(avg >= 0.0 && avg * (double(ctx.prim_count) + 1.0) < 0x1p62))
        return param(offsetof(CostaParams, avg), "offset predictor out of range (its slope)");
      if (min < -lim || min > lim)
        return param(offsetof(CostaParams, residual_min),
                     "offset predictor out of range (its smallest residual)");
    }
    if constexpr (F)  // 0 bits only in an empty store (entries of 0 bits would cost no bytes)
      if (r.face_bits > 32 || (r.face_bits == 0 && ctx.prim_count > 0))
        return param(offsetof(CostaParams, face_bits), "face entry width outside 1..32 bits");
    const CostaFaceMap& m = ctx.faces;
    if (m.width > 32)
      return param(offsetof(CostaParams, face_width), "face map width beyond 32 bits");
    if (uint64_t(m.mesh_count) + 1 > ctx.face_base_count)
      return param(offsetof(CostaParams, mesh_count),
                   "mesh count beyond the face bases (costa.face_base)");
    if (m.mesh_count > 1 && m.face_base[0] != 0)
      return {"costa.face_base", 0, "first face base not 0"};
    return {};
  }
  // Whether bit_read(data, width, i) stays inside `bytes` (it loads 8 bytes).
  static bool bits_readable(uint64_t bytes, uint32_t width, uint64_t i) {
    return ((i * width) >> 3) + 8 <= bytes;
  }
  // The store's primitives, once per opened scene before the leaf walk (the scene's
  // check_opened): each primitive's two offsets readable, 3+ face entries inside the face array,
  // each naming a vertex inside the vertex array, its face map entry readable. Offsets rise by 3+
  // from one primitive to the next, so the loop reads every face entry once: the work is bounded
  // by the face array, whatever the blocks name (check_block then bounds only a block's range;
  // a per-block scan of the entries would read a damaged file's huge primitive once per block
  // naming it). prim_count itself is bounded by the leaf arena (kBlockPrims per block), the face
  // entries by the face array's bytes (packed entries take 1+ bits: check_params).
  static StoreFault check_store(const Context& ctx, uint64_t leaf_bytes) {
    if (const StoreFault f = check_params(ctx); f.what) return f;
    if (uint64_t(ctx.prim_count) > leaf_bytes / kBlockBytes * kBlockPrims)
      return {"costa.params", offsetof(CostaParams, prim_count),
              "primitive count beyond what the leaf blocks can hold"};
    const CostaView<P, F, V>& s = ctx.view;
    const QuantizedMesh::Counts& n = ctx.counts;
    const char* offsets = P ? "costa.residuals" : "costa.offsets";
    const char* faces = F ? "costa.packed_faces" : "costa.faces";
    auto offset_byte = [&](uint64_t prim) { return P ? prim * s.r.residual_bits / 8 : prim * 4; };
    auto face_byte = [&](uint64_t j) { return F ? j * s.r.face_bits / 8 : j * 4; };
    // The first offset is 0 (as the builder writes it; decoded_triangles starts there, also in a
    // store without primitives).
    if (P ? !bits_readable(n.residual_bytes, s.r.residual_bits, 0) : n.offsets == 0)
      return {offsets, 0, "first primitive offset beyond the array"};
    if (s.offset(0) != 0) return {offsets, 0, "first primitive offset not 0"};
    for (uint64_t prim = 0; prim < ctx.prim_count; ++prim) {
      if (P ? !bits_readable(n.residual_bytes, s.r.residual_bits, prim + 1) : prim + 1 >= n.offsets)
        return {offsets, offset_byte(prim + 1), "primitive offset beyond the array"};
      const uint32_t o0 = s.offset(uint32_t(prim)), o1 = s.offset(uint32_t(prim + 1));
      if (uint64_t(o0) + 3 > o1)
        return {offsets, offset_byte(prim), "primitive of fewer than 3 face entries"};
      if (F ? !bits_readable(n.packed_face_bytes, s.r.face_bits, uint64_t(o1) - 1) : o1 > n.faces)
        return {faces, face_byte(o1 - 1), "face entry beyond the face array"};
      for (uint32_t j = o0; j < o1; ++j) {
        uint32_t f = s.face(j);
        if (j == o0 && o1 - o0 >= kFanStripFlagMin) f >>= 1;
        if (V ? 3 * uint64_t(f) + 3 > n.qvertices : f >= n.vertices)
          return {faces, face_byte(j), "face entry names a vertex beyond the vertex array"};
      }
      if (!bits_readable(ctx.face_map_bytes, ctx.faces.width, prim))
        return {"costa.face_map", prim * ctx.faces.width / 8, "primitive beyond the face map"};
    }
    return {};
  }
  // A block: its primitive range inside the store (whose primitives check_store checked).
  static const char* check_block(const Context& ctx, const uint8_t* p) {
    CostaBlock blk;
    std::memcpy(&blk, p, sizeof(blk));
    if (blk.count == 0 || blk.count > kBlockPrims) return "primitive count outside 1..4";
    if (uint64_t(blk.first) + blk.count > ctx.prim_count)
      return "primitive range beyond the store (costa.params prim_count)";
    return nullptr;
  }

  // Up to 8 triangles gathered for one SIMD test.
  struct Batch {
    alignas(32) float v[3][3][8];  // [corner][axis][lane], world space (decoded)
    uint32_t prim[8];
    PrimKind kind[8];
    uint32_t n;
  };

  // Tests the gathered triangles; kept out of line so that the decoder stays small.
  template <bool kAny, class Stats>
  static __attribute__((noinline)) bool flush(const Context& ctx, Batch& b, TravRay& ray,
                                              HitRecord& hit, Stats& st) {
    using namespace simd;
    const uint32_t n = b.n;
    b.n = 0;
    st.prims(int(n));
    RayVertex<vfloat8> A = to_ray_space(ray.wt, vfloat8::load(b.v[0][0]), vfloat8::load(b.v[0][1]),
                                        vfloat8::load(b.v[0][2]));
    RayVertex<vfloat8> B = to_ray_space(ray.wt, vfloat8::load(b.v[1][0]), vfloat8::load(b.v[1][1]),
                                        vfloat8::load(b.v[1][2]));
    RayVertex<vfloat8> C = to_ray_space(ray.wt, vfloat8::load(b.v[2][0]), vfloat8::load(b.v[2][1]),
                                        vfloat8::load(b.v[2][2]));
    vfloat8 t(0.0f), u(0.0f), v(0.0f);
    uint32_t m = intersect_triangles(A, B, C, (1u << n) - 1, ray.tnear, ray.tfar, t, u, v);
    if (!m) return false;
    if constexpr (kAny) return true;
    alignas(32) float tt[8];
    t.store(tt);
    int i = pop_lowest(m);
    while (m) {
      int j = pop_lowest(m);
      if (tt[j] < tt[i]) i = j;
    }
    auto vert = [&](int k) { return Vec3f(b.v[k][0][i], b.v[k][1][i], b.v[k][2][i]); };
    const Vec3f p0 = vert(0), p1 = vert(1), p2 = vert(2);
    hit.t = tt[i];
    hit.u = u[i];
    hit.v = v[i];
    hit.Ng = cross(p1 - p0, p2 - p0);
    ctx.faces.lookup(b.prim[i], hit.geomID, hit.primID);
    hit.kind = b.kind[i];
    ray.tfar = tt[i];
    return true;
  }

  // Not inlined into the traversal loop on purpose: the decoder is large, and inlined it costs
  // the node loop its registers (measured: ~25% slower traversal).
  template <bool kAny, class Stats>
  static __attribute__((noinline)) bool intersect(const Context& ctx, const uint8_t* p,
                                                  TravRay& ray, HitRecord& hit, Stats& st) {
    CostaBlock blk;
    std::memcpy(&blk, p, sizeof(blk));
    const CostaView<P, F, V>& s = ctx.view;
    Batch b;
    for (auto& corner : b.v)  // unused lanes hold finite values (no NaN/denormal work)
      for (float* axis : corner) simd::vfloat8(0.0f).store(axis);
    b.n = 0;
    bool found = false;
    // Adds one triangle and tests the batch when it is full. Returns true for an any-hit exit.
    auto emit = [&](const Vec3f& a, const Vec3f& c1, const Vec3f& c2, uint32_t prim, PrimKind kind)
        __attribute__((always_inline)) {
      const uint32_t l = b.n++;
      b.v[0][0][l] = a.x, b.v[0][1][l] = a.y, b.v[0][2][l] = a.z;
      b.v[1][0][l] = c1.x, b.v[1][1][l] = c1.y, b.v[1][2][l] = c1.z;
      b.v[2][0][l] = c2.x, b.v[2][1][l] = c2.y, b.v[2][2][l] = c2.z;
      b.prim[l] = prim;
      b.kind[l] = kind;
      if (b.n == 8 && flush<kAny>(ctx, b, ray, hit, st)) {
        found = true;
        if constexpr (kAny) return true;
      }
      return false;
    };
    // TESTPRIMITIVE (Listing 5) for each primitive of the range.
    uint32_t o0 = s.offset(blk.first);
    for (uint32_t k = 0; k < blk.count; ++k) {
      const uint32_t prim = blk.first + k;
      const uint32_t o1 = s.offset(prim + 1);
      const uint32_t n = o1 - o0;
      if (n == 3) {
        if (emit(s.vertex(s.face(o0)), s.vertex(s.face(o0 + 1)), s.vertex(s.face(o0 + 2)), prim,
                 PrimKind::Triangle))
          return true;
      } else if (n == 4) {
        const Vec3f a = s.vertex(s.face(o0)), c1 = s.vertex(s.face(o0 + 1));
        const Vec3f c2 = s.vertex(s.face(o0 + 2)), c3 = s.vertex(s.face(o0 + 3));
        if (emit(a, c1, c2, prim, PrimKind::Quad)) return true;
        if (emit(a, c2, c3, prim, PrimKind::Quad)) return true;
      } else {
        const uint32_t f0 = s.face(o0);
        Vec3f a = s.vertex(f0 >> 1), c1 = s.vertex(s.face(o0 + 1));
        if ((f0 & 1) == 0) {  // fan: a is the centre, c1 the previous rim vertex
          for (uint32_t j = o0 + 2; j < o1; ++j) {
            const Vec3f c2 = s.vertex(s.face(j));
            if (emit(a, c1, c2, prim, PrimKind::Fan)) return true;
            c1 = c2;
          }
        } else {  // strip: (a, c1) are the last two vertices
          for (uint32_t j = o0 + 2, t = 0; j < o1; ++j, ++t) {
            const Vec3f c2 = s.vertex(s.face(j));
            if (t & 1) {
              if (emit(c1, a, c2, prim, PrimKind::Strip)) return true;
            } else {
              if (emit(a, c1, c2, prim, PrimKind::Strip)) return true;
            }
            a = c1;
            c1 = c2;
          }
        }
      }
      o0 = o1;
    }
    if (b.n && flush<kAny>(ctx, b, ray, hit, st)) found = true;
    return found;
  }

  // Bounds and key of each primitive of a block (validation). Ranges beyond the store are
  // clipped (validate() then reports the missing primitives).
  template <class Fn>
  static void visit(const Context& ctx, const uint8_t* p, Fn&& fn) {
    CostaBlock blk;
    std::memcpy(&blk, p, sizeof(blk));
    const CostaView<P, F, V>& s = ctx.view;
    if (blk.first >= ctx.prim_count) return;
    const uint32_t end = blk.first + std::min(blk.count, ctx.prim_count - blk.first);
    for (uint32_t prim = blk.first; prim < end; ++prim) {
      const uint32_t o0 = s.offset(prim), o1 = s.offset(prim + 1);
      const uint32_t n = o1 - o0;
      Box3f box;
      CostaKey key;
      uint32_t flag = 0;
      for (uint32_t j = o0; j < o1; ++j) {
        uint32_t f = s.face(j);
        if (j == o0 && n >= kFanStripFlagMin) flag = f & 1, f >>= 1;
        const Vec3f q = s.vertex(f);
        box.extend(q);
        key.add(q);
      }
      uint32_t geom, face;
      ctx.faces.lookup(prim, geom, face);
      fn(box, key.finish(n, flag, geom, face));
    }
  }
};

}  // namespace slim
