// Chunked builds (Scene::build_chunked, src/api/scene_joined.cpp): a scene joined from chunk scenes
// gives the in-memory build's hits up to ties, stays watertight across chunk borders, and
// round-trips through a scene file.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "slimrt/render.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

namespace slim {
namespace {

std::string read_all(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}

// Rays from outside the torus's box towards random points near its surface, and rays from its
// core circle (inside the tube) in random directions.
std::vector<Ray> torus_rays(int n, uint64_t seed) {
  Rng rng(seed);
  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    const float a = 6.2831853f * rng.uniform(), b = 6.2831853f * rng.uniform();
    const Vec3f target((1.0f + 0.4f * std::cos(b)) * std::cos(a),
                       (1.0f + 0.4f * std::cos(b)) * std::sin(a), 0.4f * std::sin(b));
    Ray r;
    r.org = Vec3f(rng.uniform() * 6 - 3, rng.uniform() * 6 - 3, rng.uniform() * 6 - 3);
    r.dir = normalize(target - r.org);
    rays.push_back(r);
  }
  return rays;
}

// Origins on the core circle: every ray must hit the closed torus.
int leaks(const Scene& s, int n, uint64_t seed) {
  Rng rng(seed);
  int count = 0;
  for (int i = 0; i < n; ++i) {
    const float a = 6.2831853f * rng.uniform();
    Ray r;
    r.org = Vec3f(std::cos(a), std::sin(a), 0.0f);
    r.dir = normalize(Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
    count += !s.intersect(r).valid();
    count += !s.occluded(r);
  }
  return count;
}

// Same t bits and the same face, or a tie checked geometrically on `tris` (the input's fan
// triangles): the other scene's face is hit at the same t, the hit point lies within tie_delta of
// that face and of the boundary of the first scene's face (the ray passes through an edge or a
// vertex the two faces share). Ties are rays through shared edges: rare on random rays, bounded.
// `rel_tol`: the relative difference of t allowed on the same face (0: the same bits).
void expect_same_hits(const Scene& a, const Scene& b, const std::vector<test::RefTri>& tris,
                      const std::vector<Ray>& rays, const std::string& what, float rel_tol = 0.0f) {
  int mismatches = 0, ties = 0, hits = 0, wrong = 0;
  for (const Ray& r : rays) {
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    ASSERT_EQ(ha.valid(), hb.valid()) << what;
    EXPECT_EQ(a.occluded(r), ha.valid()) << what;
    EXPECT_EQ(b.occluded(r), hb.valid()) << what;
    if (!ha.valid()) continue;
    ++hits;
    if (ha.primID == hb.primID && std::fabs(ha.t - hb.t) <= rel_tol * ha.t) continue;
    if (ha.t != hb.t) {
      if (mismatches++ < 3)
        ADD_FAILURE() << what << ": t " << ha.t << " vs " << hb.t << " faces " << ha.primID << " "
                      << hb.primID;
      continue;
    }
    ASSERT_EQ(hb.geomID, 0u) << what;
    test::RefHit at;
    at.t = ha.t;
    at.geom = 0;
    at.prim = ha.primID;
    if (test::geometric_tie(tris, r, at, 0, hb.primID, test::tie_delta(r, ha.t)) ==
        test::TieKind::Edge) {
      ++ties;
    } else if (wrong++ < 3) {
      ADD_FAILURE() << what << ": face " << hb.primID << " instead of " << ha.primID << " at t "
                    << ha.t << ", not through an edge or vertex they share";
    }
  }
  EXPECT_GT(hits, int(rays.size()) / 2) << what;
  EXPECT_EQ(mismatches, 0) << what;
  EXPECT_EQ(wrong, 0) << what;
  EXPECT_LE(ties, hits / 1000 + 2) << what;
}

// Every configuration that intersects the input's fan triangles: the lossy ones keep their error
// bound instead, and `grid` splits each quad along the diagonal its grid picks, which depends on
// the grids a chunk holds.
TEST(JoinedScene, TorusIn16ChunksMatchesTheInMemoryBuild) {
  const PolyMesh torus = load("torus:256");  // 256 x 128 quads, 65536 triangles
  const std::vector<Ray> rays = torus_rays(5000, 3);
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 4096;
  const std::vector<test::RefTri> tris = test::reference_triangles({&torus});
  for (const ConfigInfo& row : configs()) {
    if (row.own_geometry) continue;
    const BuildOptions opt = row.options;
    const Scene whole = Scene::build(torus, opt);
    const Scene joined = Scene::build_chunked("torus:256", opt, chunking);
    EXPECT_GE(test::detail_value(joined, "chunks"), 16) << row.name;
    EXPECT_EQ(joined.stats().input_faces, whole.stats().input_faces) << row.name;
    EXPECT_EQ(joined.stats().triangles, whole.stats().triangles) << row.name;
    EXPECT_EQ(joined.memory().triangles, whole.memory().triangles) << row.name;
    EXPECT_EQ(joined.options().config_name(), row.name);
    std::string why;
    EXPECT_TRUE(joined.validate(&why)) << row.name << ": " << why;
    // `grid` intersects a quad's triangles with its corners in the order of the sub-grid that
    // holds it, which depends on the grids a chunk makes: t may differ in the last bits.
    expect_same_hits(whole, joined, tris, rays, row.name, row.name == "grid" ? 1e-6f : 0.0f);
    EXPECT_EQ(leaks(joined, 5000, 11), 0) << row.name;
  }
}

// A mesh file goes the streamed way: partitioned into Morton-ordered chunks spilled to disk.
TEST(JoinedScene, StreamedObjMatchesTheInMemoryBuild) {
  test::TempDir dir("slimrt_joined_obj");
  const PolyMesh torus = load("torus:96");
  std::string obj;
  char line[128];
  for (const Vec3f& p : torus.positions) {
    std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", p.x, p.y, p.z);
    obj += line;
  }
  const std::vector<uint64_t> off = torus.face_offsets();
  for (size_t f = 0; f < torus.face_count(); ++f) {
    obj += "f";
    for (uint64_t k = off[f]; k < off[f + 1]; ++k)
      obj += " " + std::to_string(torus.face_indices[k] + 1);
    obj += "\n";
  }
  const std::string path = dir.write("torus.obj", obj);
  const std::string spill = dir.path("spill");
  std::filesystem::create_directories(spill);
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 1024;
  chunking.spill_dir = spill;
  const PolyMesh from_file = load(path);
  const std::vector<test::RefTri> tris = test::reference_triangles({&from_file});
  for (const char* config : {"bvh8-tri4v", "clbvh-compact", "bvh8-pairs"}) {
    const BuildOptions opt = BuildOptions::from_config(config);
    const Scene joined = Scene::build_chunked(path, opt, chunking);
    EXPECT_GE(test::detail_value(joined, "chunks"), 8) << config;
    EXPECT_EQ(joined.stats().input_faces, torus.face_count()) << config;
    expect_same_hits(Scene::build(from_file, opt), joined, tris, torus_rays(3000, 9), config);
    EXPECT_EQ(leaks(joined, 3000, 13), 0) << config;
  }
  EXPECT_TRUE(std::filesystem::is_empty(spill));  // the spill files are gone
}

// subdiv: meshes exist only chunked; a closed base mesh stays closed.
TEST(JoinedScene, SubdividedTorusIsClosed) {
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 2048;
  const Scene s =
      Scene::build_chunked("subdiv:2:torus:32", BuildOptions::from_config("bvh8-tri4v"), chunking);
  EXPECT_EQ(s.stats().triangles, uint64_t(32 * 16 * 2) * 16);
  EXPECT_GE(test::detail_value(s, "chunks"), 8);
  EXPECT_EQ(leaks(s, 5000, 17), 0);
}

TEST(JoinedScene, RoundTripsThroughASceneFile) {
  test::TempDir dir("slimrt_joined");
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 1024;
  chunking.spill_dir = dir.dir();
  const std::vector<Ray> rays = torus_rays(5000, 5);
  for (const char* config : {"bvh8-tri4v", "clbvh-compact"}) {
    const Scene built =
        Scene::build_chunked("torus:128", BuildOptions::from_config(config), chunking);
    EXPECT_GE(test::detail_value(built, "chunks"), 8) << config;
    const std::string path = dir.path(std::string(config) + ".slim");
    built.save(path);
    OpenOptions deep;
    deep.check_structure = true;
    const Scene opened = Scene::open(path, deep);
    EXPECT_EQ(opened.memory().total(), built.memory().total()) << config;
    EXPECT_EQ(opened.stats().triangles, built.stats().triangles) << config;
    EXPECT_EQ(test::detail_value(opened, "chunks"), test::detail_value(built, "chunks")) << config;
    std::string why;
    EXPECT_TRUE(opened.validate(&why)) << config << ": " << why;
    for (const Ray& r : rays) {
      const Hit a = built.intersect(r), b = opened.intersect(r);
      ASSERT_EQ(a.valid(), b.valid()) << config;
      if (!a.valid()) continue;
      EXPECT_EQ(a.t, b.t) << config;
      EXPECT_EQ(a.primID, b.primID) << config;
      EXPECT_EQ(a.u, b.u) << config;
    }
    // Every truncation gives an error naming the file, never a crash.
    const std::string bytes = read_all(path);
    for (size_t cut : {size_t(0), size_t(100), bytes.size() / 3, bytes.size() - 1}) {
      const std::string p = dir.write("cut.slim", bytes.substr(0, cut));
      const std::string msg = test::error_of([&] { Scene::open(p); });
      EXPECT_NE(msg.find("cut.slim"), std::string::npos) << cut << ": " << msg;
    }
    // A damaged byte in the last chunk's sections: the checksum names a chunk's section.
    std::string damaged = bytes;
    damaged[bytes.size() - 8] ^= 0x40;
    const std::string p = dir.write("damaged.slim", damaged);
    const std::string msg = test::error_of([&] { Scene::open(p); });
    EXPECT_NE(msg.find("section 'c"), std::string::npos) << msg;
  }
  // The partition's temporary files are gone.
  for (const std::string& name : dir.names())
    EXPECT_EQ(name.find("slimrt-chunks"), std::string::npos) << name;
}

TEST(JoinedScene, PrimitiveIdsAreTheInputFaces) {
  // A terrain's faces are rows: each chunk maps back through a few id runs.
  const PolyMesh terrain = load("terrain:96");
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 1000;
  const BuildOptions opt = BuildOptions::from_config("bvh8-tri4v");
  const Scene joined = Scene::build_chunked("terrain:96", opt, chunking);
  const Scene whole = Scene::build(terrain, opt);
  EXPECT_GE(test::detail_value(joined, "chunks"), 18);
  EXPECT_LT(test::detail_value(joined, "id_runs"), double(terrain.face_count()) / 4);
  // Straight down onto every face's centre: the face itself.
  int checked = 0;
  const std::vector<uint64_t> offsets = terrain.face_offsets();
  for (uint32_t f = 0; f < terrain.face_count(); f += 4) {
    Vec3f c(0, 0, 0);
    const uint32_t* idx = terrain.face_indices.data() + offsets[f];
    for (uint32_t k = 0; k < terrain.face_sizes[f]; ++k) c = c + terrain.positions[idx[k]];
    c = c * (1.0f / float(terrain.face_sizes[f]));
    Ray r;  // from above (z is up in the procedural terrains)
    r.org = c + Vec3f(0, 0, 1);
    r.dir = Vec3f(0, 0, -1);
    const Hit a = whole.intersect(r), b = joined.intersect(r);
    ASSERT_TRUE(b.valid());
    EXPECT_EQ(a.primID, b.primID);
    EXPECT_EQ(a.t, b.t);
    ++checked;
  }
  EXPECT_GT(checked, 2000);
}

}  // namespace
}  // namespace slim
