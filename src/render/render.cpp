// The renderer: BENCHMARK.md workload 2 (diffuse path tracing, slim::trace_path) and two debug
// shadings, over 32x32 tiles spread across threads with TBB.
//
// Rays are deterministic: sample s of pixel (x, y) uses slim::Rng(pixel_seed(x, y, s)) for its
// jitter and its bounces, so an image does not depend on the thread count or the tile order and two
// configurations of one scene can be compared pixel by pixel (PSNR of lossy formats). With one
// sample per pixel the ray goes through the pixel centre, as the benchmark's primary rays do.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <mutex>

#include "slimrt/render.h"

namespace slim {

namespace {

constexpr int kTileSize = 32;

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

// Unit geometric normal, or zero for a degenerate one.
Vec3f unit_normal(const Hit& h) {
  float len = length(h.Ng);
  return len > 0.0f && std::isfinite(len) ? h.Ng * (1.0f / len) : Vec3f(0.0f);
}

// A progress bar on stderr, updated as tiles finish (any thread); redrawn only when the shown
// percentage changes.
class ProgressBar {
 public:
  ProgressBar(bool enabled, int total) : enabled_(enabled), total_(std::max(total, 1)) {
    if (enabled_) draw(0);
  }
  void tile_done() {
    if (!enabled_) return;
    int done = ++done_;
    int percent = int(int64_t(done) * 100 / total_);
    std::lock_guard<std::mutex> lock(mutex_);
    if (percent > shown_) draw(percent);
  }
  void finish() {
    if (!enabled_) return;
    std::lock_guard<std::mutex> lock(mutex_);
    std::fputc('\n', stderr);
    std::fflush(stderr);
  }

 private:
  void draw(int percent) {  // caller holds mutex_ (or runs before the threads start)
    constexpr int kWidth = 40;
    char bar[kWidth + 1];
    int filled = percent * kWidth / 100;
    for (int i = 0; i < kWidth; ++i) bar[i] = i < filled ? '#' : '.';
    bar[kWidth] = 0;
    std::fprintf(stderr, "\rrender [%s] %3d%%", bar, percent);
    std::fflush(stderr);
    shown_ = percent;
  }

  bool enabled_;
  int total_;
  std::atomic<int> done_{0};
  std::mutex mutex_;
  int shown_ = -1;
};

}  // namespace

Image render(const Scene& scene, const Camera& cam_in, const RenderOptions& opt,
             RenderStats* stats) {
  // The camera defines the view, the options the resolution: rescale the pixel steps when they
  // differ so that the whole camera view lands in the image.
  Camera cam = cam_in;
  int width = opt.width > 0 ? opt.width : cam.width;
  int height = opt.height > 0 ? opt.height : cam.height;
  if (width <= 0 || height <= 0)
    throw Error("render: image size must be positive, got " + std::to_string(width) + "x" +
                std::to_string(height));
  if (cam.width > 0 && cam.height > 0) {
    cam.du = cam.du * (float(cam.width) / float(width));
    cam.dv = cam.dv * (float(cam.height) / float(height));
  }
  cam.width = width;
  cam.height = height;

  const int spp = std::max(opt.spp, 1);
  const int max_bounces = std::max(opt.max_bounces, 0);
  const float offset = ray_offset_scale(scene.bounds());
  const float inv_spp = 1.0f / float(spp);

  Image img;
  img.width = width;
  img.height = height;
  img.rgb.assign(size_t(width) * size_t(height) * 3, 0.0f);

  std::atomic<uint64_t> rays_traced{0};
  auto shade_sample = [&](int x, int y, int s, uint64_t& rays) -> Vec3f {
    Rng rng(pixel_seed(x, y, s));
    float jx = 0.5f, jy = 0.5f;
    if (spp > 1) {
      jx = rng.uniform();
      jy = rng.uniform();
    }
    Ray ray = camera_ray(cam, float(x) + jx, float(y) + jy);
    switch (opt.shade) {
      case Shade::Diffuse: {
        PathResult p = trace_path(scene, ray, rng, max_bounces, offset);
        rays += p.rays;
        return p.radiance;
      }
      case Shade::Normals: {
        rays++;
        Hit h = scene.intersect(ray);
        if (!h.valid()) return Vec3f(0.03f);  // dark grey background
        return Vec3f(0.5f) + unit_normal(h) * 0.5f;
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
  };

  const int tiles_x = (width + kTileSize - 1) / kTileSize;
  const int tiles_y = (height + kTileSize - 1) / kTileSize;
  const int tile_count = tiles_x * tiles_y;
  ProgressBar progress(opt.progress, tile_count);

  auto render_tiles = [&] {
    tbb::parallel_for(
        tbb::blocked_range<int>(0, tile_count, 1), [&](const tbb::blocked_range<int>& r) {
          uint64_t rays = 0;
          for (int tile = r.begin(); tile != r.end(); ++tile) {
            int x0 = (tile % tiles_x) * kTileSize, y0 = (tile / tiles_x) * kTileSize;
            int x1 = std::min(x0 + kTileSize, width), y1 = std::min(y0 + kTileSize, height);
            for (int y = y0; y < y1; ++y) {
              for (int x = x0; x < x1; ++x) {
                Vec3f sum(0.0f);
                for (int s = 0; s < spp; ++s) sum += shade_sample(x, y, s, rays);
                sum *= inv_spp;
                float* px = &img.rgb[(size_t(y) * size_t(width) + size_t(x)) * 3];
                px[0] = sum.x;
                px[1] = sum.y;
                px[2] = sum.z;
              }
            }
            progress.tile_done();
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
  if (stats) stats->rays = rays_traced.load();
  return img;
}

}  // namespace slim
