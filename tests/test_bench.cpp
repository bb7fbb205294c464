// The benchmark instrument: the Embree adapter against slimrt, the interleaved rounds and
// their statistics, and `slimrt bench --json` against the schema of docs/benchmark.md. No test
// asserts a timing.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "bench_json.h"
#include "bench_markdown.h"
#include "bench_runner.h"
#include "bench_stats.h"
#include "embree_scene.h"
#include "slimrt/pairing.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;
using slim::bench::EmbreeScene;

namespace {

struct Comparison {
  uint64_t rays = 0, agree = 0, both_hit = 0, same_face = 0, same_geom = 0;
  struct Mismatch {
    Ray ray;
    Hit a, b;
  };
  std::vector<Mismatch> other_face;  // both hit, on different faces
};

template <class A, class B>
void compare_ray(const A& a, const B& b, const Ray& r, Comparison& c) {
  const Hit ha = a.intersect(r), hb = b.intersect(r);
  c.rays++;
  c.agree += bench::hits_agree(ha, hb);
  if (ha.valid() && hb.valid()) {
    c.both_hit++;
    const bool same = ha.geomID == hb.geomID && ha.primID == hb.primID;
    c.same_face += same;
    if (!same) c.other_face.push_back({r, ha, hb});
    c.same_geom += ha.geomID == hb.geomID;
  }
  EXPECT_EQ(a.occluded(r), ha.valid());
}

// Random rays around the box plus the benchmark camera's rays at res x res.
template <class A, class B>
Comparison compare(const A& a, const B& b, const Box3f& box, int random_rays, int res) {
  Comparison c;
  Rng rng(11);
  for (int i = 0; i < random_rays; ++i) compare_ray(a, b, random_ray(rng, box), c);
  const Camera cam = frame_box(box, res, res);
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x)
      compare_ray(a, b, camera_ray(cam, float(x) + 0.5f, float(y) + 0.5f), c);
  return c;
}

std::vector<const PolyMesh*> ptrs(const PolyMesh& m) { return {&m}; }

// Where the two name different faces, a tie checked geometrically on the input's fan triangles
// `tris`: both hits at the same t (hits_agree) and each hit point on an edge or vertex the two
// faces share (within tie_delta of the boundary of one face's triangles and of the other face,
// both ways round).
bool is_tie(const std::vector<RefTri>& tris, const Comparison::Mismatch& x) {
  auto on_shared_edge = [&](const Hit& a, const Hit& b) {
    RefHit ra;
    ra.t = a.t;
    ra.geom = a.geomID;
    ra.prim = a.primID;
    return is_geometric_tie(tris, x.ray, ra, b.geomID, b.primID, tie_delta(x.ray, a.t));
  };
  return bench::hits_agree(x.a, x.b) && on_shared_edge(x.a, x.b) && on_shared_edge(x.b, x.a);
}

// The hits on different faces that are not ties (each reported, the first 5 in full).
size_t count_non_ties(const std::vector<RefTri>& tris, const std::string& what,
                      const Comparison& c) {
  size_t not_ties = 0;
  for (const Comparison::Mismatch& x : c.other_face)
    if (!is_tie(tris, x) && ++not_ties <= 5)
      ADD_FAILURE() << what << ": Embree face " << x.a.geomID << "/" << x.a.primID << " at t "
                    << x.a.t << ", slimrt face " << x.b.geomID << "/" << x.b.primID << " at t "
                    << x.b.t << " is not a tie (ray org " << x.ray.org.x << " " << x.ray.org.y
                    << " " << x.ray.org.z << ")";
  return not_ties;
}

}  // namespace

TEST(BenchEmbree, TriangleHitsMatchSlimrtOnRandomSoup) {
  PolyMesh m = random_soup(4000, 5);
  EmbreeScene e(ptrs(m), "embree-tri");
  Scene s = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
  Comparison c = compare(e, s, m.bounds(), 20000, 128);
  EXPECT_GT(c.both_hit, 5000u);
  // A soup has no shared edges: every hit names the same face at the same t.
  EXPECT_EQ(c.agree, c.rays);
  EXPECT_EQ(c.same_face, c.both_hit);
}

