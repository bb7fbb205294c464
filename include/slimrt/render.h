// slimrt rendering: the benchmark camera, the diffuse path tracer (the benchmark's workloads 1 and
// 2), debug shadings and images. The path tracer is a template over any "tracer" with
//   slim::Hit intersect(const slim::Ray&) const;
// so that slimrt scenes and the Embree baseline run exactly the same rays.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "slimrt/math.h"
#include "slimrt/scene.h"

namespace slim {

// Pinhole camera. Rays start at `eye`; pixel (x, y) maps to eye + dir00 + du * (x+0.5) + dv *
// (y+0.5). When `clip` is set (an eye beyond the supported coordinate range, see kMaxCoordinate),
// each ray starts where it enters `clip_box` instead, so that a view from far away still sees the
// scene.
struct Camera {
  Vec3f eye;
  Vec3f dir00;   // direction to the top-left image corner
  Vec3f du, dv;  // per-pixel steps
  int width = 1024, height = 1024;
  bool clip = false;
  Box3f clip_box;
};

// The benchmark camera: looks at the box from a fixed direction (from the +x, -y, +z side, 35
// degrees above the horizon, 30 degrees off the -y axis, z up, 40 degree vertical field of view)
// and frames the box's bounding sphere.
Camera frame_box(const Box3f& box, int width, int height);

// The user's camera (slimrt render): which axis is up, an optional eye and look-at point, the
// vertical field of view. Without an eye the camera looks from the benchmark camera's direction
// (35 degrees above the horizon, 30 degrees round from the front) relative to the up axis and
// backs off until the box's eight corners fill the image (centred, 3% margin); without a look-at
// point it looks at the box centre. An eye beyond +-kMaxCoordinate / 2 sets Camera::clip.
enum class Axis : uint8_t { X = 0, Y = 1, Z = 2 };
struct ViewOptions {
  Axis up = Axis::Z;
  bool has_eye = false, has_look_at = false;
  Vec3f eye, look_at;
  float fov_deg = 40.0f;  // vertical field of view, degrees, in (0, 180)
};
// Throws slim::Error for a field of view outside (0, 180), non-finite points, an eye on the
// look-at point or a view direction along the up axis.
Camera view_camera(const Box3f& box, const ViewOptions& view, int width, int height);

SLIM_INLINE Ray camera_ray(const Camera& c, float px, float py) {
  Ray r;
  r.org = c.eye;
  r.dir = normalize(c.dir00 + c.du * px + c.dv * py);
  r.tnear = 0.0f;
  r.tfar = kInf;
  if (c.clip) {  // start on the box (slab test); a ray that misses it keeps its far origin
    float t0 = 0.0f, t1 = kInf;
    for (int k = 0; k < 3; ++k) {
      float inv = 1.0f / r.dir[k];
      float a = (c.clip_box.lo[k] - r.org[k]) * inv, b = (c.clip_box.hi[k] - r.org[k]) * inv;
      t0 = std::max(t0, std::min(a, b));
      t1 = std::min(t1, std::max(a, b));
    }
    if (t0 <= t1 && std::isfinite(t0)) r.org = r.org + r.dir * t0;
  }
  return r;
}

// Small, fast, deterministic per-pixel random numbers (PCG32).
struct Rng {
  uint64_t state;
  explicit Rng(uint64_t seed, uint64_t stream = 0) : state(0) {
    inc = (stream << 1u) | 1u;
    next();
    state += seed;
    next();
  }
  uint32_t next() {
    uint64_t old = state;
    state = old * 6364136223846793005ULL + inc;
    uint32_t xorshifted = uint32_t(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = uint32_t(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((32 - rot) & 31));
  }
  float uniform() { return float(next() >> 8) * (1.0f / 16777216.0f); }  // [0,1)
  uint64_t inc;
};

// Orthonormal basis around n (Duff et al. 2017).
SLIM_INLINE void onb(Vec3f n, Vec3f& t, Vec3f& b) {
  float s = std::copysign(1.0f, n.z);
  float a = -1.0f / (s + n.z);
  float c = n.x * n.y * a;
  t = {1.0f + s * n.x * n.x * a, s * c, -s * n.x};
  b = {c, s + n.y * n.y * a, -n.y};
}

// Scale used to offset secondary ray origins off the surface they start on.
SLIM_INLINE float ray_offset_scale(const Box3f& box) {
  return 2e-5f * std::max(reduce_max(abs(box.lo)), reduce_max(abs(box.hi)));
}

struct PathResult {
  Vec3f radiance;
  uint32_t rays = 0;  // rays traced for this path (primary + bounces)
  Hit primary;        // the primary hit
};

// The benchmark's workload 2: a primary ray and up to `max_bounces` cosine-weighted diffuse
// bounces, albedo 0.7, lit by a white-blue sky, bluest towards `up` (a unit vector; the benchmark
// keeps +z); every ray traced is counted.
template <class Tracer>
PathResult trace_path(const Tracer& tracer, Ray ray, Rng& rng, int max_bounces, float offset,
                      Vec3f up = Vec3f(0.0f, 0.0f, 1.0f)) {
  PathResult res;
  Vec3f throughput(1.0f);
  for (int bounce = 0; bounce <= max_bounces; ++bounce) {
    Hit h = tracer.intersect(ray);
    res.rays++;
    if (bounce == 0) res.primary = h;
    if (!h.valid()) {
      const float a = 0.5f + 0.5f * dot(ray.dir, up);
      Vec3f sky = Vec3f(1.0f) * (1.0f - a) + Vec3f(0.5f, 0.7f, 1.0f) * a;
      res.radiance += throughput * sky;
      break;
    }
    if (bounce == max_bounces) break;
    Vec3f n = safe_normalize(h.Ng);
    if (n.x == 0.0f && n.y == 0.0f && n.z == 0.0f) break;
    if (dot(n, ray.dir) > 0.0f) n = -n;
    Vec3f p = ray.org + ray.dir * h.t;
    float eps = offset + 1e-6f * reduce_max(abs(p));
    Vec3f t, b;
    onb(n, t, b);
    float r1 = rng.uniform(), r2 = rng.uniform();
    float phi = 6.28318530718f * r1;
    float sr = std::sqrt(r2);
    Vec3f d = t * (std::cos(phi) * sr) + b * (std::sin(phi) * sr) +
              n * std::sqrt(std::max(0.0f, 1.0f - r2));
    ray.org = p + n * eps;
    ray.dir = normalize(d);
    ray.tnear = 0.0f;
    ray.tfar = kInf;
    throughput = throughput * 0.7f;
  }
  return res;
}

// Per-pixel RNG seed used by the renderer and the benchmark (deterministic).
SLIM_INLINE uint64_t pixel_seed(int x, int y, int sample) {
  return (uint64_t(uint32_t(y)) << 32 | uint32_t(x)) * 0x9E3779B97F4A7C15ULL + uint64_t(sample);
}

// Diffuse: the benchmark's workload 2 (docs/benchmark.md) (sky light only, the sky's zenith at
// RenderOptions::up). Sun: a low sun from the camera's left (25 degrees above the horizon of
// RenderOptions::up) with a shadow ray, plus one diffuse bounce under the sky: the shading that
// shows relief. Normals, Kind: debug shadings.
enum class Shade { Diffuse, Normals, Kind, Sun };

struct RenderOptions {
  int width = 1024, height = 1024;
  int spp = 1;
  int max_bounces = 8;
  Shade shade = Shade::Diffuse;
  int threads = 0;             // 0 = all cores
  Vec3f up{0.0f, 0.0f, 1.0f};  // Diffuse, Sun: the scene's up direction, the sky's zenith
  bool progress = false;       // progress on stderr (percentage, elapsed, MRays/s) after ~2 s
};

// Linear RGB float image, row-major, top row first.
struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 floats per pixel
};

struct RenderStats {
  uint64_t rays = 0;  // every ray traced (camera rays and diffuse bounces)
};

// The image size render(scene, cam, opt) makes: opt's width/height where set, else the camera's.
// Throws slim::Error unless both are positive.
void render_size(const Camera& cam, const RenderOptions& opt, int& width, int& height);
// Renders the scene with the camera, tiles spread over the threads.
Image render(const Scene& scene, const Camera& cam, const RenderOptions& opt,
             RenderStats* stats = nullptr);
// The pixels [x0, x1) x [y0, y1) of the image render(scene, cam, opt) makes, written row-major
// into out, which must hold (x1 - x0) * (y1 - y0) * 3 floats: every pixel is traced with the same
// rays, seeds and sample order as in render(), so its value is the same bits. For splitting one
// image across processes (`slimrt render` under mpirun). Throws slim::Error unless the rectangle
// is non-empty and inside the image; opt.progress reports on this rectangle alone.
void render_region(const Scene& scene, const Camera& cam, const RenderOptions& opt, int x0, int y0,
                   int x1, int y1, float* out, RenderStats* stats = nullptr);
// Writes PNG (8-bit sRGB) or EXR (float) by the file extension; throws slim::Error otherwise.
void write_image(const Image& img, const std::string& path);
// PSNR in dB of b against a (both tone-mapped to 8-bit sRGB as in the PNG); +inf if identical.
double psnr(const Image& a, const Image& b);

}  // namespace slim
