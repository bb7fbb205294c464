// Renderer (src/render/): benchmark camera, image writers, PSNR, rendering, `slimrt render`.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include "render/tiling.h"
#include "slimrt/mesh.h"
#include "slimrt/render.h"

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wunused-function"
#pragma GCC diagnostic ignored "-Wmissing-field-initializers"
#pragma GCC diagnostic ignored "-Wsign-compare"
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb/stb_image.h>
#pragma GCC diagnostic pop

#include <tinyexr.h>

namespace {

using slim::Box3f;
using slim::Camera;
using slim::Image;
using slim::Vec3f;
namespace fs = std::filesystem;

// A fresh directory per test process, removed at exit of the fixture.
class RenderFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("slimrt_render_test_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  fs::path dir_;
};

// Pixel coordinates of a world point through the camera, solving
// p - eye = s * (dir00 + du * px + dv * py) (du, dv orthogonal). False if behind the camera.
bool project(const Camera& c, Vec3f p, float& px, float& py) {
  Vec3f v = p - c.eye;
  Vec3f n = cross(c.du, c.dv);
  float s = dot(v, n) / dot(c.dir00, n);
  if (!(s > 0)) return false;
  Vec3f w = v * (1.0f / s) - c.dir00;
  px = dot(w, c.du) / dot(c.du, c.du);
  py = dot(w, c.dv) / dot(c.dv, c.dv);
  return true;
}

bool camera_finite(const Camera& c) {
  return is_finite(c.eye) && is_finite(c.dir00) && is_finite(c.du) && is_finite(c.dv);
}

Image gradient_image(int w, int h) {
  Image img;
  img.width = w;
  img.height = h;
  img.rgb.resize(size_t(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float* p = &img.rgb[(size_t(y) * w + x) * 3];
      p[0] = float(x) / float(w - 1);
      p[1] = float(y) / float(h - 1);
      p[2] = 0.25f;
    }
  return img;
}

// Reference sRGB encoding (double precision) of the PNG writer's contract.
int srgb8_reference(double v) {
  if (!(v > 0)) return 0;
  if (v >= 1) return 255;
  double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1 / 2.4) - 0.055;
  return int(std::floor(s * 255 + 0.5));
}

}  // namespace

// ---- camera ----

TEST(RenderCamera, FramesEveryBoxCorner) {
  const Box3f boxes[] = {
      {{0, 0, 0}, {1, 1, 1}},
      {{0, 0, -0.03f}, {1, 1, 0.03f}},                // terrain-like: flat
      {{-1.4f, -1.4f, -0.45f}, {1.4f, 1.4f, 0.45f}},  // torus-like
      {{-0.1f, -0.1f, 0}, {0.1f, 0.1f, 5}},           // tall and thin
      {{1000, 2000, 3000}, {1010, 2001, 3000.5f}},    // far from the origin
      {{-1e-3f, 5, 5}, {1e-3f, 5, 5}},                // a segment
  };
  const int sizes[][2] = {{64, 64}, {1024, 1024}, {200, 100}, {100, 300}, {1, 1}};
  for (const Box3f& b : boxes)
    for (const auto& wh : sizes) {
      Camera c = slim::frame_box(b, wh[0], wh[1]);
      ASSERT_TRUE(camera_finite(c));
      EXPECT_EQ(c.width, wh[0]);
      EXPECT_EQ(c.height, wh[1]);
      for (int k = 0; k < 8; ++k) {
        Vec3f p((k & 1) ? b.hi.x : b.lo.x, (k & 2) ? b.hi.y : b.lo.y, (k & 4) ? b.hi.z : b.lo.z);
        float px, py;
        ASSERT_TRUE(project(c, p, px, py));
        EXPECT_GE(px, 0.0f) << "corner " << k << " of box " << b.lo.x;
        EXPECT_LE(px, float(wh[0]));
        EXPECT_GE(py, 0.0f);
        EXPECT_LE(py, float(wh[1]));
      }
      // The box centre is in the middle of the image.
      float cx, cy;
      ASSERT_TRUE(project(c, b.center(), cx, cy));
      EXPECT_NEAR(cx, wh[0] * 0.5f, wh[0] * 0.01f + 1e-3f);
      EXPECT_NEAR(cy, wh[1] * 0.5f, wh[1] * 0.01f + 1e-3f);
    }
}

