// `slimrt bench` driver: see bench_runner.h and ../shared/BENCHMARK.md.
#include "bench_runner.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <memory>
#include <sstream>
#include <utility>

#include "embree_scene.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"

namespace slim::bench {

namespace {

constexpr int kTile = 32;  // pixels per tile side: the unit of parallel work
constexpr double kLosslessAgreement = 0.999;
constexpr int kW2CountStride = 4;  // workload-2 counting: pixels with x, y multiples of 4

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0.0 : (n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]));
}

// The rays of one scene, shared by every configuration.
struct Workload {
  Camera cam;
  float offset = 0;  // secondary ray origin offset (ray_offset_scale of the input bounds)
  int width = 0, height = 0, max_bounces = 8;
  int tiles_x = 0, tiles_y = 0;
  int tiles() const { return tiles_x * tiles_y; }
  template <class F>
  void for_tile(int tile, F&& f) const {  // f(x, y) for each pixel of the tile
    const int x0 = (tile % tiles_x) * kTile, y0 = (tile / tiles_x) * kTile;
    const int x1 = std::min(x0 + kTile, width), y1 = std::min(y0 + kTile, height);
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) f(x, y);
  }
  Ray primary(int x, int y) const { return camera_ray(cam, float(x) + 0.5f, float(y) + 0.5f); }
};

struct RunResult {
  double seconds = 0;
  uint64_t rays = 0;
  double checksum = 0;
};

// Runs body(tile, rays, checksum) over every tile in the arena, FTZ/DAZ set in every task; the
// per-tile sums are added in tile order, so the checksum does not depend on the schedule.
template <class Body>
RunResult run_tiles(tbb::task_arena& arena, const Workload& w, Body&& body) {
  std::vector<uint64_t> rays(size_t(w.tiles()), 0);
  std::vector<double> sums(size_t(w.tiles()), 0.0);
  const auto t0 = Clock::now();
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, w.tiles()), [&](const tbb::blocked_range<int>& r) {
      DenormalsAreZero ftz;
      for (int tile = r.begin(); tile != r.end(); ++tile) {
        uint64_t n = 0;
        double s = 0;
        body(tile, n, s);
        rays[size_t(tile)] = n;
        sums[size_t(tile)] = s;
      }
    });
  });
  RunResult res;
  res.seconds = seconds_since(t0);
  for (size_t i = 0; i < rays.size(); ++i) {
    res.rays += rays[i];
    res.checksum += sums[i];
  }
  return res;
}

// Workload 1: one primary ray per pixel centre; the checksum adds every hit distance.
template <class Tracer>
RunResult run_primary(const Tracer& tracer, tbb::task_arena& arena, const Workload& w) {
  return run_tiles(arena, w, [&](int tile, uint64_t& rays, double& sum) {
    w.for_tile(tile, [&](int x, int y) {
      const Hit h = tracer.intersect(w.primary(x, y));
      ++rays;
      if (h.valid()) sum += double(h.t);
    });
  });
}

// Workload 2: slim::trace_path from every pixel centre with the pixel's deterministic RNG.
template <class Tracer>
RunResult run_diffuse(const Tracer& tracer, tbb::task_arena& arena, const Workload& w) {
  return run_tiles(arena, w, [&](int tile, uint64_t& rays, double& sum) {
    w.for_tile(tile, [&](int x, int y) {
      Rng rng(pixel_seed(x, y, 0));
      const PathResult p = trace_path(tracer, w.primary(x, y), rng, w.max_bounces, w.offset);
      rays += p.rays;
      sum += double(p.radiance.x) + double(p.radiance.y) + double(p.radiance.z) +
             (p.primary.valid() ? double(p.primary.t) : 0.0);
    });
  });
}

// All workload-1 hits (untimed).
template <class Tracer>
std::vector<Hit> primary_hits(const Tracer& tracer, tbb::task_arena& arena, const Workload& w) {
  std::vector<Hit> hits(size_t(w.width) * size_t(w.height));
  run_tiles(arena, w, [&](int tile, uint64_t&, double&) {
    w.for_tile(tile, [&](int x, int y) {
      hits[size_t(y) * size_t(w.width) + size_t(x)] = tracer.intersect(w.primary(x, y));
    });
  });
  return hits;
}