TEST(BenchEmbree, TriangleHitsMatchSlimrtOnTerrain) {
  PolyMesh m = make_terrain(64);
  const std::vector<RefTri> tris = reference_triangles(ptrs(m));
  // Rays from above aimed exactly at vertices and at edge midpoints, where ties happen.
  std::vector<Vec3f> targets(m.positions.begin(), m.positions.end());
  for (size_t f = 0; f < m.face_sizes.size(); ++f) {
    ASSERT_EQ(m.face_sizes[f], 4u);
    const uint32_t* q = &m.face_indices[4 * f];
    for (int k = 0; k < 4; ++k)
      targets.push_back((m.positions[q[k]] + m.positions[q[(k + 1) % 4]]) * 0.5f);
    targets.push_back((m.positions[q[0]] + m.positions[q[2]]) * 0.5f);  // fan diagonal
  }
  const Box3f box = m.bounds();
  // Interior targets only: a ray aimed at the mesh's border may pass beside it.
  targets.erase(std::remove_if(targets.begin(), targets.end(),
                               [&](const Vec3f& p) {
                                 return p.x <= box.lo.x || p.x >= box.hi.x || p.y <= box.lo.y ||
                                        p.y >= box.hi.y;
                               }),
                targets.end());
  for (const char* config : {"embree-tri", "embree-tri-compact"}) {
    EmbreeScene e(ptrs(m), config);
    Scene s = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
    Comparison c = compare(e, s, box, 20000, 256);
    EXPECT_GT(c.both_hit, 30000u) << config;
    // Embree's default triangle test is not watertight: a ray through a shared edge may slip
    // between two triangles (about one camera ray in a million on terrain:64 at 1024 x 1024).
    EXPECT_LE(c.rays - c.agree, c.rays / 10000) << config;
    // Random and camera rays: the same face but for rare ties.
    EXPECT_LE(c.other_face.size(), c.both_hit / 1000) << config;
    EXPECT_EQ(count_non_ties(tris, config, c), 0u) << config << ": of " << c.other_face.size();
    // Aimed rays: steep rays from above (at most ~3 degrees off the vertical, so that they cross
    // the heightfield at the target instead of grazing it) aimed exactly at vertices and edge
    // midpoints, where ties happen. slimrt reaches every target; where Embree's test (not
    // watertight) lets a ray slip through, the two disagree on t: not a face question, counted
    // apart.
    Comparison aimed;
    Rng rng(23);
    const float h = box.size().z + 1.0f;
    for (size_t i = 0; i < targets.size(); i += 3) {
      Ray r;
      r.org = targets[i] +
              Vec3f(0.1f * h * (rng.uniform() - 0.5f), 0.1f * h * (rng.uniform() - 0.5f), h);
      r.dir = targets[i] - r.org;
      compare_ray(e, s, r, aimed);
      // slimrt's test is watertight: the target, on the surface, is reached.
      const Hit hs = s.intersect(r);
      EXPECT_TRUE(hs.valid() && hs.t <= 1.0f + 1e-5f) << config << " target " << i;
    }
    Comparison aimed_ties;
    for (const Comparison::Mismatch& x : aimed.other_face)
      if (bench::hits_agree(x.a, x.b)) aimed_ties.other_face.push_back(x);
    EXPECT_GT(aimed_ties.other_face.size(), 100u) << config << ": too few ties to check";
    EXPECT_EQ(count_non_ties(tris, config, aimed_ties), 0u)
        << config << ": of " << aimed_ties.other_face.size();
    // The check itself: a hit moved to a face away from the ray is not a tie.
    if (!aimed_ties.other_face.empty()) {
      Comparison::Mismatch wrong = aimed_ties.other_face[0];
      wrong.b.primID = (wrong.b.primID + 64 * 32 + 32) % uint32_t(m.face_count());
      EXPECT_FALSE(is_tie(tris, wrong)) << config;
    }
    std::printf(
        "%s: other face on %zu of %llu random/camera hits; aimed: %llu rays, %llu hits, %zu ties "
        "(checked), %llu disagreeing on t (Embree's slips)\n",
        config, c.other_face.size(), (unsigned long long)c.both_hit, (unsigned long long)aimed.rays,
        (unsigned long long)aimed.both_hit, aimed_ties.other_face.size(),
        (unsigned long long)(aimed.rays - aimed.agree));
  }
}

TEST(BenchEmbree, MixedPolygonsSeveralMeshesAndNonFiniteFaces) {
  // Two meshes, faces of 3..6 corners, and faces using a NaN vertex (skipped, as slimrt does):
  // primID must name the input face, geomID the mesh.
  PolyMesh a = random_soup(300, 3);
  PolyMesh b;
  Rng rng(4);
  for (int f = 0; f < 400; ++f) {
    const int n = 3 + f % 4;
    const Vec3f c(rng.uniform(), rng.uniform(), rng.uniform());
    const uint32_t base = uint32_t(b.positions.size());
    for (int k = 0; k < n; ++k) {
      const float ang = 6.2831853f * float(k) / float(n);
      b.positions.push_back(c + Vec3f(std::cos(ang), std::sin(ang), 0.2f * rng.uniform()) * 0.04f);
      b.face_indices.push_back(base + uint32_t(k));
    }
    b.face_sizes.push_back(uint32_t(n));
  }
  b.positions[7 * 5 + 1].x = NAN;  // hits a face of b; its face (and only it) is skipped
  std::vector<const PolyMesh*> meshes = {&a, &b};
  EmbreeScene e(meshes, "embree-tri");
  Scene s = Scene::build(meshes);
  Comparison c = compare(e, s, merge(a.bounds(), b.bounds()), 20000, 128);
  EXPECT_GT(c.both_hit, 3000u);
  EXPECT_EQ(c.agree, c.rays);
  EXPECT_EQ(c.same_geom, c.both_hit);
  // Random faces far apart from each other's planes: no two faces meet a ray at the same t, so
  // every hit names the same face (a fan triangle of a face is a hit on that face).
  EXPECT_EQ(c.same_face, c.both_hit);
  // The face table is Embree's side data.
  EXPECT_GT(e.memory().other_bytes, 0u);
  EXPECT_EQ(e.memory().triangles, a.fan_triangle_count() + b.fan_triangle_count());

  // Configurations that do not apply say so by type (a message for people besides).
  try {
    EmbreeScene q(meshes, "embree-quad");
    ADD_FAILURE() << "embree-quad built on non-quad faces";
  } catch (const NotApplicable& err) {
    EXPECT_NE(std::string(err.what()).find("non-quad faces"), std::string::npos) << err.what();
  }
  EXPECT_THROW(EmbreeScene(meshes, "embree-grid"), NotApplicable) << "embree-grid on a soup";
}

TEST(BenchEmbree, LatticeDetection) {
  for (int n : {1, 2, 7, 64}) {
    bench::QuadLattice t = bench::detect_quad_lattice(make_terrain(n));
    EXPECT_EQ(t.nx, uint32_t(n));
    EXPECT_EQ(t.ny, uint32_t(n));
    EXPECT_FALSE(t.periodic);
  }
  bench::QuadLattice c = bench::detect_quad_lattice(make_canyon(33));
  EXPECT_EQ(c.nx, 33u);
  EXPECT_FALSE(c.periodic);
  bench::QuadLattice t = bench::detect_quad_lattice(make_torus(64));
  EXPECT_EQ(t.nx, 64u);
  EXPECT_EQ(t.ny, 32u);
  EXPECT_TRUE(t.periodic);
  EXPECT_FALSE(bench::detect_quad_lattice(random_soup(100, 1)).valid());
  PolyMesh broken = make_terrain(16);
  std::swap(broken.face_indices[4 * 37 + 1], broken.face_indices[4 * 37 + 2]);
  EXPECT_FALSE(bench::detect_quad_lattice(broken).valid());
}

