// `slimrt verify SCENE [--config NAME...] [--rays N] [--seed S] [build options: --threads N, ...]`
//
// Watertightness and hit-distance checks of every slimrt configuration on a closed mesh (the idea
// of Embree's `verify` suite): rays start strictly inside the mesh and go
//   1/3 in random directions,
//   1/3 exactly at mesh vertices     (direction = vertex - origin, not normalized),
//   1/3 exactly at edge midpoints    (edges of the fan triangles, diagonals included),
// so every ray must hit: a miss of intersect() or an occluded() == false is a leak. Each hit is
// also compared with the first surface crossing of the input mesh, t_ref, given by `bvh8-tri4v`
// on the same ray (an uncompressed, watertight reference): a hit farther than t_ref by more than
// the format's stated error is counted as `far`, one nearer by more than that as `near`.
//
// Tolerances, in scene units along the ray (t * |dir|):
//   lossless formats: 1e-5 * (distance to the reference hit) + 1e-6 * (box diagonal) (rounding:
//     two formats may hit the two triangles of a shared edge, whose t differ in the last bits);
//   lossy formats (Scene::is_lossy()): that plus e / max(|cos theta|, 0.05), where e bounds
//     the distance of every decoded vertex from its input vertex and theta is the angle between
//     the ray and the input surface normal at t_ref. Each decoded triangle is the convex hull of
//     decoded vertices within e of the input ones (the formats keep the input's fan diagonals),
//     so the decoded surface lies within e of the input surface and, where it is locally flat,
//     the crossing moves by at most e / |cos theta| along the ray; below |cos theta| = 0.05
//     (grazing by less than 3 degrees) the bound is held at 20 e. e is what the format's
//     specification promises, computed from the input mesh alone (never from the scene's own
//     statistics): its registry row's ConfigInfo::promised_error (slimrt/scene.h), which includes
//     a few float roundings of the largest coordinate. A lossy hit beyond e / |cos theta| of
//     the input crossing FAILS the configuration unless the geometry excuses it: its point lies
//     within e of the input surface (double-precision distance to the input's fan triangles) and,
//     if it is farther than t_ref, the ray runs along the input surface in between (grazing: the
//     midpoint of t_ref and t lies within 2e of it), only dips under it by less than 2e (the
//     midpoint of t_ref and the next input crossing lies within 2e of the surface), or only
//     touches it at t_ref (a ray aimed at a vertex or edge of a saddle: still inside the input
//     4e past t_ref, by the parity test below). Every such hit is checked, at any ray count: the
//     rays are traced in chunks (--check-chunk) and a chunk's hits are checked before the next
//     chunk is traced; the distances are exact, through a grid of the input triangles
//     (InputSurface). --bound-scale F holds the formats to F e instead (a test of the check).
//
// SCENE is anything slim::load() reads, or `sphere:L`: an icosahedron subdivided L times
// (20 * 4^L triangles, 1 <= L <= 9) with vertices jittered radially by +-1%, closed and welded.
// Inside points are sampled in the box and kept when the parity of their crossings with the
// reference scene is odd along 2 of 3 directions. Exit code 0 when no configuration leaks or
// misplaces a hit, 1 otherwise (also when a configuration fails to build or validate), 2 when
// the mesh is not closed (boundary or non-manifold edges; --allow-open runs it anyway).
// Configurations that throw slim::NotApplicable are listed as such.
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <map>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "build_flags.h"
#include "commands.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"

