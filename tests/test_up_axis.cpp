// The up axis of `slimrt render`: glTF is Y up by its specification, so by default its Y axis
// points up in the image and the sky's zenith (--shade diffuse) is +Y; --up overrides both.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <tinyexr.h>

namespace {

namespace fs = std::filesystem;

// A pole along +Y (two crossed 0.2 x 8 rectangles, 4 triangles) as a binary glTF.
std::string pole_glb() {
  const float r = 0.1f, h = 8.0f;
  const float p[12][3] = {{-r, 0, 0}, {r, 0, 0}, {r, h, 0}, {-r, 0, 0}, {r, h, 0}, {-r, h, 0},
                          {0, 0, -r}, {0, 0, r}, {0, h, r}, {0, 0, -r}, {0, h, r}, {0, h, -r}};
  std::string bin(reinterpret_cast<const char*>(p), sizeof p);  // 144 bytes
  std::string json = R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
    "nodes": [{"mesh": 0}], "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": 12, "type": "VEC3",
                   "min": [-0.1, 0, -0.1], "max": [0.1, 8, 0.1]}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 144}],
    "buffers": [{"byteLength": 144}]})";
  while (json.size() % 4) json += ' ';
  auto u32 = [](std::string& out, uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  std::string out;
  u32(out, 0x46546C67);  // "glTF"
  u32(out, 2);
  u32(out, uint32_t(12 + 8 + json.size() + 8 + bin.size()));
  u32(out, uint32_t(json.size()));
  u32(out, 0x4E4F534A);  // "JSON"
  out += json;
  u32(out, uint32_t(bin.size()));
  u32(out, 0x004E4942);  // "BIN"
  out += bin;
  return out;
}

struct Rendered {
  int w = 0, h = 0;
  std::vector<float> rgb;
  const float* at(int x, int y) const { return &rgb[(size_t(y) * w + x) * 3]; }
};

class UpAxis : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("slimrt_up_" + std::to_string(getpid()));
    fs::create_directories(dir_);
    glb_ = (dir_ / "pole.glb").string();
    std::ofstream(glb_, std::ios::binary) << pole_glb();
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Renders the pole at 48x48 with extra options; fails the test if the CLI fails.
  Rendered render(const std::string& args) {
    const std::string out = (dir_ / "out.exr").string();
    fs::remove(out);
    // SLIMRT_CLI: another slimrt binary to check (e.g. one without the fix these tests cover).
    const char* cli = std::getenv("SLIMRT_CLI");
    const std::string cmd = std::string(cli ? cli : SLIM_CLI_PATH) + " render " + glb_ + " -o " +
                            out + " --res 48x48 --quiet " + args + " >/dev/null 2>&1";
    const int rc = std::system(cmd.c_str());
    EXPECT_TRUE(WIFEXITED(rc) && WEXITSTATUS(rc) == 0) << cmd;
    Rendered r;
    float* rgba = nullptr;
    const char* err = nullptr;
    if (LoadEXR(&rgba, &r.w, &r.h, out.c_str(), &err) != TINYEXR_SUCCESS) {
      ADD_FAILURE() << cmd << ": " << (err ? err : "no image");
      if (err) FreeEXRErrorMessage(err);
      return r;
    }
    r.rgb.resize(size_t(r.w) * r.h * 3);
    for (int i = 0; i < r.w * r.h; ++i)
      for (int c = 0; c < 3; ++c) r.rgb[size_t(i) * 3 + c] = rgba[i * 4 + c];
    free(rgba);
    return r;
  }

  fs::path dir_;
  std::string glb_;
};

// Width and height in pixels of the pole (--shade normals: the background is 0.03 grey).
void pole_extent(const Rendered& r, int& w, int& h) {
  int xlo = r.w, xhi = -1, ylo = r.h, yhi = -1;
  for (int y = 0; y < r.h; ++y)
    for (int x = 0; x < r.w; ++x)
      if (std::abs(r.at(x, y)[0] - 0.03f) > 1e-3f || std::abs(r.at(x, y)[2] - 0.03f) > 1e-3f) {
        xlo = std::min(xlo, x), xhi = std::max(xhi, x);
        ylo = std::min(ylo, y), yhi = std::max(yhi, y);
      }
  w = xhi - xlo + 1;
  h = yhi - ylo + 1;
}

TEST_F(UpAxis, GltfIsYUpByDefaultAndUpOverrides) {
  int w = 0, h = 0;
  for (const char* args : {"", "--up y"}) {
    pole_extent(render(std::string("--shade normals ") + args), w, h);
    EXPECT_GT(h, 3 * w) << "'" << args << "': the Y pole should stand upright, " << w << "x" << h;
  }
  // Z up: the camera looks from (+x, -y, +z) and the pole runs across the image diagonally.
  pole_extent(render("--shade normals --up z"), w, h);
  EXPECT_LT(h, 2 * w) << "--up z: the pole should lie across the image, " << w << "x" << h;
}

// The sky is bluest at the zenith of the up axis (less red than at the horizon and below), so in
// a view from above the horizon the top rows are bluer than the bottom rows, whatever the axis.
// And the sky is symmetric about the up axis, the camera's right vector horizontal: mirrored
// columns of sky get the same colour. A sky with another zenith than the camera's up is lopsided.
TEST_F(UpAxis, DiffuseSkyFollowsTheUpAxis) {
  for (const char* up : {"", "--up y", "--up z", "--up x"}) {
    const Rendered r = render(std::string("--shade diffuse --bounces 0 ") + up);
    ASSERT_EQ(r.w, 48);
    // Mean red of the sky pixels (the pole is black with no bounce) in the top and bottom rows.
    auto mean_red = [&](int y0, int y1) {
      double sum = 0;
      int n = 0;
      for (int y = y0; y < y1; ++y)
        for (int x = 0; x < r.w; ++x)
          if (r.at(x, y)[2] > 0.0f) sum += r.at(x, y)[0], n++;
      return n ? sum / n : 0.0;
    };
    const double top = mean_red(0, 4), bottom = mean_red(r.h - 4, r.h);
    EXPECT_GT(bottom - top, 0.05) << "'" << up << "': top " << top << ", bottom " << bottom;
    float worst = 0.0f;
    int pairs = 0;
    for (int y = 0; y < r.h; ++y)
      for (int x = 0; x < r.w / 2; ++x) {
        const float *a = r.at(x, y), *b = r.at(r.w - 1 - x, y);
        if (a[2] <= 0.0f || b[2] <= 0.0f) continue;  // the pole on either side
        pairs++;
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(a[c] - b[c]));
      }
    EXPECT_GT(pairs, r.w * r.h / 4);
    EXPECT_LT(worst, 2e-3f) << "'" << up << "': mirrored sky columns differ";
  }
}

}  // namespace