// embree-quad and embree-grid split each quad on the fan's diagonal and map hits back to the
// input face: on noisy (non-planar) quads the wrong diagonal would change t by far more than 1e-5.
TEST(BenchEmbree, QuadAndGridMatchTrianglesOnGridScenes) {
  for (const char* scene : {"terrain:64", "torus:64", "canyon:48"}) {
    PolyMesh m = load(scene);
    const std::vector<RefTri> tris = reference_triangles(ptrs(m));
    EmbreeScene tri(ptrs(m), "embree-tri");
    Scene s = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
    for (const char* config : {"embree-quad", "embree-grid"}) {
      EmbreeScene e(ptrs(m), config);
      Comparison c = compare(e, s, m.bounds(), 20000, 256);
      EXPECT_GT(c.both_hit, 20000u) << scene << " " << config;
      EXPECT_LE(c.rays - c.agree, c.rays / 10000) << scene << " " << config;
      // Another face only as a checked tie, and rarely.
      EXPECT_EQ(count_non_ties(tris, std::string(scene) + " " + config, c), 0u);
      EXPECT_LE(c.other_face.size(), 1 + c.both_hit / 1000) << scene << " " << config;
    }
    // Memory: grid vertices with the torus seam duplicated, plus 12 B RTCGrid records.
    EmbreeScene grid(ptrs(m), "embree-grid");
    bench::QuadLattice lat = bench::detect_quad_lattice(m);
    const uint64_t verts = uint64_t(lat.nx + 1) * (lat.ny + 1);
    EXPECT_EQ(grid.memory().geometry_bytes, verts * 12 + 16 + 12) << scene;
    EXPECT_EQ(grid.memory().other_bytes, 0u);
    EXPECT_GT(grid.memory().bvh_bytes, 0u);
    // Triangles: the input vertices (+16 B padding) and 12 B per triangle; no face table needed
    // for quads, but needed for the triangles.
    const MemoryStats mt = tri.memory();
    EXPECT_EQ(mt.geometry_bytes, m.positions.size() * 12 + 16 + m.fan_triangle_count() * 12);
    EXPECT_EQ(mt.other_bytes, m.fan_triangle_count() * 4);
    EmbreeScene quad(ptrs(m), "embree-quad");
    EXPECT_EQ(quad.memory().geometry_bytes, m.positions.size() * 12 + 16 + m.face_count() * 16);
    EXPECT_EQ(quad.memory().other_bytes, 0u);
  }
}

// embree-quad-pairs: Embree's quads over slimrt's pairs give bvh8-pairs' hits (same faces, t),
// with u, v of the input fan triangle and its orientation (as bvh8-tri4v reports them), on a
// sphere the heuristic pairs (some windings flipped: the second triangle's shared edge runs
// either way) and on a terrain the pre-scan keeps in input order.
TEST(BenchEmbree, QuadPairsMatchPairsAndTriangles) {
  PolyMesh sphere = icosphere(5);
  for (uint32_t f = 0; f < sphere.face_count(); f += 5)
    std::swap(sphere.face_indices[3 * f + 1], sphere.face_indices[3 * f + 2]);
  for (const PolyMesh& m : {sphere, load("terrain:64")}) {
    const std::vector<RefTri> tris = reference_triangles(ptrs(m));
    EmbreeScene e(ptrs(m), "embree-quad-pairs");
    Scene pairs = Scene::build(m, BuildOptions::from_config("bvh8-pairs"));
    Comparison c = compare(e, pairs, m.bounds(), 20000, 256);
    EXPECT_GT(c.both_hit, 15000u) << m.name;
    EXPECT_LE(c.rays - c.agree, c.rays / 10000) << m.name;
    EXPECT_EQ(count_non_ties(tris, m.name, c), 0u);
    EXPECT_LE(c.other_face.size(), 1 + c.both_hit / 1000) << m.name;
    Scene tri = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
    Rng rng(5);
    int checked = 0;
    for (int i = 0; i < 20000; ++i) {
      Ray r = random_ray(rng, m.bounds());
      Hit a = e.intersect(r), b = tri.intersect(r);
      if (!a.valid() || !b.valid() || a.primID != b.primID) continue;
      if (std::min(std::min(a.u, a.v), std::min(b.u, b.v)) < 0.01f) continue;
      ++checked;
      EXPECT_GT(dot(a.Ng, b.Ng), 0.0f) << m.name;
      EXPECT_NEAR(a.u, b.u, 1e-3f) << m.name;
      EXPECT_NEAR(a.v, b.v, 1e-3f) << m.name;
    }
    EXPECT_GT(checked, 1000) << m.name;
    // Memory: the vertices (+16 B), 16 B per quad, and 10 B per quad of face and corner tables.
    const PairingStats ps = pairing_stats(m);
    const uint64_t quads = ps.pairs + ps.unpaired;
    EXPECT_EQ(e.memory().geometry_bytes, m.positions.size() * 12 + 16 + quads * 16) << m.name;
    EXPECT_EQ(e.memory().other_bytes, quads * 10) << m.name;
    EXPECT_GT(e.memory().bvh_bytes, 0u);
  }
}

