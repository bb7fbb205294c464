// The benchmark camera (BENCHMARK.md, "Rays"): a pinhole looking at the scene box from one fixed
// direction and framing it whole, so every configuration of a scene traces the same rays.
//
// View: from the (+x, -y, +z) side, 35 degrees above the horizon, azimuth 30 degrees from the -y
// axis towards +x, z up; vertical field of view 40 degrees. The eye is far enough back that the
// bounding sphere of the box fits inside the narrower of the two fields of view (plus 5%).
// Constants are literals rather than libm calls so that the rays are bit-identical everywhere.
#include <cmath>

#include "slimrt/render.h"

namespace slim {

namespace {
// cos/sin of the elevation (35 deg) and azimuth (30 deg), tan of half the vertical fov (20 deg).
constexpr float kCosEl = 0.819152044f, kSinEl = 0.573576436f;
constexpr float kCosAz = 0.866025404f, kSinAz = 0.5f;
constexpr float kTanHalfFov = 0.363970234f;
constexpr float kMargin = 1.05f;
}  // namespace

Camera frame_box(const Box3f& box, int width, int height) {
  Camera cam;
  cam.width = std::max(width, 1);
  cam.height = std::max(height, 1);

  // Bounding sphere; an empty or non-finite box frames the unit sphere at the origin, a zero-size
  // box a tiny sphere around its point (never a zero radius, which would put the eye on it).
  Vec3f center(0.0f);
  float radius = 1.0f;
  if (!box.empty() && is_finite(box.lo) && is_finite(box.hi)) {
    center = box.center();
    radius = 0.5f * length(box.size());
    float floor_radius = std::max(1e-6f, 1e-5f * reduce_max(abs(center)));
    if (!(radius >= floor_radius)) radius = floor_radius;
    if (!std::isfinite(radius) || !is_finite(center)) center = Vec3f(0.0f), radius = 1.0f;
  }

  Vec3f to_eye(kCosEl * kSinAz, -kCosEl * kCosAz, kSinEl);  // unit length
  Vec3f forward = -to_eye;
  Vec3f right = normalize(cross(forward, Vec3f(0.0f, 0.0f, 1.0f)));
  Vec3f up = cross(right, forward);

  float aspect = float(cam.width) / float(cam.height);
  float tan_v = kTanHalfFov, tan_h = kTanHalfFov * aspect;
  // A sphere of radius r at distance D fills half-angle asin(r / D): D = r / sin(half-angle).
  float tan_min = std::min(tan_v, tan_h);
  float sin_min = tan_min / std::sqrt(1.0f + tan_min * tan_min);
  float dist = kMargin * radius / sin_min;

  cam.eye = center + to_eye * dist;
  cam.du = right * (2.0f * tan_h / float(cam.width));
  cam.dv = up * (-2.0f * tan_v / float(cam.height));  // top row first
  cam.dir00 = forward - right * tan_h + up * tan_v;
  return cam;
}

}  // namespace slim