// A slim::Scene seen through Scene::intersect(ray, counters), for trace_path.
struct CountingTracer {
  const Scene* scene;
  TraversalCounters* counters;
  Hit intersect(const Ray& r) const { return scene->intersect(r, *counters); }
};

// Box and primitive tests per ray: all workload-1 rays, and the paths of every 16th pixel.
void count_traversal(const Scene& scene, tbb::task_arena& arena, const Workload& w, BenchRow& row) {
  std::vector<TraversalCounters> c1(size_t(w.tiles())), c2(size_t(w.tiles()));
  run_tiles(arena, w, [&](int tile, uint64_t&, double&) {
    TraversalCounters& a = c1[size_t(tile)];
    TraversalCounters& b = c2[size_t(tile)];
    CountingTracer counting{&scene, &b};
    w.for_tile(tile, [&](int x, int y) {
      scene.intersect(w.primary(x, y), a);
      if (x % kW2CountStride == 0 && y % kW2CountStride == 0) {
        Rng rng(pixel_seed(x, y, 0));
        trace_path(counting, w.primary(x, y), rng, w.max_bounces, w.offset);
      }
    });
  });
  TraversalCounters s1, s2;
  for (size_t i = 0; i < c1.size(); ++i) {
    for (auto [s, c] : {std::pair{&s1, &c1[i]}, std::pair{&s2, &c2[i]}}) {
      s->rays += c->rays, s->box_tests += c->box_tests, s->prim_tests += c->prim_tests;
      s->prim_records += c->prim_records;
    }
  }
  if (s1.rays) {
    row.box_tests_per_ray = double(s1.box_tests) / double(s1.rays);
    row.prim_tests_per_ray = double(s1.prim_tests) / double(s1.rays);
    row.prim_records_per_ray = double(s1.prim_records) / double(s1.rays);
  }
  if (s2.rays) {
    row.box_tests_per_ray_w2 = double(s2.box_tests) / double(s2.rays);
    row.prim_tests_per_ray_w2 = double(s2.prim_tests) / double(s2.rays);
    row.prim_records_per_ray_w2 = double(s2.prim_records) / double(s2.rays);
  }
}

std::optional<double> detail(const SceneStats& st, const char* key) {
  for (const auto& [k, v] : st.details)
    if (k == key) return v;
  return std::nullopt;
}