// A lattice wider than an RTCGrid record (32767 vertices a side) is cut into records that share
// their border column; hits still map to the input face.
TEST(BenchEmbree, GridRecordsSplitLongLattices) {
  const uint32_t nx = 70000, ny = 3;
  PolyMesh m;
  m.name = "strip";
  Rng rng(8);
  for (uint32_t j = 0; j <= ny; ++j)
    for (uint32_t i = 0; i <= nx; ++i)
      m.positions.push_back(Vec3f(float(i), float(j), 0.3f * rng.uniform()));
  for (uint32_t j = 0; j < ny; ++j)
    for (uint32_t i = 0; i < nx; ++i) {
      const uint32_t v = j * (nx + 1) + i;
      m.face_indices.insert(m.face_indices.end(), {v, v + 1, v + nx + 2, v + nx + 1});
      m.face_sizes.push_back(4);
    }
  bench::QuadLattice lat = bench::detect_quad_lattice(m);
  ASSERT_EQ(lat.nx, nx);
  ASSERT_EQ(lat.ny, ny);
  EmbreeScene grid(ptrs(m), "embree-grid");
  // The reference is slimrt's watertight BVH: at |x| ~ 5e4, embree-tri's triangle test lets a
  // few rays slip through shared edges.
  Scene tri = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
  // 3 records of 12 bytes; one vertex buffer.
  EXPECT_EQ(grid.memory().geometry_bytes, uint64_t(nx + 1) * (ny + 1) * 12 + 16 + 3 * 12);
  Comparison c;
  auto shoot = [&](float x, float y) {
    Ray r;
    r.org = Vec3f(x, y, 2.0f);
    r.dir = normalize(Vec3f(0.01f, 0.02f, -1.0f));
    compare_ray(grid, tri, r, c);
  };
  for (int k = 0; k < 20000; ++k) shoot(rng.uniform() * float(nx), rng.uniform() * float(ny));
  for (float x0 : {32766.0f, 65532.0f, 0.0f, float(nx - 1)})  // around the record borders
    for (int k = 0; k < 2000; ++k) shoot(x0 + 2.0f * rng.uniform() - 1.0f, rng.uniform() * ny);
  EXPECT_GT(c.both_hit, 25000u);
  EXPECT_LE(c.rays - c.agree, c.rays / 10000);
  EXPECT_EQ(count_non_ties(reference_triangles(ptrs(m)), "strip", c), 0u);
  EXPECT_LE(c.other_face.size(), 1 + c.both_hit / 1000);
}

TEST(BenchEmbree, HitAttributesMatchSlimrt) {
  // u, v are the fan triangle's barycentrics and Ng its orientation, whatever the Embree geometry.
  PolyMesh m = make_terrain(32);
  Scene s = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
  for (const char* config : {"embree-tri", "embree-quad", "embree-grid"}) {
    EmbreeScene e(ptrs(m), config);
    Rng rng(3);
    int checked = 0;
    for (int i = 0; i < 5000; ++i) {
      Ray r = random_ray(rng, m.bounds());
      Hit a = e.intersect(r), b = s.intersect(r);
      if (!a.valid() || !b.valid() || a.primID != b.primID) continue;
      // Near the quad's diagonal either fan triangle may be reported.
      if (std::min(std::min(a.u, a.v), std::min(b.u, b.v)) < 0.01f) continue;
      ++checked;
      EXPECT_GT(dot(a.Ng, b.Ng), 0.0f) << config;
      EXPECT_NEAR(a.u, b.u, 1e-3f) << config;
      EXPECT_NEAR(a.v, b.v, 1e-3f) << config;
    }
    EXPECT_GT(checked, 1000) << config;
  }
}

TEST(BenchEmbree, UnknownConfigAndInvalidRays) {
  PolyMesh m = make_terrain(4);
  EXPECT_THROW(EmbreeScene(ptrs(m), "embree-foo"), Error);
  EXPECT_THROW(bench::check_config_name("bvh9-tri4v"), Error);
  EXPECT_NO_THROW(bench::check_config_name("embree-grid"));
  EXPECT_NO_THROW(bench::check_config_name("costa-TPFV"));
  EmbreeScene e(ptrs(m), "embree-tri");
  Ray r;
  r.org = Vec3f(0.5f, 0.5f, 2.0f);
  r.dir = Vec3f(0.0f, 0.0f, -1.0f);
  EXPECT_TRUE(e.intersect(r).valid());
  Ray bad = r;
  bad.dir = Vec3f(0.0f);
  EXPECT_FALSE(e.intersect(bad).valid());
  bad = r;
  bad.org.x = NAN;
  EXPECT_FALSE(e.occluded(bad));
  bad = r;
  bad.tnear = 5.0f;
  bad.tfar = 1.0f;
  EXPECT_FALSE(e.intersect(bad).valid());
}

TEST(BenchRunner, LossyNamesAndAgreement) {
  EXPECT_TRUE(bench::is_lossy_config("lossy-grid"));
  EXPECT_TRUE(bench::is_lossy_config("lossy-grid-e2"));
  EXPECT_TRUE(bench::is_lossy_config("costa-PFV"));
  EXPECT_TRUE(bench::is_lossy_config("costa-V"));
  EXPECT_FALSE(bench::is_lossy_config("costa-TPF"));
  EXPECT_FALSE(bench::is_lossy_config("costa"));
  EXPECT_FALSE(bench::is_lossy_config("bvh8-tri4v"));
  EXPECT_FALSE(bench::is_lossy_config("embree-grid"));
  Hit a, b;
  EXPECT_TRUE(bench::hits_agree(a, b));
  a.geomID = b.geomID = 0;
  a.t = 2.0f;
  b.t = 2.0f * (1.0f + 0.9e-5f);
  EXPECT_TRUE(bench::hits_agree(a, b));
  b.t = 2.0f * (1.0f + 2e-5f);
  EXPECT_FALSE(bench::hits_agree(a, b));
  b.geomID = kInvalidID;
  EXPECT_FALSE(bench::hits_agree(a, b));
}

