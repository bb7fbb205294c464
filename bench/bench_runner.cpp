// `slimrt bench` driver: see bench_runner.h and docs/benchmark.md.
#include "bench_runner.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <utility>

#include "embree_scene.h"
#include "slimrt/analysis.h"

namespace slim::bench {

namespace {

constexpr int kTile = 32;          // pixels per tile side: the unit of parallel work
constexpr int kW2CountStride = 4;  // workload-2 counting: pixels with x, y multiples of 4

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
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

// CPU seconds of the whole process (every thread), for the rounds' cpu_seconds figures.
double process_cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

struct RunResult {
  double seconds = 0;
  double cpu_seconds = 0;  // process CPU time over the run (includes idle workers' spinning)
  uint64_t rays = 0;
  double checksum = 0;
  int passes = 1;          // passes timed (seconds and cpu_seconds are the fastest one's)
  bool repeatable = true;  // every pass traced the same rays with the same checksum
};

// Runs `pass` (one whole workload) until min_seconds have passed, at least once and at most
// kMaxTimingPasses times, and keeps the fastest pass: other processes on a shared machine only ever
// slow a pass down, so the fastest is the least disturbed.
template <class Pass>
RunResult timed_passes(Pass&& pass, double min_seconds) {
  RunResult best = pass();
  double total = best.seconds;
  int passes = 1;
  bool repeatable = true;
  while (total < min_seconds && passes < kMaxTimingPasses) {
    const RunResult r = pass();
    repeatable = repeatable && r.rays == best.rays && r.checksum == best.checksum;
    total += r.seconds;
    ++passes;
    if (r.seconds < best.seconds) best = r;
  }
  best.passes = passes;
  best.repeatable = repeatable;
  return best;
}

// Runs body(tile, rays, checksum) over every tile in the arena, FTZ/DAZ set in every task; the
// per-tile sums are added in tile order, so the checksum does not depend on the schedule.
template <class Body>
RunResult run_tiles(tbb::task_arena& arena, const Workload& w, Body&& body) {
  std::vector<uint64_t> rays(size_t(w.tiles()), 0);
  std::vector<double> sums(size_t(w.tiles()), 0.0);
  const double cpu0 = process_cpu_seconds();
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
  res.cpu_seconds = process_cpu_seconds() - cpu0;
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

// A slim::Scene seen through intersect_counted (slimrt/analysis.h), for trace_path.
struct CountingTracer {
  const Scene* scene;
  TraversalCounters* counters;
  Hit intersect(const Ray& r) const { return intersect_counted(*scene, r, *counters); }
};

// Box and primitive tests per ray: all workload-1 rays, and the paths of every 16th pixel.
void count_traversal(const Scene& scene, tbb::task_arena& arena, const Workload& w, BenchRow& row) {
  std::vector<TraversalCounters> c1(size_t(w.tiles())), c2(size_t(w.tiles()));
  run_tiles(arena, w, [&](int tile, uint64_t&, double&) {
    TraversalCounters& a = c1[size_t(tile)];
    TraversalCounters& b = c2[size_t(tile)];
    CountingTracer counting{&scene, &b};
    w.for_tile(tile, [&](int x, int y) {
      intersect_counted(scene, w.primary(x, y), a);
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

void progress(const BenchOptions& opt, const std::string& line) {
  if (opt.progress) {
    std::fputs(line.c_str(), stderr);
    std::fflush(stderr);
  }
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

std::string spread_text(const std::optional<Spread>& s, const char* f) {
  if (!s) return "-";
  return fmt(f, s->median) + " (" + fmt(f, s->lo) + "-" + fmt(f, s->hi) + ")" +
         (s->noisy() ? "!" : "");
}

// One configuration of a scene: its row, and its built scene between rounds (one of the two
// pointers, or neither while a scene that does not fit the memory budget waits for its turn).
struct Slot {
  size_t row = 0;
  std::unique_ptr<EmbreeScene> embree;
  std::unique_ptr<Scene> slim;
  bool built() const { return embree || slim; }
  void release() {
    embree.reset();
    slim.reset();
  }
};

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
  std::vector<Slot> slots;              // the configurations prepared, in configuration order
  std::vector<uint64_t> slot_bytes;     // their memory() totals, for the keep decision

  void error(const BenchRow& row, const std::string& msg) {
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

  // Validation of a built tracer's workload-1 hits against embree-tri's (untimed).
  template <class Tracer>
  void validate_hits(const Tracer& tracer, BenchRow& row) {
    std::vector<Hit> hits = primary_hits(tracer, arena, w);
    if (row.config == "embree-tri") {
      reference = std::move(hits);
      row.hit_agreement = 1.0;
      row.same_face = 1.0;
      return;
    }
    if (reference.empty()) return;
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
    std::optional<OwnGeometry> own;  // Embree reads the input itself
    if constexpr (std::is_same_v<Tracer, Scene>) own = own_geometry(tracer, meshes);
    if (own) {
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
      error(row, "hit agreement with " + against + " " + fmt("%.4f%%", 100.0 * *row.hit_agreement) +
                     " is under 99.9%");
  }

  void fill_memory(const MemoryStats& m, BenchRow& row) {
    row.bytes_geometry = m.geometry_bytes;
    row.bytes_bvh = m.bvh_bytes;
    row.bytes_other = m.other_bytes;
    row.bytes_total = m.total();
    if (triangles) row.bytes_per_triangle = double(m.total()) / double(triangles);
  }

  // Builds the row's scene into the slot (the previous one freed first); returns the build time:
  // EmbreeScene::build_seconds() (buffer set-up + commit), Scene::build's wall time.
  double build(const BenchRow& row, Slot& slot) {
    slot.release();
    if (row.embree) {
      arena.execute([&] { slot.embree = std::make_unique<EmbreeScene>(meshes, row.config); });
      return slot.embree->build_seconds();
    }
    BuildOptions bo = BuildOptions::from_config(row.config, opt.tuning);
    bo.threads = report.machine.threads;
    const auto t0 = Clock::now();
    arena.execute([&] { slot.slim = std::make_unique<Scene>(Scene::build(meshes, bo)); });
    return seconds_since(t0);
  }

  // The first build of each configuration (untimed: the rounds time the builds) and what is
  // checked before the rounds.
  void prepare_embree(BenchRow& row, Slot& slot) {
    build(row, slot);
    fill_memory(slot.embree->memory(), row);
    validate_hits(*slot.embree, row);
  }

  void prepare_slim(BenchRow& row, Slot& slot) {
    build(row, slot);
    const Scene& scene = *slot.slim;
    fill_memory(scene.memory(), row);

    std::string why;
    if (!scene.validate(&why)) error(row, "Scene::validate failed: " + why);
    count_traversal(scene, arena, w, row);

    if (row.config == "bvh8-tri4v" && need_psnr_reference) psnr_reference = normals_image(scene);
    if (row.lossy) {
      row.error.rms = stat_detail(scene, "rms_error");
      row.error.diag_avg_pct = stat_detail(scene, "diag_avg_pct");
      row.error.diag_max_pct = stat_detail(scene, "diag_max_pct");
      if (!psnr_reference) {  // bvh8-tri4v is not among the configurations: build it for this
        Scene ref = Scene::build(meshes, BuildOptions::from_config("bvh8-tri4v"));
        psnr_reference = normals_image(ref);
      }
      const double p = psnr(*psnr_reference, normals_image(scene));
      if (std::isinf(p))
        row.error.psnr_identical = true;
      else
        row.error.psnr_db = p;
    }
    validate_hits(scene, row);
  }

  // A row that was not measured: every figure empty, the reason kept.
  BenchRow unmeasured(const BenchRow& row, const std::string& reason) {
    BenchRow r{row.scene, row.config, row.triangles};
    r.reason = reason;
    r.embree = row.embree;
    r.lossy = row.lossy;
    return r;
  }

  // Part A of bench_runner.h for one configuration: build, validate, count; keep or free.
  void prepare(const std::string& config) {
    BenchRow row;
    row.scene = name;
    row.config = config;
    row.triangles = triangles;
    row.embree = EmbreeScene::is_config(config);
    row.lossy = is_lossy_config(config);
    progress(opt, name + " " + config + ": ");
    const auto t0 = Clock::now();
    Slot slot;
    try {
      if (row.embree)
        prepare_embree(row, slot);
      else
        prepare_slim(row, slot);
    } catch (const NotApplicable& e) {
      slot.release();
      row = unmeasured(row, e.what());
    } catch (const Error& e) {
      slot.release();
      row = unmeasured(row, e.what());
      row.build_failed = true;
      error(row, row.reason);
    } catch (const std::exception& e) {
      slot.release();
      row = unmeasured(row, std::string("failed: ") + e.what());
      row.build_failed = true;
      error(row, row.reason);
    }
    if (row.measured()) {
      slot_bytes.push_back(row.bytes_total.value_or(0));
      row.kept = keep_between_rounds(slot_bytes, report.memory_budget).back();
      if (!row.kept) slot.release();
      progress(opt, "first build and checks " + fmt("%.1f s", seconds_since(t0)) + ", " +
                        fmt("%.1f B/tri", row.bytes_per_triangle.value_or(0)) + ", agreement " +
                        fmt("%.4f%%", 100.0 * row.hit_agreement.value_or(0)) + " (same face " +
                        fmt("%.4f%%", 100.0 * row.same_face.value_or(0)) + "), " +
                        (row.kept ? "kept" : "rebuilt for its rays in each round") + "\n");
      slot.row = report.rows.size();
      slots.push_back(std::move(slot));
    } else {
      progress(opt, row.reason + "\n");
    }
    report.rows.push_back(std::move(row));
  }

  // One configuration's build in round `round`, timed; the scene stays for the rays. A scene
  // that does not fit the memory budget is built (and timed) at its rays' turn instead, so that
  // it is built once per round, not twice.
  void time_build(Slot& slot) {
    BenchRow& row = report.rows[slot.row];
    if (row.kept) row.seconds_build.push_back(build(row, slot));
  }

  // One configuration's turn in round `round`: both workloads, timed.
  void time_slot(Slot& slot, int round) {
    BenchRow& row = report.rows[slot.row];
    if (!slot.built()) row.seconds_build.push_back(build(row, slot));  // not kept between turns
    RunResult p, d;
    const double min_s = opt.min_seconds;
    if (slot.embree) {
      p = timed_passes([&] { return run_primary(*slot.embree, arena, w); }, min_s);
      d = timed_passes([&] { return run_diffuse(*slot.embree, arena, w); }, min_s);
    } else {
      p = timed_passes([&] { return run_primary(*slot.slim, arena, w); }, min_s);
      d = timed_passes([&] { return run_diffuse(*slot.slim, arena, w); }, min_s);
    }
    if (!row.kept) slot.release();
    if (round == 0) {
      row.rays_primary = p.rays;
      row.checksum_primary = p.checksum;
      row.rays_diffuse = d.rays;
      row.checksum_diffuse = d.checksum;
    } else if (p.rays != row.rays_primary || d.rays != row.rays_diffuse ||
               p.checksum != row.checksum_primary || d.checksum != row.checksum_diffuse) {
      error(row, "round " + std::to_string(round + 1) +
                     " traced different rays than round 1 (not deterministic)");
    }
    if (!p.repeatable || !d.repeatable)
      error(row, "round " + std::to_string(round + 1) +
                     ": the passes of one timing traced different rays (not deterministic)");
    row.seconds_primary.push_back(p.seconds);
    row.seconds_diffuse.push_back(d.seconds);
    row.passes_primary.push_back(p.passes);
    row.passes_diffuse.push_back(d.passes);
    row.cpu_seconds_primary.push_back(p.cpu_seconds);
    row.cpu_seconds_diffuse.push_back(d.cpu_seconds);
  }

  // Part B of bench_runner.h: the interleaved rounds, then the medians and ranges.
  void time_rounds() {
    std::vector<Slot*> active;
    for (Slot& s : slots) active.push_back(&s);
    for (int round = 0; round < report.repeat; ++round) {
      const auto t0 = Clock::now();
      std::vector<Slot*> failed;
      // A slot whose build or rays throw (out of memory) leaves the rounds.
      auto guarded = [&](Slot& slot, auto&& fn) {
        if (std::find(failed.begin(), failed.end(), &slot) != failed.end()) return;
        try {
          fn();
        } catch (const std::exception& e) {
          slot.release();
          BenchRow& row = report.rows[slot.row];
          row = unmeasured(row, "failed in round " + std::to_string(round + 1) + ": " + e.what());
          row.build_failed = true;
          error(row, row.reason);
          failed.push_back(&slot);
        }
      };
      // Every configuration's build in the round's order, then every configuration's rays in the
      // same order: drift of the shared machine spreads over all configurations alike.
      const std::vector<size_t> order = round_order(active.size(), round);
      for (size_t i : order) guarded(*active[i], [&] { time_build(*active[i]); });
      for (size_t i : order) guarded(*active[i], [&] { time_slot(*active[i], round); });
      for (Slot* f : failed) active.erase(std::find(active.begin(), active.end(), f));
      progress(opt, name + ": round " + std::to_string(round + 1) + "/" +
                        std::to_string(report.repeat) + fmt(" (%.1f s)\n", seconds_since(t0)));
    }
    const BenchRow* ref = nullptr;
    for (Slot* s : active)
      if (report.rows[s->row].config == "embree-tri") ref = &report.rows[s->row];
    for (Slot* s : active) {
      BenchRow& row = report.rows[s->row];
      std::vector<double> m1, m2, r1, r2;
      for (size_t k = 0; k < row.seconds_primary.size(); ++k) {
        m1.push_back(double(row.rays_primary) / row.seconds_primary[k] * 1e-6);
        m2.push_back(double(row.rays_diffuse) / row.seconds_diffuse[k] * 1e-6);
        if (!ref) continue;
        r1.push_back(m1.back() / (double(ref->rays_primary) / ref->seconds_primary[k] * 1e-6));
        r2.push_back(m2.back() / (double(ref->rays_diffuse) / ref->seconds_diffuse[k] * 1e-6));
      }
      if (m1.empty()) continue;
      row.build_s = spread_of(row.seconds_build);
      if (row.build_s->median > 0)
        row.build_mprims_s = double(triangles) / row.build_s->median * 1e-6;
      row.mrays_primary = spread_of(m1);
      row.mrays_diffuse = spread_of(m2);
      if (ref) {
        row.ratio_primary = spread_of(r1);
        row.ratio_diffuse = spread_of(r2);
      }
      progress(opt, name + " " + row.config + ": build " + spread_text(row.build_s, "%.3f") +
                        " s, " + spread_text(row.mrays_primary, "%.2f") + " / " +
                        spread_text(row.mrays_diffuse, "%.2f") + " MRays/s, ratios " +
                        spread_text(row.ratio_primary, "%.2f") + " / " +
                        spread_text(row.ratio_diffuse, "%.2f") + ", checksums " +
                        fmt("%.17g", row.checksum_primary) + " " +
                        fmt("%.17g", row.checksum_diffuse) + "\n");
    }
    slots.clear();
  }
};

}  // namespace

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
  report.min_seconds = opt.min_seconds;
  report.width = opt.width;
  report.height = opt.height;
  report.max_bounces = opt.max_bounces;
  report.memory_budget = opt.memory_budget > 0 ? opt.memory_budget : default_memory_budget();
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
    // The PSNR reference is bvh8-tri4v's render, made when bvh8-tri4v is prepared (it comes before
    // the lossy formats in the default order) or built on demand by the first lossy configuration.
    for (const std::string& c : configs) run.prepare(c);
    run.reference = {};
    run.psnr_reference.reset();
    run.time_rounds();
  }
  return report;
}

}  // namespace slim::bench