TEST(RenderCamera, FixedViewFromPlusXMinusYAbove) {
  Camera c = slim::frame_box({{0, 0, 0}, {1, 1, 1}}, 64, 64);
  Vec3f to_eye = normalize(c.eye - Vec3f(0.5f));
  EXPECT_GT(to_eye.x, 0.0f);
  EXPECT_LT(to_eye.y, 0.0f);
  EXPECT_NEAR(std::asin(to_eye.z) * 180 / M_PI, 35.0, 1.0);              // elevation
  EXPECT_NEAR(std::atan2(to_eye.x, -to_eye.y) * 180 / M_PI, 30.0, 1.0);  // azimuth from -y
  // z up: the top image row looks higher than the bottom one, the image is not mirrored.
  Vec3f top = normalize(c.dir00 + c.du * 32.0f),
        bottom = normalize(c.dir00 + c.du * 32.0f + c.dv * 64.0f);
  EXPECT_GT(top.z, bottom.z);
  EXPECT_LT(dot(cross(c.du, -c.dv), c.dir00), 0.0f);  // right x up = backwards: not mirrored
  // Vertical field of view 40 degrees.
  double fov = std::acos(dot(top, bottom)) * 180 / M_PI;
  EXPECT_NEAR(fov, 40.0, 0.5);
}

TEST(RenderCamera, DegenerateBoxesGiveFiniteRays) {
  const Box3f boxes[] = {
      Box3f(),                                            // empty
      {{1, 2, 3}, {1, 2, 3}},                             // a point
      {{0, 0, 0}, {0, 0, 0}},                             // the origin
      {{1e7f, 1e7f, 1e7f}, {1e7f, 1e7f, 1e7f}},           // a far point
      {{-slim::kInf, 0, 0}, {slim::kInf, 1, 1}},          // infinite
      {{-3e38f, -3e38f, -3e38f}, {3e38f, 3e38f, 3e38f}},  // size overflows float
      {{std::nanf(""), 0, 0}, {1, 1, 1}},
  };
  for (const Box3f& b : boxes) {
    Camera c = slim::frame_box(b, 16, 16);
    ASSERT_TRUE(camera_finite(c)) << b.lo.x << " " << b.hi.x;
    slim::Ray r = slim::camera_ray(c, 8.0f, 8.0f);
    EXPECT_TRUE(is_finite(r.org));
    EXPECT_TRUE(is_finite(r.dir));
    EXPECT_NEAR(length(r.dir), 1.0f, 1e-5f);
    EXPECT_FALSE(c.eye == b.center() && !b.empty()) << "eye on the point";
  }
  Camera c = slim::frame_box(Box3f(), 0, -5);  // bad sizes: clamped, not NaN
  EXPECT_TRUE(camera_finite(c));
}

// ---- images ----

TEST_F(RenderFiles, WritePngAndReadBack) {
  Image img = gradient_image(37, 21);
  // Out-of-range and non-finite values are clamped.
  img.rgb[0] = -1.0f;
  img.rgb[1] = 7.0f;
  img.rgb[2] = std::numeric_limits<float>::quiet_NaN();
  img.rgb[3] = slim::kInf;
  std::string file = path("out.png");
  slim::write_image(img, file);
  int w = 0, h = 0, comp = 0;
  unsigned char* data = stbi_load(file.c_str(), &w, &h, &comp, 3);
  ASSERT_NE(data, nullptr) << stbi_failure_reason();
  EXPECT_EQ(w, 37);
  EXPECT_EQ(h, 21);
  EXPECT_EQ(comp, 3);
  for (size_t i = 0; i < img.rgb.size(); ++i)
    ASSERT_EQ(int(data[i]), srgb8_reference(img.rgb[i])) << i;
  EXPECT_EQ(data[0], 0);
  EXPECT_EQ(data[1], 255);
  EXPECT_EQ(data[2], 0);
  EXPECT_EQ(data[3], 255);
  stbi_image_free(data);
  // Upper-case extension works too.
  slim::write_image(img, path("OUT.PNG"));
  std::ifstream in(path("OUT.PNG"), std::ios::binary);
  char sig[8] = {};
  in.read(sig, 8);
  EXPECT_EQ(std::string(sig, 8), std::string("\x89PNG\r\n\x1a\n", 8));
}