TEST(BenchRounds, EveryConfigOncePerRoundInRotatingOrder) {
  for (size_t n : {size_t(1), size_t(2), size_t(3), size_t(7)}) {
    std::vector<int> opened(n, 0);
    for (int round = 0; round < int(3 * n); ++round) {
      const std::vector<size_t> order = bench::round_order(n, round);
      ASSERT_EQ(order.size(), n);
      std::vector<int> seen(n, 0);
      for (size_t c : order) {
        ASSERT_LT(c, n);
        ++seen[c];
      }
      for (size_t c = 0; c < n; ++c) EXPECT_EQ(seen[c], 1) << "n " << n << " round " << round;
      // Each round starts one configuration further, the rest following in configuration order.
      EXPECT_EQ(order[0], size_t(round) % n);
      for (size_t i = 1; i < n; ++i) EXPECT_EQ(order[i], (order[i - 1] + 1) % n);
      if (round > 0 && n > 1) {
        EXPECT_NE(order, bench::round_order(n, round - 1));
      }
      ++opened[order[0]];
    }
    for (size_t c = 0; c < n; ++c) EXPECT_EQ(opened[c], 3) << "n " << n;  // each opens in turn
  }
  EXPECT_TRUE(bench::round_order(0, 4).empty());
}

TEST(BenchRounds, MedianRangeAndNoisyFlag) {
  EXPECT_EQ(bench::median({}), 0.0);
  EXPECT_EQ(bench::median({3.0}), 3.0);
  EXPECT_EQ(bench::median({4.0, 1.0, 2.0}), 2.0);
  EXPECT_EQ(bench::median({4.0, 1.0, 2.0, 3.0}), 2.5);

  bench::Spread s = bench::spread_of({1.05, 0.97, 1.0, 1.08, 1.02});
  EXPECT_EQ(s.median, 1.02);
  EXPECT_EQ(s.lo, 0.97);
  EXPECT_EQ(s.hi, 1.08);
  EXPECT_FALSE(s.noisy());
  // Either end further than 10% of the median from it is flagged.
  EXPECT_TRUE(bench::spread_of({1.0, 1.0, 1.11}).noisy());
  EXPECT_TRUE(bench::spread_of({1.0, 1.0, 0.89}).noisy());
  EXPECT_FALSE(bench::spread_of({1.0, 1.0, 1.09, 0.91}).noisy());
  EXPECT_FALSE(bench::spread_of({2.0}).noisy());  // one round: an empty range
  // The figures of the three back-to-back runs (bvh8-pairs W2 2.36, 0.65, 0.97).
  const bench::Spread pairs = bench::spread_of({2.36, 0.65, 0.97});
  EXPECT_EQ(pairs.median, 0.97);
  EXPECT_TRUE(pairs.noisy());
}

TEST(BenchRounds, ScenesKeptWithinTheMemoryBudget) {
  using V = std::vector<bool>;
  EXPECT_EQ(bench::keep_between_rounds({10, 20, 30, 5}, 35), (V{true, true, false, true}));
  EXPECT_EQ(bench::keep_between_rounds({10, 20, 30, 5}, 1000), (V{true, true, true, true}));
  EXPECT_EQ(bench::keep_between_rounds({10, 20}, 0), (V{false, false}));
  EXPECT_EQ(bench::keep_between_rounds({40, 20}, 30), (V{false, true}));
  EXPECT_GT(bench::default_memory_budget(), 0u);
}

TEST(BenchReport, RatiosAsMedianWithRangeInJsonAndMarkdown) {
  bench::BenchReport rep;
  rep.repeat = 5;
  bench::BenchRow a;
  a.scene = "s";
  a.config = "bvh8-tri4v";
  a.triangles = 10;
  a.mrays_primary = bench::spread_of({4.0, 4.2, 3.9, 4.1, 4.0});
  a.mrays_diffuse = bench::spread_of({2.0, 2.1, 2.0, 1.9, 2.0});
  a.ratio_primary = bench::spread_of({1.02, 0.97, 1.08, 1.0, 1.05});
  a.ratio_diffuse = bench::spread_of({1.02, 0.85, 1.08, 1.0, 1.05});
  a.seconds_primary = {0.25, 0.24, 0.26, 0.25, 0.25};
  a.checksum_primary = 123.5;
  rep.rows.push_back(a);
  bench::BenchRow b;
  b.scene = "s";
  b.config = "embree-grid";
  b.reason = "does not apply: not a lattice";
  rep.rows.push_back(b);

  const nlohmann::json j = bench::report_json(rep);
  EXPECT_EQ(j["rounds"].get<int>(), 5);
  const nlohmann::json& r = j["results"][0];
  for (const char* f : {"mrays_primary", "mrays_diffuse", "ratio_primary", "ratio_diffuse"}) {
    const std::string n = f;
    ASSERT_TRUE(r[n].is_number()) << n;
    ASSERT_TRUE(r[n + "_range"].is_array()) << n;
    ASSERT_EQ(r[n + "_range"].size(), 2u) << n;
    ASSERT_TRUE(r[n + "_noisy"].is_boolean()) << n;
    EXPECT_LE(r[n + "_range"][0].get<double>(), r[n].get<double>()) << n;
    EXPECT_GE(r[n + "_range"][1].get<double>(), r[n].get<double>()) << n;
  }
  EXPECT_EQ(r["ratio_primary"].get<double>(), 1.02);
  EXPECT_EQ(r["ratio_primary_range"][0].get<double>(), 0.97);
  EXPECT_EQ(r["ratio_primary_range"][1].get<double>(), 1.08);
  EXPECT_FALSE(r["ratio_primary_noisy"].get<bool>());
  EXPECT_TRUE(r["ratio_diffuse_noisy"].get<bool>());
  EXPECT_EQ(r["seconds_primary_rounds"].size(), 5u);
  EXPECT_EQ(r["checksum_primary"].get<double>(), 123.5);
  const nlohmann::json& u = j["results"][1];
  for (const char* f : {"ratio_primary", "ratio_primary_range", "ratio_primary_noisy"})
    EXPECT_TRUE(u[f].is_null()) << f;
  EXPECT_TRUE(u["reason"].is_string());

  EXPECT_EQ(bench::ratio_cell(a.ratio_primary), "1.02 (0.97-1.08)");
  EXPECT_EQ(bench::ratio_cell(a.ratio_diffuse), "1.02 (0.85-1.08) !");
  EXPECT_EQ(bench::ratio_cell(std::nullopt), "—");
  const std::string md = bench::report_markdown(rep);
  EXPECT_NE(md.find("| 1.02 (0.97-1.08) | 1.02 (0.85-1.08) ! |"), std::string::npos) << md;
  EXPECT_NE(md.find("5 interleaved rounds"), std::string::npos) << md;
}

