// The registry of configurations (src/api/registry.cpp): every row checked against the scene it
// builds, so that a property stated in a row (lossy, own geometry, applicability) is what the
// format does; and BuildOptions' orthogonal fields and their checks.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <optional>
#include <set>
#include <string>

#include "embree_scene.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// A mesh every format encodes with a nonzero error: a noisy terrain (lossy grids move the grid
// vertices between the corners), plus a second mesh with a hexagon (costa tessellates it with
// GLU, not as a fan) so that costa's own geometry differs from the fan triangulation.
std::vector<PolyMesh> registry_meshes() {
  std::vector<PolyMesh> v;
  v.push_back(make_terrain(24));
  PolyMesh hex;
  hex.name = "hexagon";
  for (int k = 0; k < 6; ++k) {
    const float a = float(k) * 1.0471976f;
    hex.positions.push_back(
        {0.3f + 0.2f * std::cos(a), 0.3f + 0.2f * std::sin(a), 0.9f + 0.05f * float(k % 2)});
    hex.face_indices.push_back(uint32_t(k));
  }
  hex.face_sizes.push_back(6);
  v.push_back(hex);
  return v;
}

}  // namespace

TEST(Registry, NamesAreUniqueAndRoundTrip) {
  std::set<std::string> seen;
  for (const ConfigInfo& c : configs()) {
    EXPECT_TRUE(seen.insert(c.name).second) << c.name << " twice";
    EXPECT_EQ(BuildOptions::from_config(c.name).config_name(), c.name);
    EXPECT_EQ(&config_info(c.name), find_config(c.name));
    EXPECT_FALSE(c.summary.empty()) << c.name;
    EXPECT_FALSE(c.error_bound.empty()) << c.name;
    EXPECT_EQ(describe(c.options).lossy, c.lossy) << c.name;
    EXPECT_EQ(describe(c.options).own_geometry, c.own_geometry) << c.name;
  }
  EXPECT_EQ(all_config_names().size(), configs().size());
  EXPECT_EQ(find_config("no-such-config"), nullptr);
  try {
    config_info("no-such-config");
    ADD_FAILURE() << "an unknown name must throw";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no-such-config"), std::string::npos) << what;
    EXPECT_NE(what.find("bvh8-tri4v"), std::string::npos) << "lists the known names: " << what;
  }
}

// Each row against the scene it builds: lossy exactly when error_bound() > 0, own geometry
// exactly when decoded_triangles() returns triangles, and the scene's options are the row's.
TEST(Registry, EveryRowMatchesItsScene) {
  const std::vector<PolyMesh> meshes = registry_meshes();
  std::vector<const PolyMesh*> ptrs;
  for (const PolyMesh& m : meshes) ptrs.push_back(&m);
  int lossy = 0, own = 0;
  for (const ConfigInfo& c : configs()) {
    SCOPED_TRACE(c.name);
    Scene s = Scene::build(ptrs, c.options);
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    EXPECT_EQ(s.options().config_name(), c.name);
    EXPECT_EQ(s.is_lossy(), c.lossy);
    EXPECT_EQ(s.error_bound() > 0.0, c.lossy) << "error_bound " << s.error_bound();
    EXPECT_TRUE(std::isfinite(s.error_bound()));
    // The bound is small against the scene: every vertex within 1% of the box diagonal.
    EXPECT_LT(s.error_bound(), 0.01 * double(length(s.bounds().size())));
    const std::optional<DecodedTriangles> t = decoded_triangles(s, ptrs);
    EXPECT_EQ(t.has_value(), c.own_geometry);
    if (t) {
      EXPECT_GT(t->size(), 0u);
      EXPECT_EQ(t->vertices.size(), 3 * t->size());
      EXPECT_EQ(t->geom.size(), t->size());
    }
    lossy += c.lossy;
    own += c.own_geometry;
  }
  // Lossy: 4 grid rows, the 8 costa rows with V and `cluster`; own geometry: those and the 8
  // costa rows without V.
  EXPECT_EQ(lossy, 13);
  EXPECT_EQ(own, 21);
}

// The triangles a built scene decodes from its leaves (Scene::decoded_triangles) are those of the
// rebuild from the input (decoded_triangles(meshes, options)), bit for bit, each with the same
// input mesh and face, in another order (the scene's leaf order); under every node layout.
TEST(Registry, SceneDecodesTheTrianglesOfTheRebuild) {
  const std::vector<PolyMesh> meshes = registry_meshes();
  std::vector<const PolyMesh*> ptrs;
  for (const PolyMesh& m : meshes) ptrs.push_back(&m);
  // A triangle as 9 coordinate bit patterns (corners rotated to start at the smallest, winding
  // kept), then its mesh and face; a decoding as the sorted keys.
  using Key = std::array<uint32_t, 11>;
  auto keys = [](const DecodedTriangles& t) {
    std::vector<Key> k(t.size());
    for (size_t i = 0; i < t.size(); ++i) {
      std::array<std::array<uint32_t, 3>, 3> c;
      std::memcpy(c.data(), &t.vertices[3 * i], 36);
      const size_t r = size_t(std::min_element(c.begin(), c.end()) - c.begin());
      for (size_t v = 0; v < 3; ++v)
        for (size_t a = 0; a < 3; ++a) k[i][3 * v + a] = c[(r + v) % 3][a];
      k[i][9] = t.geom[i];
      k[i][10] = t.face[i];
    }
    std::sort(k.begin(), k.end());
    return k;
  };
  int decoded = 0;
  for (const ConfigInfo& c : configs()) {
    if (!c.own_geometry) continue;
    for (Nodes nodes : {Nodes::Bvh8, Nodes::QBvh8, Nodes::CompressedLeaf}) {
      BuildOptions o = c.options;
      o.nodes = nodes;
      try {
        o.check();
      } catch (const Error&) {
        continue;  // a leaf that lives in multi-leaf nodes only
      }
      SCOPED_TRACE(c.name + " nodes " + std::to_string(int(nodes)));
      const Scene s = Scene::build(ptrs, o);
      const std::optional<DecodedTriangles> mine = s.decoded_triangles();
      ASSERT_TRUE(mine.has_value());
      const std::optional<DecodedTriangles> rebuilt = decoded_triangles(ptrs, o);
      ASSERT_TRUE(rebuilt.has_value());
      EXPECT_EQ(keys(*mine), keys(*rebuilt));
      decoded++;
    }
  }
  EXPECT_GT(decoded, 20);
  // Formats without their own geometry have none to give.
  EXPECT_FALSE(Scene::build(ptrs, BuildOptions::from_config("bvh8-tri4v")).decoded_triangles());
}