void progress(const BenchOptions& opt, const char* fmt, const std::string& a, const std::string& b,
              const std::string& c) {
  if (opt.progress) {
    std::fprintf(stderr, fmt, a.c_str(), b.c_str(), c.c_str());
    std::fflush(stderr);
  }
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

// Formats that intersect other triangles than the input's fan triangulation: lossy grids, costa
// with V (quantized), costa's GLU tessellation of n-gons, the grid cells' diagonals. They are
// validated against Embree run on their own decoded geometry (DESIGN.md "Baseline and oracle"),
// with hits mapped back to the input faces.
struct OwnGeometry {
  PolyMesh mesh;  // one triangle per face
  std::vector<uint32_t> geom, face;
};

template <class Tris>
OwnGeometry own_geometry_from(const Tris& t) {
  OwnGeometry g;
  g.mesh.name = "decoded";
  g.mesh.positions = t.vertices;
  g.mesh.face_sizes.assign(t.size(), 3);
  g.mesh.face_indices.resize(3 * t.size());
  for (size_t i = 0; i < g.mesh.face_indices.size(); ++i) g.mesh.face_indices[i] = uint32_t(i);
  g.geom = t.geom;
  g.face = t.face;
  return g;
}

std::optional<OwnGeometry> own_geometry(const std::vector<const PolyMesh*>& meshes,
                                        const std::string& config) {
  if (EmbreeScene::is_config(config)) return std::nullopt;  // Embree reads the input itself
  if (std::optional<DecodedTriangles> t =
          decoded_triangles(meshes, BuildOptions::from_config(config)))
    return own_geometry_from(*t);
  return std::nullopt;
}

// Everything of one scene that outlives a single configuration.
struct SceneRun {
  const BenchOptions& opt;
  BenchReport& report;
  tbb::task_arena& arena;
  std::string name;
  PolyMesh mesh;
  std::vector<const PolyMesh*> meshes;
  uint64_t triangles = 0;
  Workload w;
  std::vector<Hit> reference;  // embree-tri's workload-1 hits
  bool need_psnr_reference = false;
  std::optional<Image> psnr_reference;  // bvh8-tri4v normals render

  void error(BenchRow& row, const std::string& msg) {
    std::string e = row.scene + " " + row.config + ": " + msg;
    std::fprintf(stderr, "ERROR: %s\n", e.c_str());
    report.errors.push_back(e);
  }

  Image normals_image(const Scene& scene) {
    RenderOptions ro;
    ro.width = ro.height = opt.psnr_size;
    ro.shade = Shade::Normals;
    ro.threads = report.machine.threads;
    ro.max_bounces = 0;
    return render(scene, w.cam, ro);
  }

  // Validation, counting and timing of a built tracer.
  template <class Tracer>
  void measure(const Tracer& tracer, BenchRow& row) {
    std::vector<Hit> hits = primary_hits(tracer, arena, w);
    if (row.config == "embree-tri") {
      reference = std::move(hits);
      row.hit_agreement = 1.0;
      row.same_face = 1.0;
    } else if (!reference.empty()) {
      auto agreement = [&](const std::vector<Hit>& ref, double& frac, double& same_frac) {
        uint64_t agree = 0, both = 0, same = 0;
        for (size_t i = 0; i < hits.size(); ++i) {
          agree += hits_agree(hits[i], ref[i]);
          if (hits[i].valid() && ref[i].valid()) {
            ++both;
            same += hits[i].geomID == ref[i].geomID && hits[i].primID == ref[i].primID;
          }
        }
        frac = double(agree) / double(hits.size());
        same_frac = both ? double(same) / double(both) : 1.0;
      };
      double frac, same_frac;
      agreement(reference, frac, same_frac);
      row.agreement_embree_tri = frac;
      std::string against = "embree-tri";
      if (std::optional<OwnGeometry> own = own_geometry(meshes, row.config)) {
        // Embree on the format's own decoded triangles, hits mapped back to the input faces.
        EmbreeScene es({&own->mesh}, "embree-tri");
        std::vector<Hit> ref = primary_hits(es, arena, w);
        for (Hit& h : ref)
          if (h.valid()) {
            uint32_t t = h.primID;
            h.geomID = own->geom[t];
            h.primID = own->face[t];
          }
        agreement(ref, frac, same_frac);
        against = "embree-tri on its own decoded geometry";
      }
      row.hit_agreement = frac;
      row.same_face = same_frac;
      if (*row.hit_agreement < kLosslessAgreement)
        error(row, "hit agreement with " + against + " " +
                       fmt("%.4f%%", 100.0 * *row.hit_agreement) + " is under 99.9%");
    }
    hits = {};

    std::vector<double> t1, t2;
    for (int r = 0; r < std::max(opt.repeat, 1); ++r) {
      const RunResult p = run_primary(tracer, arena, w);
      const RunResult d = run_diffuse(tracer, arena, w);
      if (r == 0) {
        row.rays_primary = p.rays;
        row.checksum_primary = p.checksum;
        row.rays_diffuse = d.rays;
        row.checksum_diffuse = d.checksum;
      } else if (p.rays != row.rays_primary || d.rays != row.rays_diffuse ||
                 p.checksum != row.checksum_primary || d.checksum != row.checksum_diffuse) {
        error(row, "repeated runs traced different rays (not deterministic)");
      }
      t1.push_back(p.seconds);
      t2.push_back(d.seconds);
    }
    const double m1 = median(t1), m2 = median(t2);
    if (m1 > 0) row.mrays_primary = double(row.rays_primary) / m1 * 1e-6;
    if (m2 > 0) row.mrays_diffuse = double(row.rays_diffuse) / m2 * 1e-6;
  }

  void fill_memory(const MemoryStats& m, BenchRow& row) {
    row.bytes_geometry = m.geometry_bytes;
    row.bytes_bvh = m.bvh_bytes;
    row.bytes_other = m.other_bytes;
    row.bytes_total = m.total();
    if (triangles) row.bytes_per_triangle = double(m.total()) / double(triangles);
  }

  void set_build_time(std::vector<double> seconds, BenchRow& row) {
    row.build_s = median(std::move(seconds));
    if (*row.build_s > 0) row.build_mprims_s = double(triangles) / *row.build_s * 1e-6;
  }

  void run_embree(BenchRow& row) {
    std::unique_ptr<EmbreeScene> scene;
    std::vector<double> build;
    for (int r = 0; r < std::max(opt.repeat, 1); ++r) {
      scene.reset();
      arena.execute([&] { scene = std::make_unique<EmbreeScene>(meshes, row.config); });
      build.push_back(scene->build_seconds());
    }
    set_build_time(build, row);
    fill_memory(scene->memory(), row);
    measure(*scene, row);
  }

  void run_slim(BenchRow& row) {
    BuildOptions bo = BuildOptions::from_config(row.config);
    bo.threads = report.machine.threads;
    std::unique_ptr<Scene> scene;
    std::vector<double> build;
    for (int r = 0; r < std::max(opt.repeat, 1); ++r) {
      scene.reset();
      const auto t0 = Clock::now();
      arena.execute([&] { scene = std::make_unique<Scene>(Scene::build(meshes, bo)); });
      build.push_back(seconds_since(t0));
    }
    set_build_time(build, row);
    fill_memory(scene->memory(), row);

    std::string why;
    if (!scene->validate(&why)) error(row, "Scene::validate failed: " + why);
    count_traversal(*scene, arena, w, row);

    if (row.config == "bvh8-tri4v" && need_psnr_reference) psnr_reference = normals_image(*scene);
    if (row.lossy) {
      const SceneStats& st = scene->stats();
      row.error.rms = detail(st, "rms_error");
      row.error.diag_avg_pct = detail(st, "diag_avg_pct");
      row.error.diag_max_pct = detail(st, "diag_max_pct");
      if (!psnr_reference) {  // bvh8-tri4v is not among the configurations: build it for this
        Scene ref = Scene::build(meshes, BuildOptions::from_config("bvh8-tri4v"));
        psnr_reference = normals_image(ref);
      }
      const double p = psnr(*psnr_reference, normals_image(*scene));
      if (std::isinf(p))
        row.error.psnr_identical = true;
      else
        row.error.psnr_db = p;
    }
    measure(*scene, row);
  }

  void run_config(const std::string& config) {
    BenchRow row;
    row.scene = name;
    row.config = config;
    row.triangles = triangles;
    row.embree = EmbreeScene::is_config(config);
    row.lossy = is_lossy_config(config);
    progress(opt, "%s %s: %s", name, config, "");
    const auto t0 = Clock::now();
    try {
      if (row.embree)
        run_embree(row);
      else
        run_slim(row);
    } catch (const NotApplicable& e) {
      row = BenchRow{row.scene, row.config, row.triangles};
      row.reason = e.what();
      row.embree = EmbreeScene::is_config(config);
      row.lossy = is_lossy_config(config);
    } catch (const Error& e) {
      row = BenchRow{row.scene, row.config, row.triangles};
      row.reason = e.what();
      row.embree = EmbreeScene::is_config(config);
      row.lossy = is_lossy_config(config);
      row.build_failed = true;
      error(row, row.reason);
    } catch (const std::exception& e) {
      row = BenchRow{row.scene, row.config, row.triangles};
      row.reason = std::string("failed: ") + e.what();
      row.build_failed = true;
      error(row, row.reason);
    }
    if (row.measured())
      progress(opt, "%s%s%s\n",
               "build " + fmt("%.3f s", *row.build_s) + ", " +
                   fmt("%.1f B/tri", row.bytes_per_triangle.value_or(0)) + ", " +
                   fmt("%.2f", row.mrays_primary.value_or(0)) + " / " +
                   fmt("%.2f MRays/s", row.mrays_diffuse.value_or(0)),
               ", agreement " + fmt("%.4f%%", 100.0 * row.hit_agreement.value_or(0)) +
                   " (same face " + fmt("%.4f%%", 100.0 * row.same_face.value_or(0)) + ")",
               ", checksums " + fmt("%.6g", row.checksum_primary) + " " +
                   fmt("%.6g", row.checksum_diffuse) + fmt(" (%.1f s)", seconds_since(t0)));
    else
      progress(opt, "%s%s%s\n", row.reason, "", "");
    report.rows.push_back(std::move(row));
  }
};

}  // namespace