TEST_F(RenderFiles, WriteExrAndReadBack) {
  Image img = gradient_image(19, 11);
  img.rgb[5] = 12.5f;  // HDR values are kept
  std::string file = path("out.exr");
  slim::write_image(img, file);
  float* rgba = nullptr;
  int w = 0, h = 0;
  const char* err = nullptr;
  ASSERT_EQ(LoadEXR(&rgba, &w, &h, file.c_str(), &err), TINYEXR_SUCCESS) << (err ? err : "");
  ASSERT_EQ(w, 19);
  ASSERT_EQ(h, 11);
  for (int i = 0; i < w * h; ++i)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(rgba[i * 4 + c], img.rgb[size_t(i) * 3 + c]) << i;
  free(rgba);
}

TEST_F(RenderFiles, WriteErrors) {
  Image img = gradient_image(4, 4);
  for (const char* name : {"out.jpg", "out", "out.png.bak", "dir.png/out"}) {
    try {
      slim::write_image(img, path(name));
      ADD_FAILURE() << name << " should throw";
    } catch (const slim::Error& e) {
      EXPECT_NE(std::string(e.what()).find("unknown image extension, expected .png or .exr"),
                std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find(path(name)), std::string::npos);
    }
  }
  EXPECT_THROW(slim::write_image(img, path("no/such/dir/out.png")), slim::Error);
  EXPECT_THROW(slim::write_image(img, path("no/such/dir/out.exr")), slim::Error);
  Image empty;
  EXPECT_THROW(slim::write_image(empty, path("empty.png")), slim::Error);
  Image bad = img;
  bad.rgb.pop_back();
  EXPECT_THROW(slim::write_image(bad, path("bad.png")), slim::Error);
}

// ---- PSNR ----

TEST(RenderPsnr, IdenticalNoisyAndMismatched) {
  Image a = gradient_image(64, 48);
  EXPECT_TRUE(std::isinf(slim::psnr(a, a)));
  EXPECT_GT(slim::psnr(a, a), 0);
  // Differences below half an 8-bit step vanish, as in the PNG.
  Image tiny = a;
  tiny.rgb[7] += 1e-6f;
  EXPECT_TRUE(std::isinf(slim::psnr(a, tiny)));

  auto noisy = [&](float amp) {
    Image b = a;
    slim::Rng rng(42);
    for (float& v : b.rgb) v = std::min(1.0f, std::max(0.0f, v + amp * (rng.uniform() - 0.5f)));
    return b;
  };
  double p1 = slim::psnr(a, noisy(0.01f)), p2 = slim::psnr(a, noisy(0.05f));
  EXPECT_TRUE(std::isfinite(p1));
  EXPECT_GT(p1, 30.0);
  EXPECT_GT(p1, p2);
  EXPECT_DOUBLE_EQ(slim::psnr(a, noisy(0.05f)), slim::psnr(noisy(0.05f), a));

  // Black vs white: MSE = 255^2, PSNR = 0 dB.
  Image black = a, white = a;
  std::fill(black.rgb.begin(), black.rgb.end(), 0.0f);
  std::fill(white.rgb.begin(), white.rgb.end(), 1.0f);
  EXPECT_NEAR(slim::psnr(black, white), 0.0, 1e-12);

  EXPECT_THROW(slim::psnr(a, gradient_image(48, 64)), slim::Error);
  EXPECT_THROW(slim::psnr(a, gradient_image(64, 47)), slim::Error);
  Image broken = a;
  broken.rgb.resize(10);
  EXPECT_THROW(slim::psnr(a, broken), slim::Error);
}

// ---- rendering (needs slim::Scene) ----

namespace {

size_t count_not(const Image& img, Vec3f bg) {
  size_t n = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3)
    if (Vec3f(img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]) != bg) ++n;
  return n;
}
}  // namespace

