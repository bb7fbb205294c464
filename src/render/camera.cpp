// The cameras. The benchmark camera (docs/benchmark.md): a pinhole looking at the scene box
// from one fixed direction and framing it whole, so every configuration of a scene traces the
// same rays. The user's camera (view_camera, slimrt render): any up axis, eye, look-at point and
// field of view, framing the box's corners by default.
//
// View: from the (+x, -y, +z) side, 35 degrees above the horizon, azimuth 30 degrees from the -y
// axis towards +x, z up; vertical field of view 40 degrees. The eye is far enough back that the
// bounding sphere of the box fits inside the narrower of the two fields of view (plus 5%).
// Constants are literals rather than libm calls so that the rays are bit-identical everywhere.
#include <algorithm>
#include <array>
#include <cmath>
#include <string>

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

namespace {

// The benchmark camera's direction to the eye (from the front-right, above) expressed for an up
// axis: Z up looks from (+x, -y, +z) as frame_box does; Y up (glTF) from (+x, +y, +z), the front
// of a Y-up model facing +z; X up from (+x, +y, +z) with +z as the front.
Vec3f default_to_eye(Axis up) {
  const float side = kCosEl * kSinAz, front = kCosEl * kCosAz, above = kSinEl;
  switch (up) {
    case Axis::X:
      return {above, side, front};
    case Axis::Y:
      return {side, above, front};
    case Axis::Z:
      break;
  }
  return {side, -front, above};
}

Vec3f axis_vector(Axis a) {
  return a == Axis::X ? Vec3f(1, 0, 0) : a == Axis::Y ? Vec3f(0, 1, 0) : Vec3f(0, 0, 1);
}

// The eight corners of the box, or of the unit box around the origin for an empty or non-finite
// box; a box thinner than 2.5e-7 of its distance from the origin (about two floats there) is grown
// to that size, so that the eye never lands on it.
std::array<Vec3f, 8> frame_corners(const Box3f& box) {
  Box3f b = box;
  if (b.empty() || !is_finite(b.lo) || !is_finite(b.hi)) b = {Vec3f(-1.0f), Vec3f(1.0f)};
  Vec3f c = b.center();
  float floor_half = std::max(1e-6f, 2.5e-7f * reduce_max(abs(c)));
  Vec3f half = max((b.hi - b.lo) * 0.5f, Vec3f(floor_half));
  std::array<Vec3f, 8> out;
  for (int i = 0; i < 8; ++i)
    out[i] =
        c + Vec3f(i & 1 ? half.x : -half.x, i & 2 ? half.y : -half.y, i & 4 ? half.z : -half.z);
  return out;
}

}  // namespace

Camera view_camera(const Box3f& box, const ViewOptions& view, int width, int height) {
  if (!(view.fov_deg > 0.0f && view.fov_deg < 180.0f))
    throw Error("camera: expected a field of view in (0, 180) degrees, got " +
                std::to_string(view.fov_deg));
  if ((view.has_eye && !is_finite(view.eye)) || (view.has_look_at && !is_finite(view.look_at)))
    throw Error("camera: expected finite --eye and --look-at coordinates");
  Camera cam;
  cam.width = std::max(width, 1);
  cam.height = std::max(height, 1);
  const std::array<Vec3f, 8> corners = frame_corners(box);
  // Work in double: eye and box may lie near 1e12 where float differences lose the view.
  auto d3 = [](Vec3f v) { return std::array<double, 3>{v.x, v.y, v.z}; };
  using D3 = std::array<double, 3>;
  auto sub = [](D3 a, D3 b) { return D3{a[0] - b[0], a[1] - b[1], a[2] - b[2]}; };
  auto add = [](D3 a, D3 b) { return D3{a[0] + b[0], a[1] + b[1], a[2] + b[2]}; };
  auto mul = [](D3 a, double s) { return D3{a[0] * s, a[1] * s, a[2] * s}; };
  auto dot3 = [](D3 a, D3 b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
  auto cross3 = [](D3 a, D3 b) {
    return D3{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  };
  auto unit = [&](D3 a) {
    double l = std::sqrt(dot3(a, a));
    return l > 0 ? mul(a, 1.0 / l) : D3{0, 0, 0};
  };
  D3 center{0, 0, 0};
  for (const Vec3f& c : corners) center = add(center, mul(d3(c), 0.125));
  const D3 up_axis = d3(axis_vector(view.up));
  const double tan_v = std::tan(double(view.fov_deg) * 0.5 * M_PI / 180.0);
  const double tan_h = tan_v * double(cam.width) / double(cam.height);

  D3 target = view.has_look_at ? d3(view.look_at) : center;
  D3 forward;
  if (view.has_eye) {
    forward = unit(sub(target, d3(view.eye)));
    if (forward == D3{0, 0, 0}) throw Error("camera: --eye and --look-at are the same point");
  } else {
    forward = mul(d3(default_to_eye(view.up)), -1.0);
  }
  D3 right = cross3(forward, up_axis);
  if (dot3(right, right) < 1e-12)
    throw Error("camera: the view direction is along the up axis; choose another --up or --eye");
  right = unit(right);
  const D3 up = cross3(right, forward);

  D3 eye;
  if (view.has_eye) {
    eye = d3(view.eye);
  } else {
    // Back off along -forward until every corner projects inside the image: a corner at lateral
    // offsets (x, y) and depth z (towards the eye, from the target) needs D >= z + |x| / tan.
    // Twice: the second pass re-centres the target on the corners' projected extent.
    const double margin = 1.03;
    double dist = 0;
    for (int pass = 0; pass < 2; ++pass) {
      dist = 0;
      for (const Vec3f& c : corners) {
        D3 rel = sub(d3(c), target);
        double x = dot3(rel, right), y = dot3(rel, up), z = -dot3(rel, forward);
        dist = std::max(dist, z + margin * std::max(std::fabs(x) / tan_h, std::fabs(y) / tan_v));
      }
      if (view.has_look_at || pass == 1) break;
      double xlo = 1e300, xhi = -1e300, ylo = 1e300, yhi = -1e300;
      for (const Vec3f& c : corners) {
        D3 rel = sub(d3(c), target);
        double x = dot3(rel, right), y = dot3(rel, up), depth = dist + dot3(rel, forward);
        xlo = std::min(xlo, x / depth), xhi = std::max(xhi, x / depth);
        ylo = std::min(ylo, y / depth), yhi = std::max(yhi, y / depth);
      }
      target =
          add(target, add(mul(right, 0.5 * (xlo + xhi) * dist), mul(up, 0.5 * (ylo + yhi) * dist)));
    }
    eye = sub(target, mul(forward, dist));
  }

  cam.eye = Vec3f(float(eye[0]), float(eye[1]), float(eye[2]));
  const Vec3f f{float(forward[0]), float(forward[1]), float(forward[2])};
  const Vec3f r{float(right[0]), float(right[1]), float(right[2])};
  const Vec3f u{float(up[0]), float(up[1]), float(up[2])};
  cam.du = r * float(2.0 * tan_h / cam.width);
  cam.dv = u * float(-2.0 * tan_v / cam.height);  // top row first
  cam.dir00 = f - r * float(tan_h) + u * float(tan_v);
  if (reduce_max(abs(cam.eye)) > 0.5f * kMaxCoordinate || !is_finite(cam.eye)) {
    cam.clip = true;
    Box3f b(corners[0], corners[7]);
    Vec3f pad = (b.hi - b.lo) * 1e-3f;
    cam.clip_box = Box3f(b.lo - pad, b.hi + pad);
  }
  return cam;
}

}  // namespace slim
