// Watertight ray/triangle intersection: S. Woop, C. Benthin, I. Wald, "Watertight Ray/Triangle
// Intersection", JCGT 2(1), 2013. Every slimrt format uses it.
//
// The ray is turned into a space where it starts at the origin and points along +z (section 3:
// permute the axes so that kz is the largest direction component, then shear x and y by Sx, Sy).
// Each vertex is transformed by the same deterministic arithmetic, so two triangles that share an
// edge compute bit-identical transformed vertices, and the 2D edge functions U, V, W of the shared
// edge are exact negatives of each other (the products are not fused on purpose). A ray through the
// edge therefore hits at least one of the two triangles; edge functions that are exactly zero are
// recomputed in double precision (section 3.3), so the decision is always consistent.
//
// Conventions: a hit needs tnear < t <= tfar (as in Embree); both faces are hit (no culling);
// u, v are the weights of the 2nd and 3rd vertex.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "core/simd.h"
#include "slimrt/math.h"

namespace slim {

SLIM_INLINE float fnmadd(float a, float b, float c) { return std::fma(-a, b, c); }
SLIM_INLINE float fmadd(float a, float b, float c) { return std::fma(a, b, c); }

// Per-ray constants of the watertight test (paper, section 3.1 / Listing 1).
// The default constructor leaves them unset (TravRay::wt is set only when the ray reaches a leaf:
// no stores for the rays that never do).
struct WatertightRay {
  Vec3f org;
  int kx, ky, kz;
  float Sx, Sy, Sz;
  float ox, oy, oz;  // org[kx], org[ky], org[kz]

  WatertightRay() = default;
  WatertightRay(const Vec3f& o, const Vec3f& d) : org(o) {
    Vec3f ad = abs(d);
    kz = max_dim(ad);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0.0f) {  // keep the winding of the triangle (paper, section 3.1)
      int t = kx;
      kx = ky;
      ky = t;
    }
    Sx = d[kx] / d[kz];
    Sy = d[ky] / d[kz];
    Sz = 1.0f / d[kz];
    ox = o[kx];
    oy = o[ky];
    oz = o[kz];
  }
  // The same with the reciprocal direction already at hand: one division fewer per axis. Any
  // per-ray constants work as long as every triangle of the ray uses the same ones.
  WatertightRay(const Vec3f& o, const Vec3f& d, const Vec3f& rd) : org(o) {
    kz = max_dim(abs(d));
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0.0f) {
      int t = kx;
      kx = ky;
      ky = t;
    }
    Sz = rd[kz];
    Sx = d[kx] * Sz;
    Sy = d[ky] * Sz;
    ox = o[kx];
    oy = o[ky];
    oz = o[kz];
  }
};

// A vertex in ray space (before the z scaling, which is applied only where needed).
template <class VF>
struct RayVertex {
  VF x, y, z;
};

// Transforms a vertex given as its components along the ray's axes kx, ky, kz (for a leaf that
// loads them from memory by those indices directly).
template <class VF>
SLIM_INLINE RayVertex<VF> to_ray_space_permuted(const WatertightRay& r, const VF& pkx,
                                                const VF& pky, const VF& pkz) {
  VF ax = pkx - VF(r.ox);
  VF ay = pky - VF(r.oy);
  VF az = pkz - VF(r.oz);
  using simd::fnmadd;
  using slim::fnmadd;
  return {fnmadd(VF(r.Sx), az, ax), fnmadd(VF(r.Sy), az, ay), VF(r.Sz) * az};
}

// Transforms a vertex (given as its 3 components; for SIMD types, lanes are different vertices).
template <class VF>
SLIM_INLINE RayVertex<VF> to_ray_space(const WatertightRay& r, const VF& px, const VF& py,
                                       const VF& pz) {
  const VF* p[3] = {&px, &py, &pz};
  return to_ray_space_permuted(r, *p[r.kx], *p[r.ky], *p[r.kz]);
}

namespace detail {

// Double-precision re-evaluation of one triangle when an edge function is exactly zero
// (paper, section 3.3). Returns true on a hit and sets t, u, v.
inline bool watertight_fallback(float ax, float ay, float az, float bx, float by, float bz,
                                float cx, float cy, float cz, float tnear, float tfar, float& t,
                                float& u, float& v) {
  double U = double(cx) * double(by) - double(cy) * double(bx);
  double V = double(ax) * double(cy) - double(ay) * double(cx);
  double W = double(bx) * double(ay) - double(by) * double(ax);
  if ((U < 0 || V < 0 || W < 0) && (U > 0 || V > 0 || W > 0)) return false;
  double det = U + V + W;
  if (det == 0.0) return false;
  double T = U * az + V * bz + W * cz;
  double td = T / det;
  if (!(td > double(tnear) && td <= double(tfar))) return false;
  // A hit beyond the float range (a tiny direction: t ~ distance / |dir|) is not reported.
  if (!(td <= double(std::numeric_limits<float>::max()))) return false;
  t = float(td);
  u = float(V / det);
  v = float(W / det);
  return true;
}

}  // namespace detail