namespace slim::cli {

namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

PolyMesh load_scene(const std::string& name) {
  if (name.rfind("sphere:", 0) == 0) {
    const std::string d = name.substr(7);
    const bool ok = d.size() == 1 && d[0] >= '1' && d[0] <= '9';
    if (!ok) throw Error(name + ": expected sphere:L with L a subdivision level from 1 to 9");
    return make_sphere(d[0] - '0', 0.01f, 5);  // radial jitter +-1%
  }
  return load(name);
}

struct Closedness {
  uint64_t edges = 0, boundary = 0, nonmanifold = 0;
};

// Polygon edges counted over positions welded by their exact bits (a closed mesh may duplicate
// vertices along seams of its attributes).
Closedness closedness(const PolyMesh& m) {
  std::unordered_map<uint64_t, uint32_t> weld_of;
  std::vector<uint32_t> weld(m.positions.size());
  for (size_t i = 0; i < m.positions.size(); ++i) {
    uint32_t b[3];
    std::memcpy(b, &m.positions[i], 12);
    const uint64_t key = (uint64_t(b[0]) * 0x9E3779B97F4A7C15ULL) ^
                         (uint64_t(b[1]) * 0xC2B2AE3D27D4EB4FULL) ^ (uint64_t(b[2]) << 17) ^ b[2];
    // Hash collisions of different positions would merge them: compare before trusting a key.
    auto it = weld_of.find(key);
    if (it != weld_of.end() && m.positions[it->second] == m.positions[i]) {
      weld[i] = weld[it->second];
    } else {
      weld[i] = uint32_t(i);
      if (it == weld_of.end()) weld_of.emplace(key, uint32_t(i));
    }
  }
  std::unordered_map<uint64_t, uint32_t> uses;
  uint64_t c = 0;
  for (uint32_t n : m.face_sizes) {
    for (uint32_t k = 0; k < n; ++k) {
      uint32_t a = weld[m.face_indices[c + k]], b = weld[m.face_indices[c + (k + 1) % n]];
      if (a == b) continue;
      uses[uint64_t(std::min(a, b)) << 32 | std::max(a, b)]++;
    }
    c += n;
  }
  Closedness r;
  r.edges = uses.size();
  for (const auto& [k, u] : uses) {
    if (u == 1) r.boundary++;
    if (u > 2) r.nonmanifold++;
  }
  return r;
}

// The targets of the rays: vertices used by a finite face, and midpoints (in float, as the test
// suite does) of the fan-triangle edges, diagonals included.
struct Targets {
  std::vector<Vec3f> vertices, midpoints;
};

Targets make_targets(const PolyMesh& m) {
  Targets t;
  std::vector<char> used(m.positions.size(), 0);
  std::unordered_map<uint64_t, char> seen;
  uint64_t c = 0;
  for (uint32_t n : m.face_sizes) {
    bool finite = true;
    for (uint32_t k = 0; k < n; ++k)
      finite = finite && is_finite(m.positions[m.face_indices[c + k]]);
    if (finite) {
      for (uint32_t k = 0; k < n; ++k) used[m.face_indices[c + k]] = 1;
      auto edge = [&](uint32_t a, uint32_t b) {
        if (a == b) return;
        if (seen.emplace(uint64_t(std::min(a, b)) << 32 | std::max(a, b), 1).second)
          t.midpoints.push_back((m.positions[a] + m.positions[b]) * 0.5f);
      };
      for (uint32_t k = 1; k + 1 < n; ++k) {
        const uint32_t a = m.face_indices[c], b = m.face_indices[c + k],
                       d = m.face_indices[c + k + 1];
        edge(a, b), edge(b, d), edge(d, a);
      }
    }
    c += n;
  }
  for (size_t i = 0; i < m.positions.size(); ++i)
    if (used[i]) t.vertices.push_back(m.positions[i]);
  return t;
}

// Number of surface crossings along the ray from p in direction d (odd = inside a closed mesh).
uint32_t crossings(const Scene& ref, Vec3f p, Vec3f d) {
  uint32_t n = 0;
  Ray r;
  r.org = p;
  r.dir = d;
  r.tnear = 0.0f;
  for (int it = 0; it < 100000; ++it) {
    const Hit h = ref.intersect(r);
    if (!h.valid()) break;
    ++n;
    r.tnear = h.t;
  }
  return n;
}

const Vec3f kParityDirs[3] = {
    {0.5377f, 0.8622f, -0.3188f}, {-0.7431f, 0.2016f, 0.6378f}, {0.1347f, -0.5811f, -0.8024f}};

// Inside a closed mesh: an odd number of crossings along 2 of 3 directions (one direction can
// be fooled by a ray through an edge counted twice).
bool is_inside(const Scene& ref, Vec3f p) {
  int odd = 0;
  for (const Vec3f& d : kParityDirs) odd += crossings(ref, p, d) & 1;
  return odd >= 2;
}

std::vector<Vec3f> inside_points(const Scene& ref, const Box3f& box, uint32_t want, uint32_t seed,
                                 uint64_t& tried) {
  std::vector<Vec3f> pts;
  Rng rng(seed, 91);
  const Vec3f lo = box.lo, s = box.size();
  for (tried = 0; pts.size() < want && tried < uint64_t(want) * 200; ++tried) {
    const Vec3f p(lo.x + s.x * (0.02f + 0.96f * rng.uniform()),
                  lo.y + s.y * (0.02f + 0.96f * rng.uniform()),
                  lo.z + s.z * (0.02f + 0.96f * rng.uniform()));
    if (is_inside(ref, p)) pts.push_back(p);
  }
  return pts;
}

// The rays of one run: ray i depends only on (seed, i), so every configuration traces the same.
struct RaySource {
  const std::vector<Vec3f>* inside;
  const Targets* targets;
  uint64_t seed;

