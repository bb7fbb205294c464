// `slimrt render SCENE -o OUT.png|OUT.exr [--shade diffuse|sun|normals|kind] [--spp N] [--res WxH]
//                [--config NAME] [--bounces N] [--up x|y|z] [--eye X,Y,Z]
//                [--look-at X,Y,Z] [--fov DEG] [--mpi-tile N] [--mpi-root render|coordinate]
//                [--quiet] [build options: --threads N, --collapse ..., build_flags.h]`
// Loads a mesh file or procedural scene, builds it in one configuration (registry names),
// renders it from the user's camera (slim::view_camera: by default the model's corners fill the
// image, seen from the front-right and above; glTF is Y up by its specification, other inputs Z
// up) and writes the image; prints build time, render time and MRays/s on stdout. Loading,
// building and rendering that take over ~2 s show progress on stderr when it is a terminal,
// unless --quiet. Under `mpirun -np K` the K processes render one image (mpi_render.h): rank 0
// alone shows progress, writes the image and prints.
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "build_flags.h"
#include "commands.h"
#include "discarded.h"
#include "mpi_render.h"
#include "progress.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"

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

// "X,Y,Z" as three finite floats; false otherwise.
bool parse_point(const std::string& text, Vec3f& out) {
  float v[3];
  size_t pos = 0;
  for (int i = 0; i < 3; ++i) {
    size_t end = text.find(',', pos);
    if ((i < 2) != (end != std::string::npos)) return false;
    std::string part = text.substr(pos, i < 2 ? end - pos : std::string::npos);
    try {
      size_t used = 0;
      v[i] = std::stof(part, &used);
      if (used != part.size() || !std::isfinite(v[i])) return false;
    } catch (const std::exception&) {
      return false;
    }
    pos = end + 1;
  }
  out = {v[0], v[1], v[2]};
  return true;
}