std::vector<std::string> default_configs() {
  std::vector<std::string> v = EmbreeScene::config_names();
  for (const std::string& n : all_config_names()) v.push_back(n);
  return v;
}

bool is_lossy_config(const std::string& name) {
  const ConfigInfo* c = find_config(name);
  return c && c->lossy;
}

void check_config_name(const std::string& name) {
  if (EmbreeScene::is_config(name)) return;
  try {
    BuildOptions::from_config(name);
  } catch (const Error& e) {
    throw Error(std::string(e.what()) +
                "; Embree anchors: embree-tri, embree-tri-compact, "
                "embree-quad, embree-quad-pairs, embree-grid");
  }
}

bool hits_agree(const Hit& a, const Hit& b) {
  if (!a.valid() || !b.valid()) return a.valid() == b.valid();
  const double ta = a.t, tb = b.t;
  return std::fabs(ta - tb) <= 1e-5 * std::max(std::fabs(ta), std::fabs(tb));
}

std::string cpu_model_name() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) != 0) continue;
    const size_t colon = line.find(':');
    if (colon == std::string::npos) continue;
    std::string v = line.substr(colon + 1);
    const size_t b = v.find_first_not_of(" \t");
    return b == std::string::npos ? "unknown" : v.substr(b);
  }
  return "unknown";
}

