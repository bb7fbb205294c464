// The error each lossy registry row promises (ConfigInfo::promised_error, the bound `slimrt
// verify` holds the format to) covers what the format does on real meshes: the vertex error the
// build measures, the decoded vertices' distance to their input faces, and the distance of every
// hit to the input face it reports.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "slimrt/analysis.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// The corners of face f of m, in double.
std::vector<std::array<double, 3>> corners(const PolyMesh& m, uint32_t f,
                                           const std::vector<uint64_t>& first) {
  std::vector<std::array<double, 3>> c;
  for (uint32_t k = 0; k < m.face_sizes[f]; ++k) {
    const Vec3f p = m.positions[m.face_indices[first[f] + k]];
    c.push_back({double(p.x), double(p.y), double(p.z)});
  }
  return c;
}

double det3(const double a[3], const double b[3], const double c[3], const double d[3]) {
  double u[3], v[3], w[3];
  for (int k = 0; k < 3; ++k) u[k] = b[k] - a[k], v[k] = c[k] - a[k], w[k] = d[k] - a[k];
  return u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) +
         u[2] * (v[0] * w[1] - v[1] * w[0]);
}

// Distance from p to the convex hull of a face of 3 or 4 corners: 0 inside the tetrahedron of 4
// corners, else the distance to the nearest triangle of 3 corners. A hit on a decoded triangle
// whose vertices lie within e of the face's corners lies within e of this hull.
double hull_distance(const std::vector<std::array<double, 3>>& c, const double p[3]) {
  auto tri = [&](int i, int j, int k) {
    RefTri t;
    for (int a = 0; a < 3; ++a) t.v[0][a] = c[i][a], t.v[1][a] = c[j][a], t.v[2][a] = c[k][a];
    return triangle_distance(t, p);
  };
  if (c.size() == 3) return tri(0, 1, 2);
  const double* q[4] = {c[0].data(), c[1].data(), c[2].data(), c[3].data()};
  const double vol = det3(q[0], q[1], q[2], q[3]);
  if (vol != 0) {
    const double s[4] = {det3(p, q[1], q[2], q[3]), det3(q[0], p, q[2], q[3]),
                         det3(q[0], q[1], p, q[3]), det3(q[0], q[1], q[2], p)};
    bool inside = true;
    for (double x : s) inside = inside && (x == 0 || (x > 0) == (vol > 0));
    if (inside) return 0;
  }
  return std::min({tri(0, 1, 2), tri(0, 1, 3), tri(0, 2, 3), tri(1, 2, 3)});
}

struct Measured {
  double build = 0;     // Scene::error_bound(): measured at build
  double vertices = 0;  // decoded vertices: distance to the nearest corner of their input face
  double hits = 0;      // hit points: distance to the hull of the face they report
  uint64_t hit_count = 0;
};

Measured measure(const PolyMesh& m, const BuildOptions& opt) {
  Measured r;
  const Scene s = Scene::build(m, opt);
  r.build = s.error_bound();
  std::vector<uint64_t> first(m.face_sizes.size());
  for (size_t f = 0, c = 0; f < m.face_sizes.size(); c += m.face_sizes[f], ++f) first[f] = c;
  if (const auto t = decoded_triangles(s, {&m})) {
    for (size_t i = 0; i < t->size(); ++i) {
      const auto c = corners(m, t->face[i], first);
      for (int k = 0; k < 3; ++k) {
        const Vec3f p = t->vertices[3 * i + k];
        double best = INFINITY;
        for (const auto& q : c)
          best =
              std::min(best, std::sqrt((p.x - q[0]) * (p.x - q[0]) + (p.y - q[1]) * (p.y - q[1]) +
                                       (p.z - q[2]) * (p.z - q[2])));
        r.vertices = std::max(r.vertices, best);
      }
    }
  }
  // Primary rays of the benchmark camera, 96 x 96.
  const Camera cam = frame_box(m.bounds(), 96, 96);
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 96; ++x) {
      const Ray ray = camera_ray(cam, float(x) + 0.5f, float(y) + 0.5f);
      const Hit h = s.intersect(ray);
      if (!h.valid() || m.face_sizes[h.primID] > 4) continue;
      double p[3];
      point_on_ray(ray, h.t, p);
      r.hits = std::max(r.hits, hull_distance(corners(m, h.primID, first), p));
      r.hit_count++;
    }
  return r;
}

}  // namespace

// Every lossy row, built on real meshes (a quad mesh: every format forms grids; a triangle scan):
// each measured error is within the promise, and the promise is not vacuous (within 1000x the
// error measured at build, when the build measured any).
TEST(Registry, PromisedErrorCoversTheMeasuredError) {
  const std::string quads = shared_data_dir() + "/spot_quadrangulated.obj";
  const std::string scan = shared_data_dir() + "/stanford_bunny.obj.xz";
  SLIM_REQUIRE_SHARED_FILE(quads);
  SLIM_REQUIRE_SHARED_FILE(scan);
  int checked = 0;
  for (const std::string& file : {quads, scan}) {
    const PolyMesh m = load(file);
    const double diag = length(m.bounds().size());
    // Rounding of a hit point: t and the ray's float origin and direction.
    const double hit_tol = 1e-6 * diag;
    for (const ConfigInfo& c : configs()) {
      const double promised = c.promised_error({&m});
      if (!c.lossy) {
        EXPECT_EQ(promised, 0.0) << c.name;
        continue;
      }
      SCOPED_TRACE(c.name + " on " + file);
      const Measured got = measure(m, c.options);
      EXPECT_GT(promised, 0.0);
      EXPECT_LE(got.build, promised);
      EXPECT_LE(got.vertices, promised);
      EXPECT_LE(got.hits, promised + hit_tol);
      EXPECT_GT(got.hit_count, 1000u);
      if (got.build > 0) {
        EXPECT_LE(promised, 1000 * got.build);
      }
      std::printf("%-20s %-24s promised %.4g  build %.4g  vertices %.4g  hits %.4g (%llu)\n",
                  c.name.c_str(), file.substr(file.rfind('/') + 1).c_str(), promised, got.build,
                  got.vertices, got.hits, (unsigned long long)got.hit_count);
      ++checked;
    }
  }
  EXPECT_GE(checked, 2 * 13);
  // The promise follows the options: a finer cluster error promises less.
  const PolyMesh t = make_terrain(16);
  ConfigInfo cluster = config_info("cluster");
  const double coarse = cluster.promised_error({&t});
  cluster.options.cluster_error /= 16;
  EXPECT_LT(cluster.promised_error({&t}), coarse / 8);
  EXPECT_LE(Scene::build(t, cluster.options).error_bound(), cluster.promised_error({&t}));
}