// The up axis a scene is authored with when the user names none: glTF (.gltf, .glb, also .xz)
// is Y up by its specification; OBJ, PLY and the procedural scenes are taken as Z up.
Axis default_up(const std::string& scene) {
  std::string s = scene;
  for (char& c : s) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (s.size() > 3 && s.compare(s.size() - 3, 3, ".xz") == 0) s.resize(s.size() - 3);
  auto ends = [&](const char* e) {
    size_t n = std::strlen(e);
    return s.size() >= n && s.compare(s.size() - n, n, e) == 0;
  };
  return ends(".gltf") || ends(".glb") ? Axis::Y : Axis::Z;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int render_command(int argc, char** argv, const RenderRanks& ranks) {
  CLI::App app{"Render a scene and write a PNG or EXR image.", "slimrt render"};
  std::string scene_name, output, shade = "diffuse", res = "1024x1024", config = "bvh8-tri4v";
  std::string up, eye, look_at, mpi_root = "render";
  float fov = 40.0f;
  bool quiet = false;
  int spp = 1, bounces = 8, mpi_tile = 64;
  BuildOptions tuning;
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
  app.add_option("--shade", shade,
                 "diffuse (path tracing under the sky), sun (a low sun with shadows: shows "
                 "relief), normals or kind (primitive kind)")
      ->check(CLI::IsMember({"diffuse", "sun", "normals", "kind"}))
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
  app.add_option("--config", config,
                 "the format (bvh8-tri4v, clbvh-compact, lossy-grid, ...; see the README)")
      ->capture_default_str();
  add_build_options(app, tuning);  // --threads: build and render
  app.add_option("--bounces", bounces, "diffuse bounces after the primary hit")
      ->check(CLI::Range(0, 1024))
      ->capture_default_str();
  auto point_check = [](const std::string& s) {
    Vec3f p;
    return parse_point(s, p) ? std::string()
                             : "expected three finite numbers X,Y,Z, e.g. 0,-5,2, got '" + s + "'";
  };
  app.add_option("--up", up, "the scene's up axis (default: y for glTF, z otherwise)")
      ->check(CLI::IsMember({"x", "y", "z"}));
  app.add_option("--eye", eye,
                 "camera position X,Y,Z (default: backed off until the model fills "
                 "the image)")
      ->check(point_check, "X,Y,Z");
  app.add_option("--look-at", look_at,
                 "point the camera looks at X,Y,Z (default: the model's "
                 "centre)")
      ->check(point_check, "X,Y,Z");
  app.add_option("--fov", fov, "vertical field of view, degrees")
      ->check(CLI::Range(0.01f, 179.0f))
      ->capture_default_str();
  app.add_option("--mpi-tile", mpi_tile,
                 "under mpirun: edge in pixels of the square tiles rank 0 hands out")
      ->check(CLI::Range(1, 65536))
      ->capture_default_str();
  app.add_option("--mpi-root", mpi_root,
                 "under mpirun: rank 0 renders tiles too (render) or only hands them out and "
                 "gathers them (coordinate)")
      ->check(CLI::IsMember({"render", "coordinate"}))
      ->capture_default_str();
  app.add_flag("-q,--quiet", quiet, "no progress on stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Every rank parses the same arguments: rank 0 alone says what is wrong.
    return ranks.is_root() ? app.exit(e) : e.get_exit_code();
  }

  RenderOptions ropt;
  if (!parse_resolution(res, ropt.width, ropt.height)) return 2;  // already checked by CLI11
  // Before the load, build and render: a typo in -o or a huge --res must not cost that work.
  if (ranks.is_root()) check_output_path(output);
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
  ropt.threads = tuning.threads;
  ropt.shade = shade == "normals" ? Shade::Normals
               : shade == "kind"  ? Shade::Kind
               : shade == "sun"   ? Shade::Sun
                                  : Shade::Diffuse;
  // Under mpirun stderr is a pipe to mpirun whatever the user's terminal: rank 0 shows progress
  // there unless --quiet.
  const bool show_progress =
      !quiet && ranks.is_root() && (ranks.distributed() || isatty(fileno(stderr)) != 0);
  ropt.progress = show_progress;
  ViewOptions view;
  view.up = up.empty()  ? default_up(scene_name)
            : up == "x" ? Axis::X
            : up == "y" ? Axis::Y
                        : Axis::Z;
  view.fov_deg = fov;
  ropt.up = view.up == Axis::X   ? Vec3f(1, 0, 0)
            : view.up == Axis::Y ? Vec3f(0, 1, 0)
                                 : Vec3f(0, 0, 1);
  view.has_eye = !eye.empty() && parse_point(eye, view.eye);
  view.has_look_at = !look_at.empty() && parse_point(look_at, view.look_at);

  BuildOptions bopt = build_options(config, tuning);  // throws on an unknown name

  auto t0 = std::chrono::steady_clock::now();
  PolyMesh mesh;
  Scene scene;
  double load_s = 0, build_s = 0;
  uint64_t faces = 0, triangles = 0;
  if (is_scene_file(scene_name)) {
    // A scene file: opened (mapped), not built; load_s is the open time.
    scene = open_scene_file(scene_name, &load_s);
    config = scene.options().config_name();
    faces = scene.stats().input_faces;
    triangles = scene.stats().triangles;
  } else {
    {
      StepProgress p(show_progress, "load " + scene_name);
      mesh = load(scene_name);
    }
    load_s = seconds_since(t0);

    t0 = std::chrono::steady_clock::now();
    faces = mesh.face_count(), triangles = mesh.fan_triangle_count();
    {
      BuildMeter meter(show_progress, config, triangles);
      bopt.progress = meter.callback();
      scene = out_of_memory_context("building " + scene_name + " as " + config,
                                    [&] { return Scene::build(mesh, bopt); });
    }
    build_s = seconds_since(t0);
    mesh = PolyMesh();  // the scene owns all it needs
  }

  Camera cam = view_camera(scene.bounds(), view, ropt.width, ropt.height);
  ranks.check_same_scene(scene, scene_name);
  t0 = std::chrono::steady_clock::now();
  RenderStats rstats;
  std::vector<int> rank_tiles;
  Image img = out_of_memory_context("rendering " + scene_name + " at " + res, [&] {
    return ranks.render(scene, cam, ropt, mpi_tile, mpi_root == "render", show_progress, &rstats,
                        &rank_tiles);
  });
  double render_s = seconds_since(t0);
  if (!ranks.is_root()) return 0;
  write_image(img, output);

  double mrays = render_s > 0 ? double(rstats.rays) / render_s * 1e-6 : 0.0;
  std::string processes;  // " (K processes, tiles a + b + ...)": the tiles each rank rendered
  if (ranks.distributed()) {
    processes = " (" + std::to_string(ranks.size()) + " processes, tiles ";
    for (size_t r = 0; r < rank_tiles.size(); ++r)
      processes += (r ? " + " : "") + std::to_string(rank_tiles[r]);
    processes += ")";
  }
  std::printf(
      "%s: %llu faces, %llu triangles%s | load %.3f s | build %.3f s (%s) | render %.3f s "
      "(%dx%d, %d spp, %s) | %.2f MRays/s%s | %s\n",
      scene_name.c_str(), (unsigned long long)faces, (unsigned long long)triangles,
      discarded_note(scene).c_str(), load_s, build_s, config.c_str(), render_s, ropt.width,
      ropt.height, ropt.spp, shade.c_str(), mrays, processes.c_str(), output.c_str());
  return 0;
}

}  // namespace

int cmd_render(int argc, char** argv) {
  RenderRanks ranks;
  if (ranks.idle()) return 0;
  return ranks.guard([&] { return render_command(argc, argv, ranks); });
}

}  // namespace slim::cli