  Ray operator()(uint64_t i, uint32_t* origin = nullptr) const {
    Rng rng(seed ^ (i * 0x9E3779B97F4A7C15ULL), 5);
    const uint32_t o = rng.next() % uint32_t(inside->size());
    if (origin) *origin = o;
    const Vec3f org = (*inside)[o];
    Vec3f target;
    const uint32_t kind = uint32_t(i % 3);
    if (kind == 1 && !targets->vertices.empty()) {
      target = targets->vertices[(i / 3 + uint64_t(rng.next()) * 7919) % targets->vertices.size()];
    } else if (kind == 2 && !targets->midpoints.empty()) {
      target =
          targets->midpoints[(i / 3 + uint64_t(rng.next()) * 7919) % targets->midpoints.size()];
    } else {
      // The direction itself, not (org + d) - org: far from the origin org + d rounds to org's
      // spacing (0.25 at 4e6, 64 at 1e9), which would bend or zero the direction.
      Vec3f d;
      do {
        d = Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
      } while (dot(d, d) < 1e-4f);
      Ray r;
      r.org = org;
      r.dir = d;
      r.tnear = 0.0f;
      r.tfar = kInf;
      return r;
    }
    Ray r;
    r.org = org;
    r.dir = target - org;  // not normalized: aimed exactly at the target
    r.tnear = 0.0f;
    r.tfar = kInf;
    return r;
  }
};

// The input's fan triangles in double, for exact point-to-surface distances, indexed by a uniform
// grid of cells so that the question "does a triangle lie within r of p" visits only the
// triangles whose boxes come within r of p: the answer is the brute force's (every triangle whose
// distance to p is at most r has its box within r of p, so it is in a visited cell), at a cost
// that does not grow with the mesh or with the number of points asked about.
struct InputSurface {
  std::vector<std::array<double, 9>> tris;
  double lo[3] = {0, 0, 0};
  double cell = 1;                                  // cell edge, scene units
  int64_t dims[3] = {1, 1, 1};                      // cells per axis
  std::vector<std::pair<uint64_t, uint32_t>> keys;  // (cell key, triangle), sorted by key
  std::vector<uint32_t> large;                      // triangles spanning too many cells: always

  explicit InputSurface(const PolyMesh& m) {
    uint64_t c = 0;
    for (uint32_t n : m.face_sizes) {
      for (uint32_t k = 1; k + 1 < n; ++k) {
        const Vec3f p[3] = {m.positions[m.face_indices[c]], m.positions[m.face_indices[c + k]],
                            m.positions[m.face_indices[c + k + 1]]};
        if (!is_finite(p[0]) || !is_finite(p[1]) || !is_finite(p[2])) continue;
        std::array<double, 9> t;
        for (int j = 0; j < 3; ++j)
          for (int a = 0; a < 3; ++a) t[3 * j + a] = p[j][a];
        tris.push_back(t);
      }
      c += n;
    }
    if (tris.empty()) return;
    // Cell edge: the median of the triangles' largest box extents (most triangles then span at
    // most 2 cells per axis), and at least 2^-20 of the box's largest extent (keys of 21 bits per
    // axis).
    double hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int a = 0; a < 3; ++a) lo[a] = INFINITY;
    std::vector<double> extent(tris.size());
    for (size_t i = 0; i < tris.size(); ++i) {
      double e = 0;
      for (int a = 0; a < 3; ++a) {
        const double mn = std::min({tris[i][a], tris[i][3 + a], tris[i][6 + a]});
        const double mx = std::max({tris[i][a], tris[i][3 + a], tris[i][6 + a]});
        lo[a] = std::min(lo[a], mn), hi[a] = std::max(hi[a], mx), e = std::max(e, mx - mn);
      }
      extent[i] = e;
    }
    std::nth_element(extent.begin(), extent.begin() + extent.size() / 2, extent.end());
    const double span = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    cell = std::max(extent[extent.size() / 2], std::ldexp(span, -20));
    if (!(cell > 0)) cell = 1;  // every triangle is one point
    for (int a = 0; a < 3; ++a)
      dims[a] = std::min<int64_t>(int64_t(std::floor((hi[a] - lo[a]) / cell)) + 1, 1 << 21);
    constexpr int64_t kMaxCells = 512;  // a triangle over more cells is tested for every point
    for (size_t i = 0; i < tris.size(); ++i) {
      int64_t c0[3], c1[3];
      int64_t count = 1;
      for (int a = 0; a < 3; ++a) {
        c0[a] = cell_of(a, std::min({tris[i][a], tris[i][3 + a], tris[i][6 + a]}));
        c1[a] = cell_of(a, std::max({tris[i][a], tris[i][3 + a], tris[i][6 + a]}));
        count *= c1[a] - c0[a] + 1;
      }
      if (count > kMaxCells) {
        large.push_back(uint32_t(i));
        continue;
      }
      for (int64_t z = c0[2]; z <= c1[2]; ++z)
        for (int64_t y = c0[1]; y <= c1[1]; ++y)
          for (int64_t x = c0[0]; x <= c1[0]; ++x) keys.emplace_back(key(x, y, z), uint32_t(i));
    }
    std::sort(keys.begin(), keys.end());
  }

  // The cell of coordinate v along axis a, clamped to the grid.
  int64_t cell_of(int a, double v) const {
    const double f = std::floor((v - lo[a]) / cell);
    if (!(f >= 0)) return 0;  // below the grid, or NaN
    return int64_t(std::min(f, double(dims[a] - 1)));
  }
  static uint64_t key(int64_t x, int64_t y, int64_t z) {
    return uint64_t(z) << 42 | uint64_t(y) << 21 | uint64_t(x);
  }