// `slimrt bench terrain:64 --repeat 1 --json` against the schema of docs/benchmark.md.
TEST(BenchCli, JsonSchemaOnTerrain64) {
  const std::string json_path = (std::filesystem::temp_directory_path() /
                                 ("slimrt_bench_" + std::to_string(getpid()) + ".json"))
                                    .string();
  const std::string configs =
      "embree-tri,embree-tri-compact,embree-quad,embree-grid,bvh8-tri4v,bvh8-tri4i,qbvh8-tri4v,"
      "clbvh-tri4v,grid,lossy-grid,costa-PFV";
  const std::string cmd = std::string(SLIM_CLI_PATH) +
                          " bench terrain:64 --repeat 1 --min-time 0 --threads 2" + " --config " +
                          configs + " --json " + json_path + " > /dev/null";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(json_path);
  ASSERT_TRUE(in.good());
  nlohmann::json j = nlohmann::json::parse(in);
  std::filesystem::remove(json_path);

  ASSERT_TRUE(j.is_object());
  ASSERT_TRUE(j.contains("machine") && j["machine"].is_object());
  EXPECT_TRUE(j["machine"]["cpu"].is_string());
  EXPECT_TRUE(j["machine"]["threads"].is_number_integer());
  EXPECT_EQ(j["machine"]["threads"].get<int>(), 2);
  EXPECT_TRUE(j["machine"]["isa"].is_string());
  ASSERT_TRUE(j.contains("results") && j["results"].is_array());
  ASSERT_EQ(j["results"].size(), 11u);

  const char* integer_fields[] = {"bytes_geometry", "bytes_bvh", "bytes_other", "bytes_total"};
  const char* number_fields[] = {"build_s",           "bytes_per_triangle", "mrays_primary",
                                 "mrays_diffuse",     "ratio_primary",      "ratio_diffuse",
                                 "box_tests_per_ray", "prim_tests_per_ray", "hit_agreement"};
  const char* error_fields[] = {"rms", "diag_avg_pct", "diag_max_pct", "psnr_db"};
  std::map<std::string, nlohmann::json> by_config;
  for (const nlohmann::json& r : j["results"]) {
    ASSERT_TRUE(r["config"].is_string());
    const std::string config = r["config"];
    by_config[config] = r;
    EXPECT_EQ(r["scene"], "terrain:64");
    EXPECT_TRUE(r["triangles"].is_number_unsigned()) << config;
    EXPECT_EQ(r["triangles"].get<uint64_t>(), 2u * 64 * 64);
    for (const char* f : integer_fields) {
      ASSERT_TRUE(r.contains(f)) << config << " " << f;
      EXPECT_TRUE(r[f].is_null() || r[f].is_number_unsigned()) << config << " " << f;
    }
    for (const char* f : number_fields) {
      ASSERT_TRUE(r.contains(f)) << config << " " << f;
      EXPECT_TRUE(r[f].is_null() || r[f].is_number()) << config << " " << f;
    }
    ASSERT_TRUE(r.contains("error") && r["error"].is_object()) << config;
    for (const char* f : error_fields) {
      ASSERT_TRUE(r["error"].contains(f)) << config << " " << f;
      EXPECT_TRUE(r["error"][f].is_null() || r["error"][f].is_number()) << config << " " << f;
    }
    // Every configuration of the list applies to a terrain: none may come back unmeasured.
    ASSERT_FALSE(r.contains("reason")) << config << ": " << r["reason"];
    for (const char* f : integer_fields) EXPECT_FALSE(r[f].is_null()) << config << " " << f;
    EXPECT_EQ(r["bytes_total"].get<uint64_t>(), r["bytes_geometry"].get<uint64_t>() +
                                                    r["bytes_bvh"].get<uint64_t>() +
                                                    r["bytes_other"].get<uint64_t>())
        << config;
    EXPECT_NEAR(r["bytes_per_triangle"].get<double>(),
                double(r["bytes_total"].get<uint64_t>()) / double(2 * 64 * 64), 1e-9)
        << config;
    for (const char* f : {"build_s", "mrays_primary", "mrays_diffuse", "ratio_primary",
                          "ratio_diffuse", "hit_agreement"}) {
      ASSERT_TRUE(r[f].is_number()) << config << " " << f;
      EXPECT_GT(r[f].get<double>(), 0.0) << config << " " << f;
    }
    // The rounds (one here): the build time, each MRays/s figure and ratio with its range and flag.
    for (const char* f :
         {"build_s", "mrays_primary", "mrays_diffuse", "ratio_primary", "ratio_diffuse"}) {
      const std::string n = f;
      ASSERT_TRUE(r.contains(n + "_range") && r[n + "_range"].is_array()) << config << " " << n;
      ASSERT_EQ(r[n + "_range"].size(), 2u) << config << " " << n;
      EXPECT_EQ(r[n + "_range"][0].get<double>(), r[n].get<double>()) << config << " " << n;
      EXPECT_EQ(r[n + "_range"][1].get<double>(), r[n].get<double>()) << config << " " << n;
      ASSERT_TRUE(r.contains(n + "_noisy") && r[n + "_noisy"].is_boolean()) << config << " " << n;
      EXPECT_FALSE(r[n + "_noisy"].get<bool>()) << config << " " << n;
    }
    EXPECT_EQ(r["seconds_build_rounds"].size(), 1u) << config;
    EXPECT_EQ(r["seconds_build_rounds"][0].get<double>(), r["build_s"].get<double>()) << config;
    EXPECT_EQ(r["seconds_primary_rounds"].size(), 1u) << config;
    EXPECT_EQ(r["seconds_diffuse_rounds"].size(), 1u) << config;
    EXPECT_EQ(r["passes_primary_rounds"], nlohmann::json::array({1})) << config;  // --min-time 0
    EXPECT_EQ(r["passes_diffuse_rounds"], nlohmann::json::array({1})) << config;
    EXPECT_EQ(r["rays_primary"].get<uint64_t>(), 1024u * 1024u) << config;
    EXPECT_GE(r["rays_diffuse"].get<uint64_t>(), 1024u * 1024u) << config;
    EXPECT_GT(r["checksum_primary"].get<double>(), 0.0) << config;
    EXPECT_GT(r["checksum_diffuse"].get<double>(), 0.0) << config;
    EXPECT_TRUE(r["kept_between_rounds"].get<bool>()) << config;
    const bool embree = config.rfind("embree-", 0) == 0;
    EXPECT_EQ(r["box_tests_per_ray"].is_null(), embree) << config;
    EXPECT_EQ(r["prim_tests_per_ray"].is_null(), embree) << config;
    // No pair format in this list: one primitive record per triangle tested.
    ASSERT_TRUE(r.contains("prim_records_per_ray")) << config;
    EXPECT_EQ(r["prim_records_per_ray"], r["prim_tests_per_ray"]) << config;
    if (!bench::is_lossy_config(config)) {
      // 1.0 up to the rays that slip through Embree's non-watertight triangle test (about one
      // in a million here; docs/benchmark.md: a lossless format under 99.9% is an error).
      EXPECT_GE(r["hit_agreement"].get<double>(), 0.9999) << config;
      for (const char* f : error_fields) EXPECT_TRUE(r["error"][f].is_null()) << config << " " << f;
    }
  }
  for (const std::string c :
       {"embree-tri", "embree-tri-compact", "embree-quad", "embree-grid", "bvh8-tri4v",
        "bvh8-tri4i", "qbvh8-tri4v", "clbvh-tri4v", "grid", "lossy-grid", "costa-PFV"})
    EXPECT_TRUE(by_config.count(c)) << c;
  const double ref_primary = by_config["embree-tri"]["mrays_primary"];
  const double ref_diffuse = by_config["embree-tri"]["mrays_diffuse"];
  // embree-tri is the reference of hit_agreement (1 by definition); what it traced is checked
  // against slimrt's watertight bvh8-tri4v instead: the same camera rays on the same triangles.
  // Rays that agree add t equal within 1e-5 relative to both checksums; each ray that does not
  // (one that slips through Embree's non-watertight test) moves the sum by at most the largest t,
  // the distance from the camera to the farthest corner of the box.
  const Box3f box = make_terrain(64).bounds();
  const Camera cam = frame_box(box, 1024, 1024);
  double t_max = 0;
  for (int c = 0; c < 8; ++c) {
    const Vec3f corner(c & 1 ? box.hi.x : box.lo.x, c & 2 ? box.hi.y : box.lo.y,
                       c & 4 ? box.hi.z : box.lo.z);
    t_max = std::max(t_max, double(length(corner - cam.eye)));
  }
  const nlohmann::json& tri4v = by_config["bvh8-tri4v"];
  const double disagree = std::round((1.0 - tri4v["hit_agreement"].get<double>()) *
                                     double(tri4v["rays_primary"].get<uint64_t>()));
  const double ck_embree = by_config["embree-tri"]["checksum_primary"];
  const double ck_slim = tri4v["checksum_primary"];
  EXPECT_NEAR(ck_embree, ck_slim, 1e-5 * ck_slim + disagree * t_max)
      << disagree << " rays disagree, t_max " << t_max;
  for (const auto& [config, r] : by_config) {
    const double rp = r["ratio_primary"], rd = r["ratio_diffuse"];
    const double mp = r["mrays_primary"], md = r["mrays_diffuse"];
    EXPECT_NEAR(rp, mp / ref_primary, 1e-6 * rp) << config;
    EXPECT_NEAR(rd, md / ref_diffuse, 1e-6 * rd) << config;
    if (bench::is_lossy_config(config)) {
      EXPECT_TRUE(r["error"]["psnr_db"].is_number()) << config;
    }
  }
}

