// The renderer: the benchmark's workload 2 (docs/benchmark.md: diffuse path tracing,
// slim::trace_path) and two debug shadings, over 32x32 tiles spread across threads with TBB
// (smaller tiles for a small region).
//
// Rays are deterministic: sample s of pixel (x, y) uses slim::Rng(pixel_seed(x, y, s)) for its
// jitter and its bounces, so an image does not depend on the thread count or the tile order and two
// configurations of one scene can be compared pixel by pixel (PSNR of lossy formats). With one
// sample per pixel the ray goes through the pixel centre, as the benchmark's primary rays do.
// render_region() shades any rectangle of that image through the same PixelShader, so the pieces
// of an image rendered apart (slimrt render under mpirun) equal render()'s pixels bit for bit.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <mutex>

#include "render/tiling.h"
#include "slimrt/render.h"

namespace slim {

namespace {

// Linear RGB colour of each primitive kind (Shade::Kind).
Vec3f kind_colour(PrimKind kind) {
  switch (kind) {
    case PrimKind::Triangle:
      return {0.90f, 0.08f, 0.06f};  // red
    case PrimKind::Quad:
      return {0.90f, 0.75f, 0.05f};  // yellow
    case PrimKind::Fan:
      return {0.08f, 0.20f, 0.95f};  // blue
    case PrimKind::Strip:
      return {0.55f, 0.12f, 0.85f};  // violet
    case PrimKind::Pair:
      return {0.08f, 0.75f, 0.15f};  // green
    case PrimKind::Grid:
      return {0.05f, 0.75f, 0.85f};  // cyan
  }
  return {1.0f, 1.0f, 1.0f};
}

// Unit geometric normal, or zero for a degenerate one (safe_normalize: no overflow for the
// normals of huge triangles).
Vec3f unit_normal(const Hit& h) { return safe_normalize(h.Ng); }

// Progress on stderr, updated as tiles finish (any thread, one atomic add per tile): nothing for
// the first 2 s, then the percentage, the elapsed time and the rate, redrawn when the shown
// percentage changes.
class Progress {
 public:
  using Clock = std::chrono::steady_clock;
  Progress(bool enabled, int total) : enabled_(enabled), total_(std::max(total, 1)) {}
  void tile_done(uint64_t rays) {
    if (!enabled_) return;
    rays_.fetch_add(rays, std::memory_order_relaxed);
    int done = ++done_;
    int percent = int(int64_t(done) * 100 / total_);
    if (percent <= shown_.load(std::memory_order_relaxed)) return;
    std::lock_guard<std::mutex> lock(mutex_);
    double elapsed = std::chrono::duration<double>(Clock::now() - start_).count();
    if (percent <= shown_ || elapsed < kDelaySeconds) return;
    std::fprintf(stderr, "\rrender %3d%% | %.1f s | %.2f MRays/s ", percent, elapsed,
                 double(rays_.load()) / elapsed * 1e-6);
    std::fflush(stderr);
    shown_ = percent;
    drawn_ = true;
  }
  void finish() {
    if (!enabled_ || !drawn_) return;
    std::fputc('\n', stderr);
    std::fflush(stderr);
  }