BenchReport run_bench(const BenchOptions& opt) {
  if (opt.scenes.empty()) throw Error("bench: no scene given");
  std::vector<std::string> configs = opt.configs.empty() ? default_configs() : opt.configs;
  for (const std::string& c : configs) check_config_name(c);
  // embree-tri is the reference of the ratios and of the validation: always first, always once.
  configs.erase(std::remove(configs.begin(), configs.end(), "embree-tri"), configs.end());
  configs.insert(configs.begin(), "embree-tri");
  std::vector<std::string> unique;
  for (const std::string& c : configs)
    if (std::find(unique.begin(), unique.end(), c) == unique.end()) unique.push_back(c);
  configs = unique;

  BenchReport report;
  report.machine.cpu = cpu_model_name();
  report.machine.threads = opt.threads > 0 ? opt.threads : tbb::this_task_arena::max_concurrency();
  // The compiled SIMD path of the library. Nothing public reports it yet (see the README).
  report.machine.isa = slim::simd_isa();
  report.repeat = std::max(opt.repeat, 1);
  report.width = opt.width;
  report.height = opt.height;
  report.max_bounces = opt.max_bounces;
  tbb::task_arena arena(report.machine.threads);
  // Start the arena's threads before anything is timed, so that the first build does not pay it.
  arena.execute([&] {
    tbb::parallel_for(0, 64 * report.machine.threads, [](int) {
      const auto t0 = Clock::now();
      while (seconds_since(t0) < 1e-3) {
      }
    });
  });

  const bool any_lossy = std::any_of(configs.begin(), configs.end(), is_lossy_config);
  for (const std::string& scene_name : opt.scenes) {
    SceneRun run{opt, report, arena, scene_name};
    const auto t0 = Clock::now();
    run.mesh = load(scene_name);
    run.meshes = {&run.mesh};
    run.triangles = run.mesh.fan_triangle_count();
    const Box3f box = run.mesh.bounds();
    run.w.cam = frame_box(box, opt.width, opt.height);
    run.w.offset = ray_offset_scale(box);
    run.w.width = opt.width;
    run.w.height = opt.height;
    run.w.max_bounces = opt.max_bounces;
    run.w.tiles_x = (opt.width + kTile - 1) / kTile;
    run.w.tiles_y = (opt.height + kTile - 1) / kTile;
    run.need_psnr_reference = any_lossy;
    if (opt.progress)
      std::fprintf(stderr, "%s: %llu faces, %llu triangles, loaded in %.2f s\n", scene_name.c_str(),
                   (unsigned long long)run.mesh.face_count(), (unsigned long long)run.triangles,
                   seconds_since(t0));
    // The PSNR reference is bvh8-tri4v's render, made when bvh8-tri4v runs (it comes before the
    // lossy formats in the default order) or built on demand by the first lossy configuration.
    for (const std::string& c : configs) run.run_config(c);
    const size_t first = report.rows.size() - configs.size();
    const BenchRow& ref = report.rows[first];
    for (size_t i = first; i < report.rows.size(); ++i) {
      BenchRow& row = report.rows[i];
      if (!row.measured() || !ref.measured()) continue;
      if (row.mrays_primary && ref.mrays_primary)
        row.ratio_primary = *row.mrays_primary / *ref.mrays_primary;
      if (row.mrays_diffuse && ref.mrays_diffuse)
        row.ratio_diffuse = *row.mrays_diffuse / *ref.mrays_diffuse;
    }
  }
  return report;
}