// One triangle, scalar. a, b, c are the ray-space vertices of its 3 corners.
SLIM_INLINE bool intersect_triangle(const RayVertex<float>& a, const RayVertex<float>& b,
                                    const RayVertex<float>& c, float tnear, float tfar, float& t,
                                    float& u, float& v) {
  // 2D edge functions (paper, section 3.2); products deliberately not fused.
  float U = c.x * b.y - c.y * b.x;
  float V = a.x * c.y - a.y * c.x;
  float W = b.x * a.y - b.y * a.x;
  if (U == 0.0f || V == 0.0f || W == 0.0f)
    return detail::watertight_fallback(a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z, tnear, tfar, t,
                                       u, v);
  if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
  float det = U + V + W;
  if (det == 0.0f) return false;
  float T = U * a.z + V * b.z + W * c.z;
  float sgn = std::signbit(det) ? -1.0f : 1.0f;
  float Tp = T * sgn, adet = det * sgn;
  if (!(Tp > tnear * adet && Tp <= tfar * adet)) return false;
  float rcp = 1.0f / det;
  t = T * rcp;
  u = V * rcp;
  v = W * rcp;
  if (t == kInf)  // T overflowed (see intersect_triangles): exact in double, or no hit
    return detail::watertight_fallback(a.x, a.y, a.z, b.x, b.y, b.z, c.x, c.y, c.z, tnear, tfar, t,
                                       u, v);
  return t > tnear && t <= tfar;
}

// N triangles at once (VF = simd::vfloat4 or vfloat8). Returns the mask of lanes that hit with
// tnear < t <= tfar and sets t, u, v in those lanes. `valid` masks lanes that hold triangles.
template <class VF>
SLIM_INLINE uint32_t intersect_triangles(const RayVertex<VF>& a, const RayVertex<VF>& b,
                                         const RayVertex<VF>& c, uint32_t valid, float tnear,
                                         float tfar, VF& t, VF& u, VF& v) {
  using namespace simd;
  const VF zero(0.0f);
  VF U = c.x * b.y - c.y * b.x;
  VF V = a.x * c.y - a.y * c.x;
  VF W = b.x * a.y - b.y * a.x;
  uint32_t zeros = ((U == zero) | (V == zero) | (W == zero)).mask() & valid;  // and overflows
  uint32_t neg = ((U < zero) | (V < zero) | (W < zero)).mask();
  uint32_t pos = ((U > zero) | (V > zero) | (W > zero)).mask();
  uint32_t m = valid & ~zeros & ~(neg & pos);
  if (m) {
    VF det = U + V + W;
    VF T = U * a.z + V * b.z + W * c.z;
    VF sgn = signmsk(det);
    VF Tp = T ^ sgn, adet = abs(det);
    m &= ((det != zero) & (Tp > VF(tnear) * adet) & (Tp <= VF(tfar) * adet)).mask();
    if (m) {
      VF rcp = rcp_exact(det);
      t = T * rcp;
      u = V * rcp;
      v = W * rcp;
      m &= ((t > VF(tnear)) & (t <= VF(tfar))).mask();
      // T = U az + V bz + W cz overflows to +inf when the ray-space depths az = (pz - oz) / dz
      // are huge: a far triangle and a tiny direction (t ~ distance / |dir| up to ~1e38, and
      // tfar = +inf lets t = inf through). Those lanes are re-evaluated in double below: the
      // right t, or no hit if t is beyond the float range.
      const uint32_t over = m & (t == VF(kInf)).mask();
      m &= ~over;
      zeros |= over;
    }
  }
  if (zeros) {  // rare: exact zeros in an edge function (or an overflowed T, above): re-evaluate
                // those lanes in double
    constexpr int N = sizeof(VF) / sizeof(float);
    alignas(32) float ax[N], ay[N], az[N], bx[N], by[N], bz[N], cx[N], cy[N], cz[N];
    alignas(32) float tt[N], uu[N], vv[N];
    a.x.storeu(ax), a.y.storeu(ay), a.z.storeu(az);
    b.x.storeu(bx), b.y.storeu(by), b.z.storeu(bz);
    c.x.storeu(cx), c.y.storeu(cy), c.z.storeu(cz);
    t.storeu(tt), u.storeu(uu), v.storeu(vv);
    for (uint32_t z = zeros; z;) {
      int i = pop_lowest(z);
      if (detail::watertight_fallback(ax[i], ay[i], az[i], bx[i], by[i], bz[i], cx[i], cy[i], cz[i],
                                      tnear, tfar, tt[i], uu[i], vv[i]))
        m |= 1u << i;
    }
    t = VF::loadu(tt), u = VF::loadu(uu), v = VF::loadu(vv);
  }
  return m;
}

}  // namespace slim
