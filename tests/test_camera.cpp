// The user's camera (slim::view_camera, `slimrt render`): framing, up axes, eye and look-at, and
// the whole supported coordinate range (meshes near +-1e12 and far from the origin are found in
// the image, with nonzero normals).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "slimrt/analysis.h"

namespace {

using slim::Axis;
using slim::Box3f;
using slim::Camera;
using slim::Vec3f;
using slim::ViewOptions;

// A closed box mesh (12 triangles) from lo to hi.
slim::PolyMesh box_mesh(Vec3f lo, Vec3f hi) {
  slim::PolyMesh m;
  m.name = "box";
  for (int i = 0; i < 8; ++i)
    m.positions.push_back({i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z});
  const uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.face_sizes.push_back(4);
    for (uint32_t k : q) m.face_indices.push_back(k);
  }
  return m;
}

struct Coverage {
  int hits = 0, zero_normals = 0;
  int xlo = 1 << 30, xhi = -1, ylo = 1 << 30, yhi = -1;  // hit pixels' extent
};

Coverage trace(const slim::Scene& scene, const Camera& cam) {
  Coverage c;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      slim::Hit h = scene.intersect(slim::camera_ray(cam, x + 0.5f, y + 0.5f));
      if (!h.valid()) continue;
      c.hits++;
      Vec3f n = slim::safe_normalize(h.Ng);
      if (n.x == 0 && n.y == 0 && n.z == 0) c.zero_normals++;
      c.xlo = std::min(c.xlo, x), c.xhi = std::max(c.xhi, x);
      c.ylo = std::min(c.ylo, y), c.yhi = std::max(c.yhi, y);
    }
  return c;
}

TEST(Camera, DefaultViewFillsTheImage) {
  // A long thin model: the bounding-sphere framing leaves most of the image empty, the corner
  // framing spans the image's width (3% margin) and centres it.
  slim::Scene scene = slim::Scene::build(box_mesh({-10, -1, -1}, {10, 1, 1}));
  for (Axis up : {Axis::X, Axis::Y, Axis::Z}) {
    ViewOptions v;
    v.up = up;
    Camera cam = slim::view_camera(scene.bounds(), v, 64, 48);
    Coverage c = trace(scene, cam);
    ASSERT_GT(c.hits, 0);
    int w = c.xhi - c.xlo + 1, h = c.yhi - c.ylo + 1;
    EXPECT_TRUE(w >= 58 || h >= 43) << "up " << int(up) << ": " << w << "x" << h;
    EXPECT_LE(std::abs((c.xlo + c.xhi) / 2 - 32), 3) << int(up);
    EXPECT_LE(std::abs((c.ylo + c.yhi) / 2 - 24), 3) << int(up);
  }
}

TEST(Camera, UpAxisPointsUpInTheImage) {
  // A tall box: with the right up axis it is taller than wide in the image.
  for (Axis up : {Axis::X, Axis::Y, Axis::Z}) {
    Vec3f hi(1, 1, 1);
    (&hi.x)[int(up)] = 8;
    slim::Scene scene = slim::Scene::build(box_mesh({0, 0, 0}, hi));
    ViewOptions v;
    v.up = up;
    Coverage c = trace(scene, slim::view_camera(scene.bounds(), v, 64, 64));
    ASSERT_GT(c.hits, 0);
    EXPECT_GT(c.yhi - c.ylo, 2 * (c.xhi - c.xlo)) << "up " << int(up);
  }
}

TEST(Camera, EyeLookAtAndFov) {
  slim::Scene scene = slim::Scene::build(box_mesh({-1, -1, -1}, {1, 1, 1}));
  ViewOptions v;
  v.up = Axis::Y;
  v.has_eye = true;
  v.eye = {0, 0, 10};
  v.has_look_at = true;
  v.look_at = {0, 0, 0};
  v.fov_deg = 30;
  Camera cam = slim::view_camera(scene.bounds(), v, 101, 101);
  EXPECT_EQ(cam.eye.x, 0.0f);
  EXPECT_EQ(cam.eye.z, 10.0f);
  // The centre pixel looks straight at the look-at point: it hits the +z face at t = 9.
  slim::Hit h = scene.intersect(slim::camera_ray(cam, 50.5f, 50.5f));
  ASSERT_TRUE(h.valid());
  EXPECT_NEAR(h.t, 9.0f, 1e-4f);
  // The face spans +-atan(1/9) of the 30 degree field: 2*tan(6.34)/ (2*tan(15)) = 41.5% of 101.
  Coverage c = trace(scene, cam);
  EXPECT_NEAR(c.xhi - c.xlo + 1, 42, 2);
  // Looking at a point off the centre moves the box to the other side of the image.
  v.look_at = {2, 0, 0};
  c = trace(scene, slim::view_camera(scene.bounds(), v, 101, 101));
  EXPECT_LT(c.xhi, 50);
  // Errors name what was expected.
  v.fov_deg = 0;
  EXPECT_THROW(slim::view_camera(scene.bounds(), v, 8, 8), slim::Error);
  v.fov_deg = 40;
  v.look_at = v.eye;
  EXPECT_THROW(slim::view_camera(scene.bounds(), v, 8, 8), slim::Error);
  v.look_at = {0, -5, 10};  // straight down the Y (up) axis
  EXPECT_THROW(slim::view_camera(scene.bounds(), v, 8, 8), slim::Error);
}

