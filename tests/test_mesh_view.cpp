// Scene::build from MeshView (arrays the caller keeps, read in place): for every registry
// configuration the same scene as the build of a PolyMesh holding the same arrays (hits, memory,
// statistics), on a triangle array (one face size for all faces) and on a mesh of triangles,
// quads and n-gons (an array of face sizes); malformed views refused as malformed PolyMeshes are.
#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// A PolyMesh's arrays copied into separate buffers (as a user's own arrays would be), and a view
// of them; the view never points into the PolyMesh.
struct OwnArrays {
  std::vector<Vec3f> positions;
  std::vector<uint32_t> sizes, indices;
  MeshView view;

  // uniform: the view has no array of face sizes (every face must have `uniform` corners).
  OwnArrays(const PolyMesh& m, uint32_t uniform)
      : positions(m.positions), sizes(m.face_sizes), indices(m.face_indices) {
    view.name = m.name;
    view.positions = positions;
    view.face_indices = indices;
    view.face_sizes = uniform ? FaceSizes::uniform(uniform, m.face_sizes.size()) : FaceSizes(sizes);
  }
  OwnArrays(const OwnArrays&) = delete;
};

// Triangles with a vertex of NaN (faces skipped at build) and two far apart clusters.
PolyMesh triangle_mesh() {
  PolyMesh m = random_soup(1500, 11);
  PolyMesh s = icosphere(3);  // 1280 triangles, closed and welded
  const uint32_t base = uint32_t(m.positions.size());
  for (const Vec3f& p : s.positions) m.positions.push_back(p * 0.3f + Vec3f(0.5f, 0.5f, 0.5f));
  for (uint32_t i : s.face_indices) m.face_indices.push_back(base + i);
  m.face_sizes.resize(m.face_indices.size() / 3, 3);
  m.positions[17].x = std::numeric_limits<float>::quiet_NaN();
  m.name = "triangles";
  return m;
}

// A terrain of quads whose cells are, in turn, kept as quads, split into two triangles, or merged
// with their right neighbour into a hexagon (6 corners), plus one heptagon: triangles, quads and
// n-gons in one mesh.
PolyMesh mixed_mesh() {
  const PolyMesh t = make_terrain(24);
  PolyMesh m;
  m.name = "mixed";
  m.positions = t.positions;
  const uint32_t n = 24, row = n + 1;
  for (uint32_t y = 0; y < n; ++y)
    for (uint32_t x = 0; x < n; ++x) {
      const uint32_t a = y * row + x, b = a + 1, c = a + row + 1, d = a + row;
      const uint32_t kind = (x + y) % 4;
      if (kind <= 1) {
        m.face_indices.insert(m.face_indices.end(), {a, b, c, d});
        m.face_sizes.push_back(4);
      } else if (kind == 2) {
        m.face_indices.insert(m.face_indices.end(), {a, b, c, a, c, d});
        m.face_sizes.insert(m.face_sizes.end(), {3, 3});
      } else if (x + 1 < n) {
        // This cell and the next one as a hexagon; the next cell is then skipped.
        m.face_indices.insert(m.face_indices.end(), {a, b, b + 1, c + 1, c, d});
        m.face_sizes.push_back(6);
        ++x;
      } else {
        m.face_indices.insert(m.face_indices.end(), {a, b, c, d});
        m.face_sizes.push_back(4);
      }
    }
  const uint32_t base = uint32_t(m.positions.size());
  for (int k = 0; k < 7; ++k) {
    const float a = float(k) * 0.8975979f;
    m.positions.push_back({0.5f + 0.2f * std::cos(a), 0.5f + 0.2f * std::sin(a), 1.5f});
    m.face_indices.push_back(base + uint32_t(k));
  }
  m.face_sizes.push_back(7);
  return m;
}

// The message of the build's slim::Error, or "" with the scene built.
std::string try_build(Scene& s, const auto& meshes, const BuildOptions& opt) {
  return error_of([&] { s = Scene::build(meshes, opt); });
}