// A lossy format whose decoded vertices lie within error_bound() of the input: the decoded
// triangles' vertices, matched to the nearest input vertex, never farther than the bound.
TEST(Registry, DecodedVerticesWithinErrorBound) {
  const PolyMesh terrain = make_terrain(24);
  for (const ConfigInfo& c : configs()) {
    if (!c.lossy) continue;
    SCOPED_TRACE(c.name);
    const Scene s = Scene::build(terrain, c.options);
    const DecodedTriangles t = *decoded_triangles({&terrain}, c.options);
    double worst = 0;
    for (size_t i = 0; i < t.size(); ++i) {
      // The input face of decoded triangle i: one of its corners is nearest each decoded vertex.
      const uint32_t f = t.face[i];
      for (int k = 0; k < 3; ++k) {
        const Vec3f p = t.vertices[3 * i + k];
        double best = 1e30;
        for (uint32_t j = 0; j < terrain.face_sizes[f]; ++j)
          best = std::min(best,
                          double(length(p - terrain.positions[terrain.face_indices[4 * f + j]])));
        worst = std::max(worst, best);
      }
    }
    EXPECT_LE(worst, s.error_bound() * (1 + 1e-6) + 1e-12);
    EXPECT_GT(worst, 0.0);
  }
}

// Embree's anchors that do not fit a mesh say so with the typed error; slimrt's rows fit every
// valid mesh.
TEST(Registry, NotApplicableIsTyped) {
  const PolyMesh soup = random_soup(50, 3);
  EXPECT_THROW(bench::EmbreeScene({&soup}, "embree-quad"), NotApplicable);
  EXPECT_THROW(bench::EmbreeScene({&soup}, "embree-grid"), NotApplicable);
  const PolyMesh terrain = make_terrain(8);
  EXPECT_NO_THROW(bench::EmbreeScene({&terrain}, "embree-quad"));
  for (const ConfigInfo& c : configs()) EXPECT_NO_THROW(Scene::build(soup, c.options)) << c.name;
}

// BuildOptions: each field reaches the build, and combinations a leaf cannot live in are refused.
TEST(Registry, BuildOptionsAreCheckedAndOrthogonal) {
  const PolyMesh m = make_terrain(12);
  BuildOptions o = BuildOptions::from_config("clbvh-compact");
  o.nodes = Nodes::Bvh8;
  EXPECT_THROW(Scene::build(m, o), Error);
  o = BuildOptions::from_config("lossy-grid-shared");
  o.nodes = Nodes::QBvh8;
  EXPECT_THROW(Scene::build(m, o), Error);
  o = BuildOptions::from_config("lossy-grid");
  o.grid_parts = 3;
  EXPECT_THROW(Scene::build(m, o), Error);
  o = BuildOptions::from_config("costa-PFV");
  o.costa = "VF";
  EXPECT_THROW(Scene::build(m, o), Error);
  o = BuildOptions::from_config("bvh8-tri4v");
  o.sah_bins = 1;
  EXPECT_THROW(Scene::build(m, o), Error);

  // The collapse rule changes the node count of a BVH8 but not its hits.
  BuildOptions optimal = BuildOptions::from_config("bvh8-tri4v");
  optimal.collapse = Collapse::Optimal;
  BuildOptions slots = optimal;
  slots.collapse = Collapse::Slots;
  const Scene a = Scene::build(m, optimal), b = Scene::build(m, slots);
  EXPECT_NE(a.memory().bvh_bytes, b.memory().bvh_bytes);
  const Agreement ag = compare_with_reference(b, {&m}, 300, 4);
  EXPECT_EQ(ag.agree, ag.rays);

  // Pairing options reach the pairing: with the pre-scan threshold above 1 the heuristic runs on
  // a quad mesh (whose input order pairs perfectly), and reports its figures.
  BuildOptions pairs = BuildOptions::from_config("bvh8-pairs");
  pairs.pairing_options.prescan_threshold = 2.0;
  auto detail = [](const Scene& s, const char* key) {
    for (const auto& [k, v] : stat_details(s))
      if (k == key) return v;
    return -1.0;
  };
  EXPECT_EQ(detail(Scene::build(m, pairs), "prescan_skipped"), 0.0);
  EXPECT_EQ(detail(Scene::build(m, BuildOptions::from_config("bvh8-pairs")), "prescan_skipped"),
            1.0);
}
