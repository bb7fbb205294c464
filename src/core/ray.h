// The ray as traversal and leaf tests see it (precomputed once per query), the internal hit record
// and the statistics policies of the traversal template.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>

#include "core/watertight.h"
#include "slimrt/math.h"
#include "slimrt/ray.h"

namespace slim {

// Internal hit record: Hit without the public conveniences.
using HitRecord = Hit;

// The ray as the traversal needs it.
struct TravRay {
  Vec3f org, dir, rdir;
  float tnear, tfar;
  // Box test (per axis a): t = bound * rdir - c, with c = org * rdir shifted by the worst-case
  // rounding error of that expression over the scene, towards the ray for near planes (c_near)
  // and away from it for far planes (c_far): boxes are never culled by rounding (Ize, "Robust BVH
  // Ray Traversal", JCGT 2013, with the bound folded into the constants).
  float c_near[4], c_far[4];  // lane 3 unused (stored 4 at a time)
  uint32_t near_plane[3];     // plane array index (2*a or 2*a+1) of the near plane of axis a
  WatertightRay wt;  // make_trav_ray, or traverse_bvh8 at the ray's first leaf (make_box_ray)
};

// Per-scene constants of the ray setup: the largest |coordinate| of the scene box per axis.
struct RaySetupBounds {
  float absmax[4] = {0, 0, 0, 0};  // lane 3 unused (loaded 4 at a time)
  RaySetupBounds() = default;
  explicit RaySetupBounds(const Box3f& b) {
    for (int a = 0; a < 3; ++a) {
      absmax[a] = std::max(std::fabs(b.lo[a]), std::fabs(b.hi[a]));
      if (!std::isfinite(absmax[a])) absmax[a] = 0.0f;
    }
  }
};

// Prepares a ray for the box tests: every field but wt, which traverse_bvh8 sets at the first leaf
// the ray reaches (a ray that meets only boxes, as most misses, never needs it). Returns false for
// rays that cannot hit anything: NaN/Inf origin, NaN or zero direction (every component below
// kMinDirection), NaN bounds or tnear > tfar (documented behaviour: a miss).
SLIM_INLINE bool make_box_ray(const Ray& r, const RaySetupBounds& sb, TravRay& tr) {
  using namespace simd;
  static_assert(offsetof(Ray, tnear) == 12 && offsetof(Ray, dir) == 16 && offsetof(Ray, tfar) == 28,
                "Ray is (org, tnear), (dir, tfar): two 4-float loads");
  const vfloat4 o4 = vfloat4::loadu(&r.org.x);  // org, tnear
  const vfloat4 d4 = vfloat4::loadu(&r.dir.x);  // dir, tfar
  // Origin within +-kMaxCoordinate (documented in slimrt/scene.h: the watertight test would
  // overflow beyond; false for NaN/Inf too) and a finite direction: lanes 0-2.
  const uint32_t ok =
      ((abs(o4) <= vfloat4(kMaxCoordinate)) & (abs(d4) <= vfloat4(3.4028235e38f))).mask();
  if ((ok & 7) != 7) return false;
  if (!(r.tnear <= r.tfar)) return false;  // also false for NaN bounds
  // Zero (or all below kMinDirection, slimrt/scene.h): no direction.
  if (((abs(d4) < vfloat4(kMinDirection)).mask() & 7) == 7) return false;
  tr.org = r.org;
  tr.dir = r.dir;
  tr.tnear = r.tnear > 0.0f ? r.tnear : 0.0f;
  tr.tfar = r.tfar;
  if (!(tr.tnear <= tr.tfar)) return false;
  // Zero components become tiny ones so that 1/d stays finite (the planes parallel to the ray
  // then give huge |t|, the right answer); the error bound below covers the change.
  const vfloat4 tiny(kMinDirection);
  const vfloat4 d = select(abs(d4) < tiny, signmsk(d4) ^ tiny, d4);
  const vfloat4 rd = vfloat4(1.0f) / d;
  const vfloat4 c = o4 * rd;
  // |error of fmsub(bound, rd, c)| <= 2^-23 * |rd| * (|bound| + |org|) for bounds in the scene
  // box: rounding of rd, of c and of the result. Use 2^-20 for margin.
  const vfloat4 err = abs(rd) * (vfloat4::loadu(sb.absmax) + abs(o4)) * vfloat4(1.0f / 1048576.0f);
  alignas(16) float rdv[4];
  rd.storeu(rdv);
  tr.rdir = Vec3f(rdv[0], rdv[1], rdv[2]);
  (c + err).storeu(tr.c_near);
  (c - err).storeu(tr.c_far);
  const uint32_t neg = (rd < vfloat4(0.0f)).mask();
  for (uint32_t a = 0; a < 3; ++a) tr.near_plane[a] = 2 * a + ((neg >> a) & 1);
  return true;
}
// The watertight test's constants of a ray make_box_ray prepared.
SLIM_INLINE void set_watertight(TravRay& tr) { tr.wt = WatertightRay(tr.org, tr.dir, tr.rdir); }
// set_watertight unless `done` says it ran (a traversal's first leaf sets them, later leaves not).
SLIM_INLINE void set_watertight_once(TravRay& tr, bool& done) {
  if (!done) {
    set_watertight(tr);
    done = true;
  }
}
// make_box_ray and the watertight constants: a ray ready for the leaf tests as well.
SLIM_INLINE bool make_trav_ray(const Ray& r, const RaySetupBounds& sb, TravRay& tr) {
  if (!make_box_ray(r, sb, tr)) return false;
  set_watertight(tr);
  return true;
}

// Statistics policies.
struct NoStats {
  SLIM_INLINE void node(int /*boxes*/) {}
  SLIM_INLINE void prims(int) {}
  SLIM_INLINE void prims(int, int) {}
};
struct CountStats {
  TraversalCounters* c;
  SLIM_INLINE void node(int boxes) {
    c->node_visits++;
    c->box_tests += boxes;
  }
  // n triangles tested (as `records` primitive records: pairs count once; by default n).
  SLIM_INLINE void prims(int n) { prims(n, n); }
  SLIM_INLINE void prims(int n, int records) {
    c->prim_tests += n;
    c->prim_records += records;
  }
};

}  // namespace slim