// Builds `config` from the PolyMeshes and from the views and checks that the scenes agree.
void expect_same_scene(const std::vector<const PolyMesh*>& meshes,
                       const std::vector<const MeshView*>& views, const std::string& config) {
  SCOPED_TRACE(config);
  const BuildOptions opt = BuildOptions::from_config(config);
  Scene a, b;
  const std::string ea = try_build(a, meshes, opt), eb = try_build(b, views, opt);
  ASSERT_EQ(ea, eb);
  // Every configuration applies to these meshes: a refusal (even an equal one) is a failure.
  ASSERT_EQ(ea, "");

  const MemoryStats ma = a.memory(), mb = b.memory();
  EXPECT_EQ(ma.geometry_bytes, mb.geometry_bytes);
  EXPECT_EQ(ma.bvh_bytes, mb.bvh_bytes);
  EXPECT_EQ(ma.other_bytes, mb.other_bytes);
  EXPECT_EQ(ma.triangles, mb.triangles);
  const SceneStats& sa = a.stats();
  const SceneStats& sb = b.stats();
  EXPECT_EQ(sa.input_faces, sb.input_faces);
  EXPECT_EQ(sa.triangles, sb.triangles);
  EXPECT_EQ(sa.skipped_faces, sb.skipped_faces);
  EXPECT_EQ(sa.primitives, sb.primitives);
  const StatDetails& da = stat_details(a);
  const StatDetails& db = stat_details(b);
  ASSERT_EQ(da.size(), db.size());
  for (size_t i = 0; i < da.size(); ++i) {
    const std::string& name = da[i].first;
    EXPECT_EQ(name, db[i].first);
    // Times ("pairing_s", ...) differ from run to run; every other figure is the build's.
    if (name.size() > 2 && name.compare(name.size() - 2, 2, "_s") == 0) continue;
    EXPECT_EQ(da[i].second, db[i].second) << name;
  }
  EXPECT_EQ(a.error_bound(), b.error_bound());
  EXPECT_EQ(config_info(config).promised_error(meshes), config_info(config).promised_error(views));

  Rng rng(5, 1);
  const Box3f box = a.bounds();
  int hits = 0, differ = 0;
  for (int i = 0; i < 3000; ++i) {
    const Ray r = random_ray(rng, box);
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    hits += ha.valid();
    const bool same = ha.geomID == hb.geomID && ha.primID == hb.primID &&
                      std::memcmp(&ha.t, &hb.t, sizeof(float)) == 0 && ha.u == hb.u && ha.v == hb.v;
    if (!same || a.occluded(r) != b.occluded(r)) ++differ;
  }
  EXPECT_EQ(differ, 0);
  EXPECT_GT(hits, 300);  // the rays do meet the meshes
}

}  // namespace

TEST(MeshView, TriangleArrayBuildsThePolyMeshScene) {
  const PolyMesh m = triangle_mesh();
  const OwnArrays own(m, 3);
  ASSERT_EQ(own.view.face_sizes.data(), nullptr);  // no array of face sizes
  for (const ConfigInfo& c : configs()) expect_same_scene({&m}, {&own.view}, c.name);
}

TEST(MeshView, PolygonMeshesBuildThePolyMeshScene) {
  const PolyMesh mixed = mixed_mesh();
  const PolyMesh tris = triangle_mesh();
  const OwnArrays a(mixed, 0), b(tris, 3);
  uint64_t quads = 0, ngons = 0;
  for (uint32_t s : mixed.face_sizes) (s == 4 ? quads : ngons) += s >= 4;
  ASSERT_GT(quads, 50u);
  ASSERT_GT(ngons, 50u);
  for (const ConfigInfo& c : configs())
    expect_same_scene({&mixed, &tris}, {&a.view, &b.view}, c.name);
}

