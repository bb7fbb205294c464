// `slimrt render SCENE -o OUT.png|OUT.exr [--shade diffuse|normals|kind] [--spp N] [--res WxH]
//                [--config NAME] [--threads N] [--bounces N]`
// Loads a mesh file or procedural scene, builds it in one configuration (BENCHMARK.md names),
// renders it from the benchmark camera and writes the image; prints build time, render time and
// MRays/s on stdout. A progress bar goes to stderr when stdout is a terminal.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cctype>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

#include "commands.h"
#include "slimrt/output.h"
#include "slimrt/slimrt.h"

namespace slim::cli {

namespace {

// "WxH" with both positive and at most 65536; false otherwise.
bool parse_resolution(const std::string& text, int& w, int& h) {
  size_t x = text.find_first_of("xX");
  if (x == std::string::npos || x == 0 || x + 1 >= text.size()) return false;
  auto parse_int = [](const std::string& s, int& out) {
    if (s.empty() || s.size() > 6) return false;
    out = 0;
    for (char c : s) {
      if (c < '0' || c > '9') return false;
      out = out * 10 + (c - '0');
    }
    return out > 0 && out <= 65536;
  };
  return parse_int(text.substr(0, x), w) && parse_int(text.substr(x + 1), h);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int cmd_render(int argc, char** argv) {
  CLI::App app{"Render a scene from the benchmark camera and write a PNG or EXR image.",
               "slimrt render"};
  std::string scene_name, output, shade = "diffuse", res = "1024x1024", config = "bvh8-tri4v";
  int spp = 1, threads = 0, bounces = 8;
  app.add_option("scene", scene_name,
                 "mesh file (.obj .ply .gltf .glb, optionally .xz) or terrain:N, torus:N, canyon:N")
      ->required();
  app.add_option("-o,--output", output, "output image, .png (8-bit sRGB) or .exr (float)")
      ->required()
      ->check(  // checked before the (possibly long) load, build and render
          [](const std::string& path) {
            std::string ext = path.size() >= 4 ? path.substr(path.size() - 4) : "";
            for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
            return ext == ".png" || ext == ".exr"
                       ? std::string()
                       : path + ": unknown image extension, expected .png or .exr";
          },
          "PATH.png|PATH.exr");
  app.add_option("--shade", shade, "diffuse (path tracing), normals or kind (primitive kind)")
      ->check(CLI::IsMember({"diffuse", "normals", "kind"}))
      ->capture_default_str();
  app.add_option("--spp", spp, "samples per pixel")
      ->check(CLI::Range(1, 1 << 16))
      ->capture_default_str();
  app.add_option("--res", res, "image resolution WxH")
      ->check(
          [](const std::string& s) {
            int w, h;
            return parse_resolution(s, w, h)
                       ? std::string()
                       : "expected WxH with W and H in [1, 65536], e.g. 1024x768, got '" + s + "'";
          },
          "WxH")
      ->capture_default_str();
  app.add_option("--config", config, "acceleration structure configuration (BENCHMARK.md)")
      ->capture_default_str();
  app.add_option("--threads", threads, "threads for build and render, 0 = all cores")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str();
  app.add_option("--bounces", bounces, "diffuse bounces after the primary hit")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }

  RenderOptions ropt;
  if (!parse_resolution(res, ropt.width, ropt.height)) return 2;  // already checked by CLI11
  // Before the load, build and render: a typo in -o or a huge --res must not cost that work.
  check_output_path(output);
  {
    // The float image (12 bytes per pixel), its 8-bit copy and the encoded file: about 24 bytes
    // per pixel at the peak of write_image.
    constexpr uint64_t kBytesPerPixel = 24;
    const uint64_t pixels = uint64_t(ropt.width) * uint64_t(ropt.height);
    const uint64_t budget = memory_budget();
    if (pixels * kBytesPerPixel > budget)
      throw Error("--res " + res + ": " + std::to_string(pixels) + " pixels need about " +
                  format_bytes(pixels * kBytesPerPixel) + " (" + std::to_string(kBytesPerPixel) +
                  " bytes per pixel); expected at most " + std::to_string(budget / kBytesPerPixel) +
                  " pixels, the memory limit being " + format_bytes(budget) +
                  " (half of this machine's memory)");
  }
  ropt.spp = spp;
  ropt.max_bounces = bounces;
  ropt.threads = threads;
  ropt.shade = shade == "normals" ? Shade::Normals : shade == "kind" ? Shade::Kind : Shade::Diffuse;
  ropt.progress = isatty(fileno(stdout)) != 0;

  BuildOptions bopt = BuildOptions::from_config(config);  // throws on an unknown name
  bopt.threads = threads;

  auto t0 = std::chrono::steady_clock::now();
  PolyMesh mesh = load(scene_name);
  double load_s = seconds_since(t0);

  t0 = std::chrono::steady_clock::now();
  Scene scene = out_of_memory_context("building " + scene_name + " as " + config,
                                      [&] { return Scene::build(mesh, bopt); });
  double build_s = seconds_since(t0);
  uint64_t faces = mesh.face_count(), triangles = mesh.fan_triangle_count();
  mesh = PolyMesh();  // the scene owns all it needs

  Camera cam = frame_box(scene.bounds(), ropt.width, ropt.height);
  t0 = std::chrono::steady_clock::now();
  RenderStats rstats;
  Image img = out_of_memory_context("rendering " + scene_name + " at " + res,
                                    [&] { return render(scene, cam, ropt, &rstats); });
  double render_s = seconds_since(t0);
  write_image(img, output);

  double mrays = render_s > 0 ? double(rstats.rays) / render_s * 1e-6 : 0.0;
  std::printf(
      "%s: %llu faces, %llu triangles | load %.3f s | build %.3f s (%s) | render %.3f s "
      "(%dx%d, %d spp, %s) | %.2f MRays/s%s | %s\n",
      scene_name.c_str(), (unsigned long long)faces, (unsigned long long)triangles, load_s, build_s,
      config.c_str(), render_s, ropt.width, ropt.height, ropt.spp, shade.c_str(), mrays,
      "", output.c_str());
  return 0;
}

}  // namespace slim::cli