 private:
  static constexpr double kDelaySeconds = 2.0;
  bool enabled_;
  int total_;
  Clock::time_point start_ = Clock::now();
  std::atomic<int> done_{0};
  std::atomic<uint64_t> rays_{0};
  std::atomic<int> shown_{-1};
  bool drawn_ = false;
  std::mutex mutex_;
};

// Unit up vector (z when unset).
Vec3f sun_up(Vec3f up) {
  Vec3f u = safe_normalize(up);
  return u.x == 0.0f && u.y == 0.0f && u.z == 0.0f ? Vec3f(0.0f, 0.0f, 1.0f) : u;
}

}  // namespace

void render_size(const Camera& cam, const RenderOptions& opt, int& width, int& height) {
  width = opt.width > 0 ? opt.width : cam.width;
  height = opt.height > 0 ? opt.height : cam.height;
  if (width <= 0 || height <= 0)
    throw Error("render: image size must be positive, got " + std::to_string(width) + "x" +
                std::to_string(height));
}

namespace {

// What decides every pixel's value: the scene, the camera scaled to the image size, the options
// and the sun of Shade::Sun. render() and render_region() shade through it, so a pixel computed by
// either (any thread, any tile, any process) is the same bits.
class PixelShader {
 public:
  PixelShader(const Scene& scene, const Camera& cam_in, const RenderOptions& opt)
      : scene_(scene), opt_(opt) {
    // The camera defines the view, the options the resolution: rescale the pixel steps when they
    // differ so that the whole camera view lands in the image.
    cam_ = cam_in;
    int width = 0, height = 0;
    render_size(cam_in, opt, width, height);
    if (cam_.width > 0 && cam_.height > 0) {
      cam_.du = cam_.du * (float(cam_.width) / float(width));
      cam_.dv = cam_.dv * (float(cam_.height) / float(height));
    }
    cam_.width = width;
    cam_.height = height;
    spp_ = std::max(opt.spp, 1);
    max_bounces_ = std::max(opt.max_bounces, 0);
    offset_ = ray_offset_scale(scene.bounds());
    inv_spp_ = 1.0f / float(spp_);
    // Shade::Sun: the sun comes from the camera's left and a little from behind the scene, 25
    // degrees above the horizon, so that slopes facing it are bright and ridges cast shadows.
    up_ = sun_up(opt.up);
    if (opt.shade == Shade::Sun) {
      const Vec3f up = up_;
      Vec3f right = safe_normalize(cam_.du - up * dot(cam_.du, up));
      Vec3f fwd = safe_normalize(cross(up, right));  // horizontal, into the picture
      Vec3f h = safe_normalize(right * -0.9f + fwd * 0.45f);
      sun_ = safe_normalize(h * 0.906f + up * 0.423f);
      if (h.x == 0.0f && h.y == 0.0f && h.z == 0.0f) sun_ = up;
    }
  }

  int width() const { return cam_.width; }
  int height() const { return cam_.height; }

  // The mean of the spp samples of pixel (x, y), summed in sample order; adds the rays traced to
  // `rays`.
  Vec3f pixel(int x, int y, uint64_t& rays) const {
    Vec3f sum(0.0f);
    for (int s = 0; s < spp_; ++s) sum += sample(x, y, s, rays);
    sum *= inv_spp_;
    return sum;
  }

 private:
  Vec3f sample(int x, int y, int s, uint64_t& rays) const {
    const Scene& scene = scene_;
    const RenderOptions& opt = opt_;
    const float offset = offset_;
    const Vec3f sun = sun_;
    const Vec3f sun_colour(1.6f, 1.42f, 1.15f);
    Rng rng(pixel_seed(x, y, s));
    float jx = 0.5f, jy = 0.5f;
    if (spp_ > 1) {
      jx = rng.uniform();
      jy = rng.uniform();
    }
    Ray ray = camera_ray(cam_, float(x) + jx, float(y) + jy);
    switch (opt.shade) {
      case Shade::Diffuse: {
        PathResult p = trace_path(scene, ray, rng, max_bounces_, offset, up_);
        rays += p.rays;
        return p.radiance;
      }
      case Shade::Normals: {
        rays++;
        Hit h = scene.intersect(ray);
        if (!h.valid()) return Vec3f(0.03f);  // dark grey background
        return Vec3f(0.5f) + unit_normal(h) * 0.5f;
      }
      case Shade::Sun: {
        rays++;
        Hit h = scene.intersect(ray);
        auto sky = [&](Vec3f d) {
          float a = 0.5f + 0.5f * dot(d, up_);
          return Vec3f(0.75f, 0.8f, 0.88f) * (1.0f - a) + Vec3f(0.25f, 0.42f, 0.8f) * a;
        };
        if (!h.valid()) return sky(ray.dir);
        Vec3f n = safe_normalize(h.Ng);
        if (dot(n, ray.dir) > 0.0f) n = -n;
        const Vec3f albedo(0.7f, 0.5f, 0.36f);
        Vec3f p = ray.org + ray.dir * h.t;
        float eps = offset + 1e-6f * reduce_max(abs(p));
        Vec3f o = p + n * eps;
        Vec3f c(0.0f);
        float ndl = dot(n, sun);
        if (ndl > 0.0f) {
          Ray s{o, 0.0f, sun, kInf};
          rays++;
          if (!scene.occluded(s)) c += sun_colour * ndl;
        }
        // One cosine-weighted bounce: sky light where the hemisphere is open, a dim bounce of
        // the sun where it meets the scene.
        Vec3f t, b;
        onb(n, t, b);
        float r1 = rng.uniform(), r2 = rng.uniform();
        float phi = 6.28318530718f * r1, sr = std::sqrt(r2);
        Vec3f d = normalize(t * (std::cos(phi) * sr) + b * (std::sin(phi) * sr) +
                            n * std::sqrt(std::max(0.0f, 1.0f - r2)));
        Ray bounce{o, 0.0f, d, kInf};
        rays++;
        Hit hb = scene.intersect(bounce);
        c += hb.valid() ? sun_colour * (0.1f * albedo.x) : sky(d) * 0.6f;
        return albedo * c;
      }
      case Shade::Kind: {
        rays++;
        Hit h = scene.intersect(ray);
        if (!h.valid()) return Vec3f(0.0f);
        float c = std::fabs(dot(unit_normal(h), ray.dir));
        return kind_colour(h.kind) * (0.15f + 0.85f * c);
      }
    }
    return Vec3f(0.0f);
  }