// Meshes anywhere in the supported range are found in the image, and their
// normals are not zero.
TEST(Camera, WholeCoordinateRange) {
  struct Case {
    Vec3f lo, hi;
    const char* what;
  };
  const float big = 9e11f;
  const Case cases[] = {
      {{-big, -big, -big}, {big, big, big}, "spanning +-9e11"},
      {{big - 1e10f, big - 1e10f, big - 1e10f}, {big, big, big}, "at +9e11"},
      {{-big, -big, -big}, {-big + 1e10f, -big + 1e10f, -big + 1e10f}, "at -9e11"},
      {{4e6f - 1e3f, 4e6f - 1e3f, 4e6f - 1e3f},
       {4e6f + 1e3f, 4e6f + 1e3f, 4e6f + 1e3f},
       "at 4e6, radius 1e3"},
      {{4e6f, 4e6f, 4e6f}, {4e6f + 4, 4e6f + 4, 4e6f + 4}, "at 4e6, size 4"},
  };
  for (const Case& k : cases) {
    slim::Scene scene = slim::Scene::build(box_mesh(k.lo, k.hi));
    for (Axis up : {Axis::Y, Axis::Z}) {
      ViewOptions v;
      v.up = up;
      Camera cam = slim::view_camera(scene.bounds(), v, 32, 32);
      Coverage c = trace(scene, cam);
      EXPECT_GT(c.hits, 32 * 32 / 5) << k.what;
      EXPECT_EQ(c.zero_normals, 0) << k.what;
      // The rendered image (normals shading) has no pixel of the zero-normal grey.
      slim::RenderOptions ro;
      ro.width = ro.height = 32;
      ro.shade = slim::Shade::Normals;
      slim::Image img = slim::render(scene, cam, ro);
      int grey = 0, lit = 0;
      for (size_t i = 0; i < img.rgb.size(); i += 3) {
        grey += img.rgb[i] == 0.5f && img.rgb[i + 1] == 0.5f && img.rgb[i + 2] == 0.5f;
        lit += img.rgb[i] > 0.1f || img.rgb[i + 1] > 0.1f || img.rgb[i + 2] > 0.1f;
      }
      EXPECT_EQ(grey, 0) << k.what;
      EXPECT_EQ(lit, c.hits) << k.what;
    }
  }
}

TEST(Camera, SafeNormalizeLargeVectors) {
  Vec3f n = slim::safe_normalize({3e30f, 0, 4e30f});
  EXPECT_NEAR(n.x, 0.6f, 1e-6f);
  EXPECT_NEAR(n.z, 0.8f, 1e-6f);
  n = slim::safe_normalize({0, 0, 0});
  EXPECT_EQ(n.x, 0.0f);
  n = slim::safe_normalize({1e-30f, 0, 0});
  EXPECT_NEAR(n.x, 1.0f, 1e-6f);
}

// The CLI's camera options: values it refuses (exit code 2 for options, 1 for a camera that
// cannot be set up) and a render that uses them all.
TEST(Camera, CliOptions) {
  namespace fs = std::filesystem;
  const fs::path out =
      fs::temp_directory_path() / ("slimrt_camera_" + std::to_string(getpid()) + ".png");
  auto run = [&](const std::string& args) {
    std::string cmd = std::string(SLIM_CLI_PATH) + " render terrain:8 -o " + out.string() +
                      " --res 16x16 --quiet " + args + " >/dev/null 2>&1";
    int rc = std::system(cmd.c_str());
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  };
  EXPECT_NE(run("--up w"), 0);
  EXPECT_NE(run("--eye 1,2"), 0);
  EXPECT_NE(run("--eye 1,2,nan"), 0);
  EXPECT_NE(run("--look-at 1,,2"), 0);
  EXPECT_NE(run("--fov 0"), 0);
  EXPECT_NE(run("--fov 180"), 0);
  EXPECT_EQ(run("--up y --eye 0.5,5,0.5 --look-at 0.5,0,0.5"), 1);  // looking along the up axis
  fs::remove(out);
  EXPECT_EQ(run("--up y --eye 2,3,4 --look-at 0,0,0 --fov 30 --shade sun"), 0);
  EXPECT_TRUE(fs::exists(out));
  fs::remove(out);
}

}  // namespace