namespace {

template <class T>
nlohmann::json opt_json(const std::optional<T>& v) {
  if (!v || (std::is_floating_point_v<T> && !std::isfinite(double(*v)))) return nullptr;
  return *v;
}

}  // namespace

nlohmann::json report_json(const BenchReport& report) {
  nlohmann::json out;
  out["machine"] = {{"cpu", report.machine.cpu},
                    {"threads", report.machine.threads},
                    {"isa", report.machine.isa}};
  nlohmann::json results = nlohmann::json::array();
  for (const BenchRow& r : report.rows) {
    nlohmann::json j;
    j["scene"] = r.scene;
    j["config"] = r.config;
    j["triangles"] = r.triangles;
    j["build_s"] = opt_json(r.build_s);
    j["bytes_geometry"] = opt_json(r.bytes_geometry);
    j["bytes_bvh"] = opt_json(r.bytes_bvh);
    j["bytes_other"] = opt_json(r.bytes_other);
    j["bytes_total"] = opt_json(r.bytes_total);
    j["bytes_per_triangle"] = opt_json(r.bytes_per_triangle);
    j["mrays_primary"] = opt_json(r.mrays_primary);
    j["mrays_diffuse"] = opt_json(r.mrays_diffuse);
    j["ratio_primary"] = opt_json(r.ratio_primary);
    j["ratio_diffuse"] = opt_json(r.ratio_diffuse);
    j["box_tests_per_ray"] = opt_json(r.box_tests_per_ray);
    j["prim_tests_per_ray"] = opt_json(r.prim_tests_per_ray);
    // Beyond BENCHMARK.md's schema: primitive records (a pair counts once), and the counts of
    // the workload-2 sample (the paths of every 16th pixel).
    j["prim_records_per_ray"] = opt_json(r.prim_records_per_ray);
    j["box_tests_per_ray_w2s"] = opt_json(r.box_tests_per_ray_w2);
    j["prim_tests_per_ray_w2s"] = opt_json(r.prim_tests_per_ray_w2);
    j["prim_records_per_ray_w2s"] = opt_json(r.prim_records_per_ray_w2);
    j["hit_agreement"] = opt_json(r.hit_agreement);
    j["hit_agreement_embree_tri"] = opt_json(r.agreement_embree_tri);
    j["error"] = {{"rms", opt_json(r.error.rms)},
                  {"diag_avg_pct", opt_json(r.error.diag_avg_pct)},
                  {"diag_max_pct", opt_json(r.error.diag_max_pct)},
                  {"psnr_db", opt_json(r.error.psnr_db)}};
    if (!r.measured()) j["reason"] = r.reason;
    results.push_back(std::move(j));
  }
  out["results"] = std::move(results);
  return out;
}

namespace {

std::string cell(const std::optional<double>& v, const char* f) {
  return v ? fmt(f, *v) : std::string("—");
}

std::string markdown_escape(std::string s) {
  std::string out;
  for (char c : s) {
    if (c == '|') out += '\\';
    out += c == '\n' ? ' ' : c;
  }
  return out;
}

}  // namespace