TEST(RenderScene, TerrainNormalsKindDiffuse) {
  slim::PolyMesh mesh = slim::make_terrain(64);
  const slim::Scene scene = slim::Scene::build(mesh, slim::BuildOptions::from_config("bvh8-tri4v"));
  slim::RenderOptions opt;
  opt.width = opt.height = 64;
  opt.shade = slim::Shade::Normals;
  Camera cam = slim::frame_box(scene.bounds(), 64, 64);
  Image img = slim::render(scene, cam, opt);
  ASSERT_EQ(img.width, 64);
  ASSERT_EQ(img.height, 64);
  ASSERT_EQ(img.rgb.size(), 64u * 64 * 3);
  size_t hits = count_not(img, Vec3f(0.03f));
  EXPECT_GT(hits, 64u * 64 / 5) << "the terrain should cover a good part of the image";
  EXPECT_LT(hits, 64u * 64) << "the framing leaves a margin";
  // A heightfield seen from above: the blue channel (0.5 + 0.5 n.z) is on one side of 0.5
  // everywhere (which side depends on the Ng convention of the scene, not on the renderer).
  size_t up = 0;
  for (size_t i = 0; i < img.rgb.size(); i += 3)
    if (Vec3f(img.rgb[i], img.rgb[i + 1], img.rgb[i + 2]) != Vec3f(0.03f) && img.rgb[i + 2] > 0.5f)
      ++up;
  EXPECT_TRUE(up == 0 || up == hits) << up << " of " << hits << " pixels face up";

  // Deterministic: the thread count does not change a single bit.
  slim::RenderOptions one = opt;
  one.threads = 1;
  Image img1 = slim::render(scene, cam, one);
  EXPECT_EQ(img.rgb, img1.rgb);

  opt.shade = slim::Shade::Kind;
  Image kind = slim::render(scene, cam, opt);
  EXPECT_EQ(count_not(kind, Vec3f(0.0f)), hits);

  opt.shade = slim::Shade::Diffuse;
  opt.spp = 2;
  opt.max_bounces = 2;
  Image diffuse = slim::render(scene, cam, opt);
  for (float v : diffuse.rgb) {
    ASSERT_TRUE(std::isfinite(v));
    ASSERT_GE(v, 0.0f);
  }
  Image diffuse1 = slim::render(scene, cam, [&] {
    auto o = opt;
    o.threads = 1;
    return o;
  }());
  EXPECT_TRUE(std::isinf(slim::psnr(diffuse, diffuse1)));

  // The options set the resolution; the camera's view is kept (rescaled pixel steps).
  opt.shade = slim::Shade::Normals;
  opt.spp = 1;
  opt.width = opt.height = 32;
  Image small = slim::render(scene, cam, opt);
  EXPECT_EQ(small.width, 32);
  size_t small_hits = count_not(small, Vec3f(0.03f));
  EXPECT_NEAR(double(small_hits) * 4, double(hits), double(hits) * 0.1);
}

// render_region: every rectangle of an image, in every shading, holds render()'s pixels bit for
// bit (what `slimrt render` under mpirun relies on), also when the camera is rescaled to the
// options' resolution; a rectangle outside the image is an error.
TEST(RenderScene, RegionsEqualTheWholeImage) {
  slim::PolyMesh mesh = slim::make_terrain(40);
  const slim::Scene scene = slim::Scene::build(mesh, slim::BuildOptions::from_config("bvh8-tri4v"));
  const Camera cam = slim::frame_box(scene.bounds(), 60, 50);
  for (slim::Shade shade :
       {slim::Shade::Diffuse, slim::Shade::Sun, slim::Shade::Normals, slim::Shade::Kind}) {
    slim::RenderOptions opt;
    opt.width = 77;  // not the camera's 60x50, and no multiple of the 32-pixel tiles
    opt.height = 45;
    opt.shade = shade;
    opt.spp = 3;
    opt.max_bounces = 2;
    slim::RenderStats whole_stats;
    const Image whole = slim::render(scene, cam, opt, &whole_stats);
    // A 40-pixel grid of rectangles covers the image; their rays add up to the whole image's.
    uint64_t rays = 0;
    size_t differing = 0;
    for (int y0 = 0; y0 < opt.height; y0 += 40) {
      for (int x0 = 0; x0 < opt.width; x0 += 40) {
        const int x1 = std::min(x0 + 40, opt.width), y1 = std::min(y0 + 40, opt.height);
        std::vector<float> px(size_t(x1 - x0) * size_t(y1 - y0) * 3, -1.0f);
        slim::RenderStats st;
        slim::render_region(scene, cam, opt, x0, y0, x1, y1, px.data(), &st);
        rays += st.rays;
        for (int y = y0; y < y1; ++y)
          for (int x = x0; x < x1; ++x)
            for (int c = 0; c < 3; ++c) {
              float a = whole.rgb[(size_t(y) * size_t(opt.width) + size_t(x)) * 3 + size_t(c)];
              float b = px[(size_t(y - y0) * size_t(x1 - x0) + size_t(x - x0)) * 3 + size_t(c)];
              if (std::memcmp(&a, &b, sizeof a) != 0) ++differing;
            }
      }
    }
    EXPECT_EQ(differing, 0u) << "shade " << int(shade);
    EXPECT_EQ(rays, whole_stats.rays) << "shade " << int(shade);
  }
  std::vector<float> px(64 * 3);
  slim::RenderOptions opt;
  opt.width = 8;
  opt.height = 8;
  EXPECT_THROW(slim::render_region(scene, cam, opt, 0, 0, 9, 1, px.data()), slim::Error);
  EXPECT_THROW(slim::render_region(scene, cam, opt, -1, 0, 1, 1, px.data()), slim::Error);
  EXPECT_THROW(slim::render_region(scene, cam, opt, 2, 0, 2, 1, px.data()), slim::Error);
}