TEST(MeshView, ViewOfPolyMeshReadsItInPlace) {
  const PolyMesh m = mixed_mesh();
  const MeshView v(m);
  EXPECT_EQ(v.positions.data(), m.positions.data());
  EXPECT_EQ(v.face_indices.data(), m.face_indices.data());
  EXPECT_EQ(v.face_sizes.data(), m.face_sizes.data());
  EXPECT_EQ(v.fan_triangle_count(), m.fan_triangle_count());
  EXPECT_EQ(v.face_offsets(), m.face_offsets());
  const OwnArrays t(triangle_mesh(), 3);
  EXPECT_EQ(t.view.fan_triangle_count(), t.view.face_count());
  EXPECT_EQ(t.view.face_offsets().back(), t.view.face_indices.size());
}

// Each malformed view is refused with the message of the same malformed PolyMesh (naming the
// mesh, the face and the value).
TEST(MeshView, MalformedViewsAreRefusedAsPolyMeshesAre) {
  PolyMesh m;
  m.name = "bad";
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {2, 0, 0}, {0, 2, 0}};
  m.face_indices = {0, 1, 2, 1, 3, 2, 2, 3, 9};  // face 2 has vertex 9 of 6
  m.face_sizes = {3, 3, 3};
  for (const ConfigInfo& c : configs()) {
    SCOPED_TRACE(c.name);
    const BuildOptions opt = c.options;
    const OwnArrays tri(m, 3);
    const std::string e = error_of([&] { Scene::build(tri.view, opt); });
    EXPECT_EQ(e, error_of([&] { Scene::build(m, opt); }));
    EXPECT_NE(e.find("bad: face 2: vertex index 9 out of range (6 vertices)"), std::string::npos)
        << e;
  }
  const BuildOptions opt;
  // An index out of range, through an array of face sizes.
  {
    const OwnArrays a(m, 0);
    EXPECT_EQ(error_of([&] { Scene::build(a.view, opt); }),
              error_of([&] { Scene::build(m, opt); }));
  }
  m.face_indices.back() = 5;
  // Face sizes that do not add up to the corners: a uniform size of 4 over 9 corners.
  {
    const OwnArrays a(m, 4);
    PolyMesh p = m;
    p.face_sizes = {4, 4, 4};
    const std::string e = error_of([&] { Scene::build(a.view, opt); });
    EXPECT_EQ(e, error_of([&] { Scene::build(p, opt); }));
    EXPECT_NE(e.find("face sizes add up to 12 corners but face_indices has 9"), std::string::npos)
        << e;
  }
  // Faces of fewer than 3 corners.
  {
    PolyMesh p = m;
    p.face_sizes = {2, 2, 2, 3};
    const OwnArrays a(p, 2);
    const std::string e = error_of([&] { Scene::build(a.view, opt); });
    EXPECT_NE(e.find("bad: face 0: has 2 vertices; expected at least 3"), std::string::npos) << e;
    const OwnArrays b(p, 0);
    EXPECT_EQ(error_of([&] { Scene::build(b.view, opt); }),
              error_of([&] { Scene::build(p, opt); }));
  }
  // A null array that claims entries.
  {
    MeshView v = MeshView::triangles(nullptr, 6, m.face_indices.data(), 3, "null");
    EXPECT_NE(error_of([&] { Scene::build(v, opt); }).find("null: positions is null but has 6"),
              std::string::npos);
    v = MeshView::triangles(m.positions.data(), 6, nullptr, 3, "null");
    EXPECT_NE(error_of([&] { Scene::build(v, opt); }).find("null: face_indices is null"),
              std::string::npos);
    v = MeshView::triangles(m.positions.data(), 6, m.face_indices.data(), 3, "null");
    v.face_sizes = FaceSizes(std::span<const uint32_t>(static_cast<const uint32_t*>(nullptr), 3));
    EXPECT_NE(error_of([&] {
                Scene::build(v, opt);
              }).find("null: face 0: has 0 vertices; expected at least 3"),
              std::string::npos);
  }
  // The well-formed mesh builds.
  const OwnArrays ok(m, 3);
  EXPECT_EQ(error_of([&] { Scene::build(ok.view, opt); }), "");
}