std::string report_markdown(const BenchReport& report) {
  std::ostringstream o;
  o << "slimrt bench: " << report.machine.cpu << ", " << report.machine.threads << " threads, isa "
    << report.machine.isa << "; camera " << report.width << "x" << report.height << "; medians of "
    << report.repeat << " runs; Embree kernels: " << EmbreeScene::kernel_isa() << ".\n"
    << "W1 = one primary ray per pixel, W2 = diffuse path tracing (up to " << report.max_bounces
    << " bounces, every ray counted). ratio = MRays/s over embree-tri's. box/prim = tests per ray "
       "(slimrt only, untimed counting pass): W1 over all workload-1 rays, W2s over the paths of "
       "every 16th pixel. agree = workload-1 hits agreeing with Embree on the same geometry "
       "(BENCHMARK.md): embree-tri, or for grid, lossy-grid* and costa-* embree-tri run on the "
       "format's own decoded triangles; vs tri = agreement with embree-tri on the input's fan "
       "triangles. MB = geometry + BVH + side tables.\n\n";
  o << "| scene | config | build s | Mtri/s | MB | B/tri | W1 MRays/s | W2 MRays/s | W1 ratio | "
       "W2 ratio | box/ray W1 | prim/ray W1 | box/ray W2s | prim/ray W2s | agree % | vs tri % | "
       "PSNR dB | note |\n";
  o << "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | "
       "---: | ---: | ---: | ---: | --- |\n";
  for (const BenchRow& r : report.rows) {
    o << "| " << markdown_escape(r.scene) << " | " << r.config << " | ";
    if (!r.measured()) {
      for (int i = 0; i < 15; ++i) o << "— | ";
      o << markdown_escape(r.reason) << " |\n";
      continue;
    }
    std::optional<double> mb;
    if (r.bytes_total) mb = double(*r.bytes_total) / 1e6;
    std::optional<double> agree;
    if (r.hit_agreement) agree = 100.0 * *r.hit_agreement;
    std::optional<double> vs_tri;
    if (r.agreement_embree_tri) vs_tri = 100.0 * *r.agreement_embree_tri;
    if (r.config == "embree-tri") vs_tri = agree;
    std::string note;
    if (r.hit_agreement && *r.hit_agreement < kLosslessAgreement) note = "ERROR: agreement < 99.9%";
    std::string psnr_cell = r.error.psnr_identical ? "inf" : cell(r.error.psnr_db, "%.2f");
    o << cell(r.build_s, "%.3f") << " | " << cell(r.build_mprims_s, "%.2f") << " | "
      << cell(mb, "%.2f") << " | " << cell(r.bytes_per_triangle, "%.1f") << " | "
      << cell(r.mrays_primary, "%.2f") << " | " << cell(r.mrays_diffuse, "%.2f") << " | "
      << cell(r.ratio_primary, "%.3f") << " | " << cell(r.ratio_diffuse, "%.3f") << " | "
      << cell(r.box_tests_per_ray, "%.1f") << " | " << cell(r.prim_tests_per_ray, "%.1f") << " | "
      << cell(r.box_tests_per_ray_w2, "%.1f") << " | " << cell(r.prim_tests_per_ray_w2, "%.1f")
      << " | " << cell(agree, "%.3f") << " | " << cell(vs_tri, "%.3f") << " | " << psnr_cell
      << " | " << note << " |\n";
  }
  return o.str();
}

// Runs gnuplot on `script` (whose "set output" names SLIM_PLOT_OUTPUT) through write_atomically:
// the PNG appears complete or not at all. gnuplot's own error lines are kept for the message.
static bool run_gnuplot(const std::string& script, const std::string& png_path, std::string* why) {
  try {
    write_atomically(png_path, [&](const std::string& tmp) {
      std::string quoted = "'";
      for (char c : tmp) quoted += c == '\'' ? std::string("''") : std::string(1, c);
      quoted += "'";
      std::string full = script;
      const std::string marker = "SLIM_PLOT_OUTPUT";
      if (const size_t at = full.find(marker); at != std::string::npos)
        full.replace(at, marker.size(), quoted);
      const std::string log = tmp + ".log";
      FILE* pipe = popen(("gnuplot 2> '" + log + "'").c_str(), "w");
      if (!pipe) throw Error("could not start gnuplot: " + std::string(std::strerror(errno)));
      std::fwrite(full.data(), 1, full.size(), pipe);
      const int status = pclose(pipe);
      std::string said;
      if (FILE* f = std::fopen(log.c_str(), "r")) {
        char line[512];
        while (std::fgets(line, sizeof line, f)) {
          std::string l(line);
          while (!l.empty() && (l.back() == '\n' || l.back() == ' ')) l.pop_back();
          if (!l.empty()) said = l;  // the last non-empty line holds gnuplot's error
        }
        std::fclose(f);
      }
      std::remove(log.c_str());
      if (status != 0) {
        std::string what =
            status == -1 ? std::string("could not wait for gnuplot")
            : WIFEXITED(status)
                ? "gnuplot exited with code " + std::to_string(WEXITSTATUS(status)) + ", expected 0"
            : WIFSIGNALED(status)
                ? "gnuplot was killed by signal " + std::to_string(WTERMSIG(status))
                : "gnuplot failed";
        throw Error(what + (said.empty() ? std::string() : ": " + said));
      }
    });
  } catch (const Error& e) {
    if (why) *why = e.what();
    return false;
  }
  return true;
}