// Three rounds, once with every built scene kept between rounds and once with none kept (a 1-byte
// budget: each is rebuilt in every round): same rays, same checksums, one time per round.
TEST(BenchCli, RoundsKeptOrRebuiltTraceTheSameRays) {
  auto run = [](const std::string& extra) {
    const std::string json_path = (std::filesystem::temp_directory_path() /
                                   ("slimrt_bench_rounds_" + std::to_string(getpid()) + ".json"))
                                      .string();
    const std::string cmd = std::string(SLIM_CLI_PATH) +
                            " bench terrain:16 --repeat 3 --min-time 0.1 --threads 2 --config "
                            "embree-tri,bvh8-tri4v,bvh8-pairs --json " +
                            json_path + extra + " > /dev/null 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream in(json_path);
    nlohmann::json j = nlohmann::json::parse(in);
    std::filesystem::remove(json_path);
    return j;
  };
  const nlohmann::json kept = run(""), rebuilt = run(" --memory-budget 0.000001");
  EXPECT_EQ(kept["rounds"].get<int>(), 3);
  EXPECT_EQ(kept["min_seconds_per_timing"].get<double>(), 0.1);
  ASSERT_EQ(kept["results"].size(), 3u);
  ASSERT_EQ(rebuilt["results"].size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const nlohmann::json &k = kept["results"][i], &r = rebuilt["results"][i];
    const std::string config = k["config"];
    EXPECT_EQ(r["config"], k["config"]);
    EXPECT_TRUE(k["kept_between_rounds"].get<bool>()) << config;
    EXPECT_FALSE(r["kept_between_rounds"].get<bool>()) << config;
    for (const nlohmann::json* x : {&k, &r}) {
      EXPECT_EQ((*x)["seconds_primary_rounds"].size(), 3u) << config;
      EXPECT_EQ((*x)["seconds_diffuse_rounds"].size(), 3u) << config;
      EXPECT_EQ((*x)["cpu_seconds_primary_rounds"].size(), 3u) << config;
      EXPECT_EQ((*x)["cpu_seconds_diffuse_rounds"].size(), 3u) << config;
      // --min-time 0.1: each timing repeats its workload until 0.1 s have passed (at most
      // 1000 passes) and keeps the fastest pass. So one pass means that pass alone took 0.1 s or
      // more, and n > 1 passes of at least the fastest one's time took less than 0.1 s before
      // the last one.
      for (const char* w : {"primary", "diffuse"}) {
        const nlohmann::json& passes = (*x)[std::string("passes_") + w + "_rounds"];
        const nlohmann::json& secs = (*x)[std::string("seconds_") + w + "_rounds"];
        ASSERT_EQ(passes.size(), 3u) << config << " " << w;
        for (size_t k = 0; k < 3; ++k) {
          const int n = passes[k].get<int>();
          const double s = secs[k].get<double>();
          EXPECT_GE(n, 1) << config << " " << w;
          EXPECT_LE(n, 1000) << config << " " << w;
          if (n == 1) {
            EXPECT_GE(s, 0.1) << config << " " << w;
          } else {
            EXPECT_LT((n - 1) * s, 0.1) << config << " " << w;
          }
        }
      }
      // Each round builds every configuration once: three build times, the median among them.
      const nlohmann::json& builds = (*x)["seconds_build_rounds"];
      ASSERT_EQ(builds.size(), 3u) << config;
      std::vector<double> b = {builds[0], builds[1], builds[2]};
      std::sort(b.begin(), b.end());
      EXPECT_EQ((*x)["build_s"].get<double>(), b[1]) << config;
      EXPECT_EQ((*x)["build_s_range"], nlohmann::json::array({b[0], b[2]})) << config;
      const nlohmann::json& range = (*x)["ratio_diffuse_range"];
      EXPECT_LE(range[0].get<double>(), (*x)["ratio_diffuse"].get<double>()) << config;
      EXPECT_GE(range[1].get<double>(), (*x)["ratio_diffuse"].get<double>()) << config;
    }
    for (const char* f : {"rays_primary", "rays_diffuse", "checksum_primary", "checksum_diffuse"})
      EXPECT_EQ(k[f], r[f]) << config << " " << f;
  }
  // The ratios are per round, against embree-tri's time in the same round: recomputed from the
  // rounds' seconds, their median and range are the reported ones (embree-tri's: 1, 1 and 1).
  for (const nlohmann::json* run : {&kept, &rebuilt}) {
    const nlohmann::json& ref = (*run)["results"][0];
    ASSERT_EQ(ref["config"], "embree-tri");
    for (const nlohmann::json& x : (*run)["results"]) {
      const std::string config = x["config"];
      for (const char* w : {"primary", "diffuse"}) {
        const std::string rays = std::string("rays_") + w;
        const std::string secs = std::string("seconds_") + w + "_rounds";
        std::vector<double> r;
        for (size_t k = 0; k < 3; ++k)
          r.push_back((x[rays].get<double>() / x[secs][k].get<double>() * 1e-6) /
                      (ref[rays].get<double>() / ref[secs][k].get<double>() * 1e-6));
        std::sort(r.begin(), r.end());
        const std::string ratio = std::string("ratio_") + w;
        const double median = x[ratio], lo = x[ratio + "_range"][0], hi = x[ratio + "_range"][1];
        EXPECT_NEAR(median, r[1], 1e-12 * r[1]) << config << " " << ratio;
        EXPECT_NEAR(lo, r[0], 1e-12 * r[0]) << config << " " << ratio;
        EXPECT_NEAR(hi, r[2], 1e-12 * r[2]) << config << " " << ratio;
      }
    }
  }
}