  static double segment(const double p[3], const double* a, const double* b) {
    double ab[3], ap[3];
    for (int k = 0; k < 3; ++k) ab[k] = b[k] - a[k], ap[k] = p[k] - a[k];
    const double l2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
    const double s =
        l2 > 0 ? std::clamp((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / l2, 0.0, 1.0) : 0.0;
    double d2 = 0;
    for (int k = 0; k < 3; ++k) d2 += (ap[k] - s * ab[k]) * (ap[k] - s * ab[k]);
    return d2;
  }

  // Squared distance from p to one triangle (Ericson, "Real-Time Collision Detection", 5.1.5).
  static double triangle2(const double p[3], const std::array<double, 9>& t) {
    const double* a = &t[0];
    double e1[3], e2[3], w[3];
    for (int k = 0; k < 3; ++k)
      e1[k] = t[3 + k] - a[k], e2[k] = t[6 + k] - a[k], w[k] = p[k] - a[k];
    const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                         e1[0] * e2[1] - e1[1] * e2[0]};
    const double n2 = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
    if (n2 > 0) {
      const double d11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2];
      const double d12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2];
      const double d22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
      const double w1 = w[0] * e1[0] + w[1] * e1[1] + w[2] * e1[2];
      const double w2 = w[0] * e2[0] + w[1] * e2[1] + w[2] * e2[2];
      const double den = d11 * d22 - d12 * d12;
      const double u = (d22 * w1 - d12 * w2) / den, v = (d11 * w2 - d12 * w1) / den;
      if (u >= 0 && v >= 0 && u + v <= 1) {
        const double h = w[0] * n[0] + w[1] * n[1] + w[2] * n[2];
        return h * h / n2;
      }
    }
    return std::min({segment(p, &t[0], &t[3]), segment(p, &t[3], &t[6]), segment(p, &t[6], &t[0])});
  }

  // Whether some input triangle lies within distance r of p (double precision), as a brute force
  // over every triangle would say: the triangles of the cells that [p - r, p + r] overlaps and the
  // large ones.
  bool within(const double p[3], double r) const {
    const double r2 = r * r;
    for (uint32_t i : large)
      if (triangle2(p, tris[i]) <= r2) return true;
    if (keys.empty()) return false;
    int64_t c0[3], c1[3];
    double cells = 1;
    for (int a = 0; a < 3; ++a) {
      c0[a] = cell_of(a, p[a] - r);
      c1[a] = cell_of(a, p[a] + r);
      cells *= double(c1[a] - c0[a] + 1);
    }
    if (cells > double(tris.size())) {  // r spans more cells than there are triangles
      for (const auto& t : tris)
        if (triangle2(p, t) <= r2) return true;
      return false;
    }
    for (int64_t z = c0[2]; z <= c1[2]; ++z)
      for (int64_t y = c0[1]; y <= c1[1]; ++y)
        for (int64_t x = c0[0]; x <= c1[0]; ++x) {
          const uint64_t k = key(x, y, z);
          auto it = std::lower_bound(keys.begin(), keys.end(), std::make_pair(k, uint32_t(0)));
          for (; it != keys.end() && it->first == k; ++it)
            if (triangle2(p, tris[it->second]) <= r2) return true;
        }
    return false;
  }
};

struct Row {
  std::string config, status, note;
  uint64_t rays = 0, leaks = 0, occluded_leaks = 0, far = 0, near = 0;
  double error_bound = 0;      // e (scene units); 0 for lossless
  double max_excess = 0;       // largest |t - t_ref| * |dir| among hits, scene units
  bool own_reference = false;  // t_ref from the format's decoded triangles
  uint64_t beyond_bound = 0;   // lossy: hits farther than e / |cos| from the input crossing
  uint64_t excused = 0;        //   of them, excused by the geometry (see the header comment)
  uint64_t beyond_random = 0;  //   of the others, rays in random directions (not aimed)
  double max_input_dev = 0;    // lossy: largest |t - t_input| * |dir|
  double build_s = 0, trace_s = 0;
  bool failed = false;
};

struct Counts {
  uint64_t leaks = 0, occluded_leaks = 0, far = 0, near = 0, beyond_bound = 0;
  uint64_t skipped = 0;
  double max_excess = -INFINITY, max_input_dev = 0;
  uint64_t first_bad = UINT64_MAX;  // smallest ray index with a problem, to reproduce it
  std::vector<std::pair<uint64_t, float>> beyond;  // lossy: (ray, t) beyond e / |cos|
};

}  // namespace

