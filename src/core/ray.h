// The ray as traversal and leaf tests see it (precomputed once per query), the internal hit record
// and the statistics policies of the traversal template.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/watertight.h"
#include "slimrt/math.h"
#include "slimrt/scene.h"

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
  float c_near[3], c_far[3];
  uint32_t near_plane[3];  // plane array index (2*a or 2*a+1) of the near plane of axis a
  WatertightRay wt;
};

// Per-scene constants of the ray setup: the largest |coordinate| of the scene box per axis.
struct RaySetupBounds {
  float absmax[3] = {0, 0, 0};
  RaySetupBounds() = default;
  explicit RaySetupBounds(const Box3f& b) {
    for (int a = 0; a < 3; ++a) {
      absmax[a] = std::max(std::fabs(b.lo[a]), std::fabs(b.hi[a]));
      if (!std::isfinite(absmax[a])) absmax[a] = 0.0f;
    }
  }
};

// Prepares a ray. Returns false for rays that cannot hit anything: NaN/Inf origin, NaN or zero
// direction, NaN bounds or tnear > tfar (documented behaviour: a miss).
SLIM_INLINE bool make_trav_ray(const Ray& r, const RaySetupBounds& sb, TravRay& tr) {
  if (!is_finite(r.org) || !is_finite(r.dir)) return false;
  if (std::fabs(r.org.x) > kMaxCoordinate || std::fabs(r.org.y) > kMaxCoordinate ||
      std::fabs(r.org.z) > kMaxCoordinate)
    return false;  // documented (slimrt/scene.h): the watertight test would overflow
  if (!(r.tnear <= r.tfar)) return false;  // also false for NaN bounds
  if (r.dir.x == 0.0f && r.dir.y == 0.0f && r.dir.z == 0.0f) return false;
  tr.org = r.org;
  tr.dir = r.dir;
  tr.tnear = r.tnear > 0.0f ? r.tnear : 0.0f;
  tr.tfar = r.tfar;
  if (!(tr.tnear <= tr.tfar)) return false;
  for (int a = 0; a < 3; ++a) {
    float d = r.dir[a];
    // Zero components become tiny ones so that 1/d stays finite (the planes parallel to the ray
    // then give huge |t|, the right answer); the error bound below covers the change.
    if (std::fabs(d) < 1e-18f) d = std::signbit(d) ? -1e-18f : 1e-18f;
    float rd = 1.0f / d;
    tr.rdir[a] = rd;
    float c = tr.org[a] * rd;
    // |error of fmsub(bound, rd, c)| <= 2^-23 * |rd| * (|bound| + |org|) for bounds in the scene
    // box: rounding of rd, of c and of the result. Use 2^-20 for margin.
    float err = std::fabs(rd) * (sb.absmax[a] + std::fabs(tr.org[a])) * (1.0f / 1048576.0f);
    tr.c_near[a] = c + err;
    tr.c_far[a] = c - err;
    tr.near_plane[a] = 2 * a + (rd < 0.0f ? 1 : 0);
  }
  tr.wt = WatertightRay(r.org, r.dir, tr.rdir);
  return true;
}

// Statistics policies.
struct NoStats {
  SLIM_INLINE void node(int /*boxes*/) {}
  SLIM_INLINE void prims(int) {}
};
struct CountStats {
  TraversalCounters* c;
  SLIM_INLINE void node(int boxes) {
    c->node_visits++;
    c->box_tests += boxes;
  }
  SLIM_INLINE void prims(int n) { c->prim_tests += n; }
};

}  // namespace slim