  const Scene& scene_;
  const RenderOptions& opt_;
  Camera cam_;
  int spp_ = 1, max_bounces_ = 0;
  float offset_ = 0.0f, inv_spp_ = 1.0f;
  Vec3f sun_{0.0f, 0.0f, 1.0f};
  Vec3f up_{0.0f, 0.0f, 1.0f};  // the sky's zenith and the sun's up (RenderOptions::up)
};

// Shades the pixels [x0, x1) x [y0, y1) into out (row-major, `stride` floats per row, pixel
// (x0, y0) first) over square tiles spread across opt.threads threads (0: the current task
// arena's); returns the rays traced. Tiles are kTileSize pixels wide, halved while the rectangle
// holds fewer than kTilesPerThread tiles per thread (down to kMinTileSize), so that a small
// rectangle (one tile of `slimrt render` under mpirun) still keeps every thread busy. A pixel's
// value does not depend on the tiling (PixelShader: per-pixel seeds).
uint64_t shade_rect(const PixelShader& shader, const RenderOptions& opt, int x0, int y0, int x1,
                    int y1, float* out, size_t stride) {
  const int threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  const int tile_size = render_tiling::tile_size(x1 - x0, y1 - y0, threads);
  const int tiles_x = (x1 - x0 + tile_size - 1) / tile_size;
  const int tiles_y = (y1 - y0 + tile_size - 1) / tile_size;
  const int tile_count = tiles_x * tiles_y;
  Progress progress(opt.progress, tile_count);
  std::atomic<uint64_t> rays_traced{0};
  auto render_tiles = [&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& r) {
          uint64_t rays = 0;
          for (int tile = r.begin(); tile != r.end(); ++tile) {
            const uint64_t rays_before = rays;
            int tx0 = x0 + (tile % tiles_x) * tile_size, ty0 = y0 + (tile / tiles_x) * tile_size;
            int tx1 = std::min(tx0 + tile_size, x1), ty1 = std::min(ty0 + tile_size, y1);
            for (int y = ty0; y < ty1; ++y) {
              for (int x = tx0; x < tx1; ++x) {
                Vec3f v = shader.pixel(x, y, rays);
                float* px = out + size_t(y - y0) * stride + size_t(x - x0) * 3;
                px[0] = v.x;
                px[1] = v.y;
                px[2] = v.z;
              }
            }
            progress.tile_done(rays - rays_before);
          }
          rays_traced += rays;
        });
  };
  if (opt.threads > 0) {
    tbb::task_arena arena(opt.threads);
    arena.execute(render_tiles);
  } else {
    render_tiles();
  }
  progress.finish();
  return rays_traced.load();
}

}  // namespace

Image render(const Scene& scene, const Camera& cam, const RenderOptions& opt, RenderStats* stats) {
  PixelShader shader(scene, cam, opt);
  Image img;
  img.width = shader.width();
  img.height = shader.height();
  img.rgb.assign(size_t(img.width) * size_t(img.height) * 3, 0.0f);
  uint64_t rays =
      shade_rect(shader, opt, 0, 0, img.width, img.height, img.rgb.data(), size_t(img.width) * 3);
  if (stats) stats->rays = rays;
  return img;
}

void render_region(const Scene& scene, const Camera& cam, const RenderOptions& opt, int x0, int y0,
                   int x1, int y1, float* out, RenderStats* stats) {
  PixelShader shader(scene, cam, opt);
  if (x0 < 0 || y0 < 0 || x1 <= x0 || y1 <= y0 || x1 > shader.width() || y1 > shader.height())
    throw Error("render_region: [" + std::to_string(x0) + ", " + std::to_string(x1) + ") x [" +
                std::to_string(y0) + ", " + std::to_string(y1) +
                ") is not a non-empty rectangle inside the " + std::to_string(shader.width()) +
                "x" + std::to_string(shader.height()) + " image");
  uint64_t rays = shade_rect(shader, opt, x0, y0, x1, y1, out, size_t(x1 - x0) * 3);
  if (stats) stats->rays = rays;
}

}  // namespace slim