int cmd_verify(int argc, char** argv) {
  CLI::App app{"Watertightness and hit-distance checks of every configuration on a closed mesh.",
               "slimrt verify"};
  std::string scene_name;
  std::vector<std::string> configs;
  uint64_t rays = 1000000;
  BuildOptions tuning;
  uint64_t seed = 1;
  bool allow_open = false;
  int64_t explain = -1;
  uint64_t check_chunk = uint64_t(1) << 22;
  double bound_scale = 1.0;
  app.add_option("scene", scene_name,
                 "closed mesh: a file (.obj .ply .gltf .glb, optionally .xz), torus:N, or sphere:L "
                 "(jittered icosphere, 20*4^L triangles)")
      ->required();
  app.add_option("--config", configs,
                 "configurations (repeatable or comma-separated); default: all_config_names()")
      ->delimiter(',');
  app.add_option("--rays", rays,
                 "rays per configuration (1/3 random, 1/3 at vertices, 1/3 at "
                 "edge midpoints)")
      ->check(CLI::Range(uint64_t(3), uint64_t(1) << 40))
      ->capture_default_str();
  add_build_options(app, tuning);  // the configurations checked; the reference keeps its own
  app.add_option("--seed", seed, "seed of the rays and inside points")->capture_default_str();
  app.add_flag("--allow-open", allow_open, "run even if the mesh has boundary/non-manifold edges");
  app.add_option("--explain", explain,
                 "print ray number I (as in 'first bad ray #I') and every configuration's hit");
  app.add_option("--check-chunk", check_chunk,
                 "rays traced before their lossy hits beyond the bound are checked against the "
                 "input surface (every one is; this bounds the memory they take)")
      ->check(CLI::Range(uint64_t(1), uint64_t(1) << 40))
      ->capture_default_str();
  app.add_option("--bound-scale", bound_scale,
                 "multiplies every lossy format's promised bound e (below 1: a test of the "
                 "check itself, which a correct lossy scene then fails)")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  {
    // t_ref, cos_ref and a format's own reference: 12 bytes per ray held at once.
    constexpr uint64_t kBytesPerRay = 12;
    const uint64_t budget = memory_budget();
    if (rays > budget / kBytesPerRay)
      throw Error("--rays " + std::to_string(rays) + " needs about " +
                  format_bytes(rays * kBytesPerRay) + " for the reference hits (" +
                  std::to_string(kBytesPerRay) + " bytes per ray); expected at most " +
                  std::to_string(budget / kBytesPerRay) + " rays, the memory limit being " +
                  format_bytes(budget) + " (half of this machine's memory)");
  }
  if (is_scene_file(scene_name))
    throw Error(scene_name +
                ": verify compares each configuration with a brute force over the "
                "input mesh, which a scene file does not hold; give the mesh, or check the file "
                "with `slimrt info " +
                scene_name + "` (validate: every invariant of the scene)");
  if (configs.empty()) configs = all_config_names();
  for (const std::string& c : configs) build_options(c, tuning);  // unknown names: error now
  const int threads = tuning.threads;

  tbb::task_arena arena(threads > 0 ? threads : tbb::task_arena::automatic);
  const auto t_load = std::chrono::steady_clock::now();
  const PolyMesh mesh =
      out_of_memory_context("loading " + scene_name, [&] { return load_scene(scene_name); });
  const MeshSummary sum = summarize(mesh);
  const Closedness cl = closedness(mesh);
  std::printf(
      "scene %s: %llu vertices, %llu faces, %llu fan triangles, %llu edges "
      "(%llu boundary, %llu non-manifold), loaded in %.2f s\n",
      scene_name.c_str(), (unsigned long long)sum.vertices, (unsigned long long)sum.faces,
      (unsigned long long)sum.fan_triangles, (unsigned long long)cl.edges,
      (unsigned long long)cl.boundary, (unsigned long long)cl.nonmanifold, seconds_since(t_load));
  if ((cl.boundary || cl.nonmanifold || cl.edges == 0) && !allow_open) {
    std::fprintf(stderr,
                 "slimrt verify: %s is not a closed manifold mesh (%llu boundary, %llu "
                 "non-manifold edges): rays from inside can leave through its holes. Use "
                 "--allow-open to run anyway.\n",
                 scene_name.c_str(), (unsigned long long)cl.boundary,
                 (unsigned long long)cl.nonmanifold);
    return 2;
  }

  BuildOptions ref_opt = BuildOptions::from_config("bvh8-tri4v");
  ref_opt.threads = threads;
  Scene ref;
  out_of_memory_context("building the bvh8-tri4v reference of " + scene_name,
                        [&] { arena.execute([&] { ref = Scene::build(mesh, ref_opt); }); });
  const Box3f box = mesh.bounds();
  const double diag = length(box.size());
  uint64_t tried = 0;
  std::vector<Vec3f> inside;
  arena.execute([&] { inside = inside_points(ref, box, 4096, uint32_t(seed), tried); });
  if (inside.size() < 16) {
    std::fprintf(stderr, "slimrt verify: found %zu points inside %s in %llu tries: is it closed?\n",
                 inside.size(), scene_name.c_str(), (unsigned long long)tried);
    return 2;
  }
  const Targets targets = make_targets(mesh);
  const InputSurface surface(mesh);
  const RaySource source{&inside, &targets, seed * 0xD1B54A32D192ED03ULL + 1};
  std::printf(
      "rays per configuration: %llu (%llu random, %llu at %zu vertices, %llu at %zu edge "
      "midpoints), from %zu inside points (%llu sampled)\n",
      (unsigned long long)rays, (unsigned long long)((rays + 2) / 3),
      (unsigned long long)((rays + 1) / 3), targets.vertices.size(), (unsigned long long)(rays / 3),
      targets.midpoints.size(), inside.size(), (unsigned long long)tried);

  // Reference: t (in ray units) and |cos theta| at the first crossing of the input surface.
  std::vector<float> t_ref, cos_ref;
  out_of_memory_context("allocating the reference hits of " + std::to_string(rays) + " rays", [&] {
    t_ref.resize(rays);
    cos_ref.resize(rays);
  });
  const auto t_ref0 = std::chrono::steady_clock::now();
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<uint64_t>(0, rays, 4096), [&](const auto& r) {
      for (uint64_t i = r.begin(); i < r.end(); ++i) {
        const Ray ray = source(i);
        const Hit h = ref.intersect(ray);
        t_ref[i] = h.valid() ? h.t : kInf;
        const float ln = length(h.Ng) * length(ray.dir);
        cos_ref[i] = h.valid() && ln > 0 ? std::fabs(dot(h.Ng, ray.dir)) / ln : 1.0f;
      }
    });
  });
  std::printf("reference bvh8-tri4v: %.2f s\n\n", seconds_since(t_ref0));

  std::vector<Row> table;
  bool any_failed = false;
  for (const std::string& name : configs) {
    Row row;
    row.config = name;
    std::fprintf(stderr, "verify %s: %s ...", scene_name.c_str(), name.c_str());
    std::fflush(stderr);
    const BuildOptions opt = build_options(name, tuning);
    Scene s;
    const auto t_build = std::chrono::steady_clock::now();
    try {
      out_of_memory_context("building " + scene_name + " as " + name,
                            [&] { arena.execute([&] { s = Scene::build(mesh, opt); }); });
    } catch (const NotApplicable& e) {
      row.status = "n/a";
      row.note = e.what();
    } catch (const Error& e) {
      row.status = "BUILD ERROR";
      row.note = e.what();
      row.failed = true;
    }
    if (!row.status.empty()) {
      std::fprintf(stderr, " %s\n", row.status.c_str());
      any_failed |= row.failed;
      table.push_back(row);
      continue;
    }
    row.build_s = seconds_since(t_build);
    std::string why;
    if (!s.validate(&why)) {
      row.failed = true;
      row.note = "validate(): " + why;
    }
    const bool lossy = s.is_lossy();
    if (lossy) {
      // The bound the registry row promises (ConfigInfo::promised_error).
      try {
        row.error_bound = describe(opt).promised_error({&mesh}) * bound_scale;
      } catch (const Error& err) {
        row.failed = true;
        row.note = std::string("lossy, but its registry row promises no bound: ") + err.what();
        row.error_bound = 0;
      }
    }
    const double e = row.error_bound;

    // Formats that store their own triangles (grids, costa) are held to the first crossing of
    // their decoded geometry; the others share the input's triangles.
    const std::vector<float>* tref = &t_ref;
    std::vector<float> t_own;
    // Origins that are inside the input but not inside the decoded surface (closer to the
    // surface than the format's error) cannot expect a hit: their rays are skipped.
    std::vector<char> origin_ok(inside.size(), 1);
    if (const std::optional<DecodedTriangles> decoded = decoded_triangles(s, {&mesh})) {
      try {
        const PolyMesh own = to_mesh(*decoded);
        Scene own_ref;
        arena.execute([&] {
          own_ref = Scene::build(own, ref_opt);
          tbb::parallel_for(size_t(0), inside.size(),
                            [&](size_t k) { origin_ok[k] = is_inside(own_ref, inside[k]); });
          t_own.resize(rays);
          tbb::parallel_for(tbb::blocked_range<uint64_t>(0, rays, 4096), [&](const auto& r) {
            for (uint64_t i = r.begin(); i < r.end(); ++i) {
              const Hit h = own_ref.intersect(source(i));
              t_own[i] = h.valid() ? h.t : kInf;
            }
          });
        });
        tref = &t_own;
        row.own_reference = true;
      } catch (const Error& err) {
        row.note = std::string("decoded geometry unavailable (") + err.what() +
                   "): checked against the input with the error bound";
      }
    }
    if (explain >= 0 && uint64_t(explain) < rays) {
      const Ray r = source(uint64_t(explain));
      const Hit h = s.intersect(r);
      std::printf(
          "ray #%lld org (%a, %a, %a) dir (%a, %a, %a): input t %.9g |cos| %.4f; "
          "%s: own reference t %.9g, hit t %.9g face %u, occluded %d\n",
          (long long)explain, r.org.x, r.org.y, r.org.z, r.dir.x, r.dir.y, r.dir.z, t_ref[explain],
          cos_ref[explain], name.c_str(), (*tref)[explain], h.t, h.primID, int(s.occluded(r)));
    }
    // Against the own reference (or the input for formats without decoded triangles): rounding
    // only (plus e / |cos theta| for a lossy format without decoded triangles). Against the
    // input, lossy formats: the promised bound e / |cos theta| (header comment), always.
    const bool bound_is_hard = lossy && !row.own_reference;
    // A lossy hit beyond e / |cos| of the input crossing, excused where the geometry allows it
    // (header comment); the distances to the input surface are exact (InputSurface::within).
    auto excused = [&](uint64_t i, float t) {
      const Ray ray = source(i);
      const double len = length(ray.dir);
      const double tol = 1e-5 * double(t_ref[i]) * len + 1e-6 * diag;
      double p[3];
      for (int a = 0; a < 3; ++a) p[a] = double(ray.org[a]) + double(t) * double(ray.dir[a]);
      if (!surface.within(p, e + tol)) return false;
      if (t < t_ref[i]) return true;  // nearer: the decoded surface within e of the input
      // Farther: the ray ran along the surface in between (grazing), or skipped a crossing
      // pair that dips under the input surface by less than 2e.
      auto near_surface_at = [&](double tm) {
        for (int a = 0; a < 3; ++a) p[a] = double(ray.org[a]) + tm * double(ray.dir[a]);
        return surface.within(p, 2 * e + tol);
      };
      if (near_surface_at(0.5 * (double(t_ref[i]) + double(t)))) return true;
      Ray r2 = ray;
      r2.tnear = t_ref[i];
      const Hit next = ref.intersect(r2);
      if (next.valid() && near_surface_at(0.5 * (double(t_ref[i]) + double(next.t)))) return true;
      // A ray aimed at a vertex or edge may only touch the input there (a saddle, a fold):
      // it is still inside 4e past t_ref, and the decoded surface need not be touched.
      const double ta = double(t_ref[i]) + (4 * e + tol) / len;
      const Vec3f after(float(ray.org.x + ta * ray.dir.x), float(ray.org.y + ta * ray.dir.y),
                        float(ray.org.z + ta * ray.dir.z));
      return is_inside(ref, after);
    };
    // The rays in chunks of check_chunk: each chunk's lossy hits beyond e / |cos| are all checked
    // before the next chunk is traced, so the memory they take is bounded whatever the ray count
    // and none goes unchecked.
    tbb::enumerable_thread_specific<Counts> tls;
    uint64_t first_unexcused = UINT64_MAX;
    std::vector<std::pair<uint64_t, float>> beyond;
    std::vector<char> ok;
    const auto t_trace = std::chrono::steady_clock::now();
    for (uint64_t r0 = 0; r0 < rays; r0 += check_chunk) {
      const uint64_t r1 = std::min(rays, r0 + std::min(check_chunk, rays - r0));
      arena.execute([&] {
        tbb::parallel_for(tbb::blocked_range<uint64_t>(r0, r1, 4096), [&](const auto& r) {
          Counts& c = tls.local();
          for (uint64_t i = r.begin(); i < r.end(); ++i) {
            uint32_t origin;
            const Ray ray = source(i, &origin);
            if (!origin_ok[origin]) {
              c.skipped++;
              continue;
            }
            const Hit h = s.intersect(ray);
            const bool occ = s.occluded(ray);
            bool bad = false;
            if (!h.valid()) c.leaks++, bad = true;
            if (!occ) c.occluded_leaks++, bad = true;
            const double len = length(ray.dir);
            const float tr = (*tref)[i];
            if (h.valid() && std::isfinite(tr)) {
              const double excess = (double(h.t) - double(tr)) * len;
              const double tol = 1e-5 * double(tr) * len + 1e-6 * diag +
                                 (bound_is_hard ? e / std::max(double(cos_ref[i]), 0.05) : 0.0);
              c.max_excess = std::max(c.max_excess, std::fabs(excess));
              if (excess > tol) c.far++, bad = true;
              if (excess < -tol) c.near++, bad = true;
            }
            if (lossy && h.valid() && std::isfinite(t_ref[i])) {
              const double dev = std::fabs(double(h.t) - double(t_ref[i])) * len;
              c.max_input_dev = std::max(c.max_input_dev, dev);
              if (dev > 1e-5 * double(t_ref[i]) * len + 1e-6 * diag +
                            e / std::max(double(cos_ref[i]), 0.05))
                c.beyond_bound++, c.beyond.emplace_back(i, h.t);
            }
            if (bad) c.first_bad = std::min(c.first_bad, i);
          }
        });
      });
      beyond.clear();
      for (Counts& c : tls) {
        beyond.insert(beyond.end(), c.beyond.begin(), c.beyond.end());
        c.beyond.clear();
      }
      if (beyond.empty()) continue;
      ok.assign(beyond.size(), 0);
      arena.execute([&] {
        tbb::parallel_for(size_t(0), beyond.size(),
                          [&](size_t k) { ok[k] = excused(beyond[k].first, beyond[k].second); });
      });
      for (size_t k = 0; k < beyond.size(); ++k) {
        if (ok[k]) {
          row.excused++;
          continue;
        }
        row.beyond_random += beyond[k].first % 3 == 0;
        first_unexcused = std::min(first_unexcused, beyond[k].first);
      }
    }
    row.trace_s = seconds_since(t_trace);
    Counts total;
    for (const Counts& c : tls) {
      total.leaks += c.leaks;
      total.occluded_leaks += c.occluded_leaks;
      total.far += c.far;
      total.near += c.near;
      total.max_excess = std::max(total.max_excess, c.max_excess);
      total.beyond_bound += c.beyond_bound;
      total.skipped += c.skipped;
      total.max_input_dev = std::max(total.max_input_dev, c.max_input_dev);
      total.first_bad = std::min(total.first_bad, c.first_bad);
    }
    row.rays = rays - total.skipped;
    if (total.skipped) {
      const size_t outside = size_t(std::count(origin_ok.begin(), origin_ok.end(), 0));
      row.note += (row.note.empty() ? "" : "; ") + std::to_string(total.skipped) + " rays from " +
                  std::to_string(outside) + " origins outside the decoded surface skipped";
    }
    row.leaks = total.leaks;
    row.occluded_leaks = total.occluded_leaks;
    row.far = total.far;
    row.near = total.near;
    row.max_excess = std::isfinite(total.max_excess) ? total.max_excess : 0.0;
    row.beyond_bound = total.beyond_bound;
    row.max_input_dev = total.max_input_dev;
    if (row.beyond_bound > row.excused) {
      row.failed = true;
      total.first_bad = std::min(total.first_bad, first_unexcused);
    }
    if (row.leaks || row.occluded_leaks || row.far || row.near) row.failed = true;
    if (total.first_bad != UINT64_MAX) {
      const Ray r = source(total.first_bad);
      char buf[256];
      std::snprintf(buf, sizeof buf, "first bad ray #%llu: org (%a, %a, %a) dir (%a, %a, %a)",
                    (unsigned long long)total.first_bad, r.org.x, r.org.y, r.org.z, r.dir.x,
                    r.dir.y, r.dir.z);
      row.note += (row.note.empty() ? "" : "; ") + std::string(buf);
    }
    row.status = row.failed ? "FAIL" : "ok";
    any_failed |= row.failed;
    std::fprintf(stderr, " %s (build %.2f s, rays %.2f s)\n", row.status.c_str(), row.build_s,
                 row.trace_s);
    table.push_back(row);
  }

  std::printf(
      "| config | rays | leaks (intersect) | leaks (occluded) | far | near | max |t - t_ref| "
      "| reference | lossy: promised e | lossy: beyond e/cos, excused (max dev.) | status |\n");
  std::printf("| --- | ---: | ---: | ---: | ---: | ---: | ---: | --- | ---: | ---: | --- |\n");
  for (const Row& r : table) {
    if (r.status == "n/a" || r.status == "BUILD ERROR") {
      std::printf("| %s | - | - | - | - | - | - | - | - | - | %s: %s |\n", r.config.c_str(),
                  r.status.c_str(), r.note.c_str());
      continue;
    }
    char bound[32] = "-", beyond[96] = "-";
    if (r.error_bound > 0) {
      std::snprintf(bound, sizeof bound, "%.3g", r.error_bound);
      std::snprintf(beyond, sizeof beyond, "%llu, %llu excused, %llu random (%.3g)",
                    (unsigned long long)r.beyond_bound, (unsigned long long)r.excused,
                    (unsigned long long)r.beyond_random, r.max_input_dev);
    }
    std::printf("| %s | %llu | %llu | %llu | %llu | %llu | %.3g | %s | %s | %s | %s%s%s |\n",
                r.config.c_str(), (unsigned long long)r.rays, (unsigned long long)r.leaks,
                (unsigned long long)r.occluded_leaks, (unsigned long long)r.far,
                (unsigned long long)r.near, r.max_excess, r.own_reference ? "own decoded" : "input",
                bound, beyond, r.status.c_str(), r.note.empty() ? "" : ": ", r.note.c_str());
  }
  std::printf("\nbox diagonal %.6g; distances are |t - t_ref| * |dir| in scene units; %s\n", diag,
              any_failed ? "FAILED" : "no leaks, every hit within its bound");
  return any_failed ? 1 : 0;
}

}  // namespace slim::cli