TEST(BenchCli, UnknownConfigFails) {
  const std::string cmd =
      std::string(SLIM_CLI_PATH) + " bench terrain:4 --config bvh9 > /dev/null 2>&1";
  EXPECT_NE(std::system(cmd.c_str()), 0);
}

// `slimrt info SCENE --pairs --json`: the top-level names other programs read, and
// --repeat's later calls.
TEST(InfoCli, PairsJsonNames) {
  const std::string json_path = (std::filesystem::temp_directory_path() /
                                 ("slimrt_info_pairs_" + std::to_string(getpid()) + ".json"))
                                    .string();
  const std::string cmd =
      std::string(SLIM_CLI_PATH) + " info torus:16 --pairs --json --repeat 3 > " + json_path;
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(json_path);
  const nlohmann::json j = nlohmann::json::parse(in);
  std::filesystem::remove(json_path);
  EXPECT_EQ(j["triangles"].get<uint64_t>(), 2u * 16 * 8);
  EXPECT_DOUBLE_EQ(j["paired_fraction"].get<double>(), 1.0);  // quads, kept by the pre-scan
  EXPECT_DOUBLE_EQ(j["window2_paired_fraction"].get<double>(), 1.0);
  EXPECT_TRUE(j["pairing_s"].is_number_float());  // a time: only its presence is checked
  EXPECT_TRUE(j["pairing_later_s"].is_number_float());
  EXPECT_EQ(j["pairing_later_runs"].get<int>(), 2);
  EXPECT_EQ(j["pairing"]["pairs"].get<uint64_t>(), 16u * 8);
  const std::string bad =
      std::string(SLIM_CLI_PATH) + " info torus:16 --pairs --repeat 0 2>/dev/null";
  EXPECT_NE(std::system(bad.c_str()), 0);
  const std::string no_pairs = std::string(SLIM_CLI_PATH) + " info torus:16 --repeat 3 2>/dev/null";
  EXPECT_NE(std::system(no_pairs.c_str()), 0);
}
