// slimrt public math types: 3-vectors, 2-vectors and axis-aligned boxes.
// Small, header-only, used by the public API and internally.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#if defined(__GNUC__)
#define SLIM_INLINE inline __attribute__((always_inline))
#else
#define SLIM_INLINE inline
#endif

namespace slim {

constexpr float kInf = std::numeric_limits<float>::infinity();

struct Vec2f {
  float x = 0, y = 0;
};

struct Vec3f {
  float x = 0, y = 0, z = 0;

  constexpr Vec3f() = default;
  constexpr Vec3f(float a, float b, float c) : x(a), y(b), z(c) {}
  explicit constexpr Vec3f(float s) : x(s), y(s), z(s) {}

  SLIM_INLINE float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  SLIM_INLINE float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

SLIM_INLINE Vec3f operator+(Vec3f a, Vec3f b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
SLIM_INLINE Vec3f operator-(Vec3f a, Vec3f b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
SLIM_INLINE Vec3f operator-(Vec3f a) { return {-a.x, -a.y, -a.z}; }
SLIM_INLINE Vec3f operator*(Vec3f a, Vec3f b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
SLIM_INLINE Vec3f operator*(Vec3f a, float s) { return {a.x * s, a.y * s, a.z * s}; }
SLIM_INLINE Vec3f operator*(float s, Vec3f a) { return {a.x * s, a.y * s, a.z * s}; }
SLIM_INLINE Vec3f operator/(Vec3f a, float s) { return {a.x / s, a.y / s, a.z / s}; }
SLIM_INLINE Vec3f operator/(Vec3f a, Vec3f b) { return {a.x / b.x, a.y / b.y, a.z / b.z}; }
SLIM_INLINE Vec3f& operator+=(Vec3f& a, Vec3f b) { return a = a + b; }
SLIM_INLINE Vec3f& operator-=(Vec3f& a, Vec3f b) { return a = a - b; }
SLIM_INLINE Vec3f& operator*=(Vec3f& a, float s) { return a = a * s; }
SLIM_INLINE bool operator==(Vec3f a, Vec3f b) { return a.x == b.x && a.y == b.y && a.z == b.z; }
SLIM_INLINE bool operator!=(Vec3f a, Vec3f b) { return !(a == b); }

SLIM_INLINE float dot(Vec3f a, Vec3f b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
SLIM_INLINE Vec3f cross(Vec3f a, Vec3f b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
SLIM_INLINE float length(Vec3f a) { return std::sqrt(dot(a, a)); }
SLIM_INLINE Vec3f normalize(Vec3f a) { return a * (1.0f / length(a)); }

SLIM_INLINE Vec3f min(Vec3f a, Vec3f b) {
  return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)};
}
SLIM_INLINE Vec3f max(Vec3f a, Vec3f b) {
  return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)};
}
SLIM_INLINE Vec3f abs(Vec3f a) { return {std::fabs(a.x), std::fabs(a.y), std::fabs(a.z)}; }
SLIM_INLINE float reduce_max(Vec3f a) { return std::max(a.x, std::max(a.y, a.z)); }

// Unit vector along v, or zero when v is zero or not finite. Scales first, so that vectors
// whose squared length overflows float (normals of triangles with 1e10-long edges) still
// normalize.
SLIM_INLINE Vec3f safe_normalize(Vec3f v) {
  float m = reduce_max(abs(v));
  if (!(m > 0.0f) || !std::isfinite(m)) return Vec3f(0.0f);
  v = v * (1.0f / m);
  return v * (1.0f / length(v));
}
SLIM_INLINE float reduce_min(Vec3f a) { return std::min(a.x, std::min(a.y, a.z)); }
SLIM_INLINE bool is_finite(Vec3f a) {
  return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z);
}
SLIM_INLINE int max_dim(Vec3f a) { return a.x >= a.y ? (a.x >= a.z ? 0 : 2) : (a.y >= a.z ? 1 : 2); }

// Axis-aligned box. An empty box has lo = +inf, hi = -inf so that extend() works from it.
struct Box3f {
  Vec3f lo{kInf, kInf, kInf};
  Vec3f hi{-kInf, -kInf, -kInf};

  constexpr Box3f() = default;
  constexpr Box3f(Vec3f l, Vec3f h) : lo(l), hi(h) {}

  SLIM_INLINE void extend(Vec3f p) {
    lo = min(lo, p);
    hi = max(hi, p);
  }
  SLIM_INLINE void extend(const Box3f& b) {
    lo = min(lo, b.lo);
    hi = max(hi, b.hi);
  }
  SLIM_INLINE bool empty() const { return !(lo.x <= hi.x && lo.y <= hi.y && lo.z <= hi.z); }
  SLIM_INLINE Vec3f size() const { return hi - lo; }
  SLIM_INLINE Vec3f center() const { return (lo + hi) * 0.5f; }
  // Half the surface area (the SAH only needs ratios). Zero for empty boxes.
  SLIM_INLINE float half_area() const {
    if (empty()) return 0.0f;
    Vec3f d = hi - lo;
    return d.x * d.y + d.y * d.z + d.z * d.x;
  }
  SLIM_INLINE bool contains(const Box3f& b) const {
    return b.lo.x >= lo.x && b.lo.y >= lo.y && b.lo.z >= lo.z && b.hi.x <= hi.x &&
           b.hi.y <= hi.y && b.hi.z <= hi.z;
  }
  SLIM_INLINE bool contains(Vec3f p) const {
    return p.x >= lo.x && p.y >= lo.y && p.z >= lo.z && p.x <= hi.x && p.y <= hi.y && p.z <= hi.z;
  }
};

SLIM_INLINE Box3f merge(const Box3f& a, const Box3f& b) { return {min(a.lo, b.lo), max(a.hi, b.hi)}; }

}  // namespace slim