bool write_plot(const BenchReport& report, const std::string& png_path, std::string* why) {
  auto fail = [&](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (std::system("gnuplot --version > /dev/null 2>&1") != 0)
    return fail("gnuplot not found (Debian package gnuplot-nox; scripts/setup.sh installs it)");

  // One panel per scene with at least one point.
  std::vector<std::string> scenes;
  for (const BenchRow& r : report.rows)
    if (r.bytes_per_triangle && r.mrays_diffuse && *r.bytes_per_triangle > 0 &&
        std::find(scenes.begin(), scenes.end(), r.scene) == scenes.end())
      scenes.push_back(r.scene);
  if (scenes.empty()) return fail("no configuration has both bytes/triangle and diffuse MRays/s");

  auto quote = [](const std::string& s) {  // gnuplot single-quoted string
    std::string out = "'";
    for (char c : s) out += c == '\'' ? std::string("''") : std::string(1, c);
    return out + "'";
  };
  std::ostringstream g;
  const int panel_h = 520;
  g << "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
    << "  set terminal pngcairo size 960," << panel_h * int(scenes.size()) << " font ',10'\n"
    << "} else {\n"
    << "  set terminal png size 960," << panel_h * int(scenes.size()) << "\n"
    << "}\n"
    << "set output SLIM_PLOT_OUTPUT\n"
    << "set multiplot layout " << scenes.size() << ",1\n"
    << "set logscale x\nset grid\nset key top right\n"
    << "set xlabel 'memory: bytes per input triangle (log scale)'\n"
    << "set ylabel 'diffuse MRays/s (workload 2)'\n"
    << "set offsets graph 0.05, graph 0.25, graph 0.1, graph 0.05\n";
  for (size_t s = 0; s < scenes.size(); ++s) {
    std::ostringstream emb, sli;
    for (const BenchRow& r : report.rows) {
      if (r.scene != scenes[s] || !r.bytes_per_triangle || !r.mrays_diffuse ||
          *r.bytes_per_triangle <= 0)
        continue;
      (r.embree ? emb : sli) << "\"" << r.config << "\" " << *r.bytes_per_triangle << " "
                             << *r.mrays_diffuse << "\n";
    }
    std::vector<std::string> parts;
    auto block = [&](const std::string& data, const char* tag, const char* colour,
                     const char* title) {
      if (data.empty()) return;
      const std::string name = "$" + std::string(tag) + std::to_string(s);
      g << name << " << EOD\n" << data << "EOD\n";
      parts.push_back(name + " using 2:3 with points pt 7 ps 1.3 lc rgb '" + colour + "' title '" +
                      title + "'");
      parts.push_back(name + " using 2:3:1 with labels left offset char 0.8,0.4 font ',8' notitle");
    };
    block(emb.str(), "embree", "#c0392b", "Embree 3");
    block(sli.str(), "slim", "#1f5fbf", "slimrt");
    g << "set title "
      << quote(scenes[s] + ": " + std::to_string(report.machine.threads) + " threads, " +
               report.machine.cpu)
      << "\nplot ";
    for (size_t i = 0; i < parts.size(); ++i) g << (i ? ", \\\n     " : "") << parts[i];
    g << "\n";
  }
  g << "unset multiplot\n";

  return run_gnuplot(g.str(), png_path, why);
}

}  // namespace slim::bench