// The tiling of a rectangle across threads: an image keeps its 32-pixel tiles; a 64x64 tile of
// `slimrt render` under mpirun is cut into at least 4 pieces per thread (down to 4-pixel pieces),
// so that a rank uses all its threads on it (32-pixel pieces would give 4, whatever the threads).
TEST(RenderScene, SmallRegionsAreCutForEveryThread) {
  namespace rt = slim::render_tiling;
  for (int threads : {1, 2, 4, 8, 16, 64, 256}) {
    SCOPED_TRACE(threads);
    EXPECT_EQ(rt::tile_size(1024, 1024, threads), 32);
    const int t = rt::tile_size(64, 64, threads);
    EXPECT_GE(t, 4);
    EXPECT_GE(rt::tile_count(64, 64, t), std::min<int64_t>(4 * threads, 256));
    // The largest tile that gives enough pieces (no needless cut).
    if (t < 32) {
      EXPECT_LT(rt::tile_count(64, 64, 2 * t), 4 * threads);
    }
  }
  EXPECT_EQ(rt::tile_size(64, 64, 2), 16);
  EXPECT_EQ(rt::tile_size(1, 1, 64), 4);  // one pixel: one piece
}

// ---- the CLI ----

namespace {
int run_cli(const std::string& args) {
  std::string cmd = std::string(SLIM_CLI_PATH) + " " + args + " >/dev/null 2>&1";
  int rc = std::system(cmd.c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}
}  // namespace

TEST_F(RenderFiles, CliRejectsBadArguments) {
  std::string out = " -o " + path("x.png");
  EXPECT_NE(run_cli("render"), 0);                                // no scene, no output
  EXPECT_NE(run_cli("render terrain:8"), 0);                      // no output
  EXPECT_NE(run_cli("render terrain:8" + out + " --res 10"), 0);  // bad resolution
  EXPECT_NE(run_cli("render terrain:8" + out + " --res 0x10"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --res axb"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --shade pink"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --spp 0"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --spp many"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --threads -1"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --bogus"), 0);
  EXPECT_NE(run_cli("render terrain:8" + out + " --config no-such-config"), 0);
  EXPECT_EQ(run_cli("render --help"), 0);
  EXPECT_FALSE(fs::exists(path("x.png")));
}

TEST_F(RenderFiles, CliRendersPng) {
  std::string file = path("terrain.png");
  ASSERT_EQ(run_cli("render terrain:16 -o " + file + " --shade normals --res 40x30 --threads 1"),
            0);
  int w = 0, h = 0, comp = 0;
  unsigned char* data = stbi_load(file.c_str(), &w, &h, &comp, 3);
  ASSERT_NE(data, nullptr);
  EXPECT_EQ(w, 40);
  EXPECT_EQ(h, 30);
  stbi_image_free(data);
  EXPECT_NE(run_cli("render terrain:16 -o " + path("t.jpg") + " --res 8x8"), 0);
}
