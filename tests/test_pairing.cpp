// Triangle pairing (A. Aman, S. Fenney, "Fast Triangle Pairing for Ray Tracing", Imagination
// Technologies) and the pair leaves: pairing invariants against a std::sort reference of the
// paper's algorithm, the key forms, weld, the window-2 baseline and the pre-scan, and bvh8-pairs /
// clbvh-pairs against the brute-force reference.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <numeric>
#include <set>
#include <tuple>

#include "api/bvh_scene.h"
#include "core/simd_ext.h"
#include "mesh/pairing.h"
#include "mesh/triangulate.h"
#include "pairing_orders.h"
#include "pairing_reference.h"
#include "prim/pairs.h"
#include "slimrt/pairing.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// ---- meshes ------------------------------------------------------------------------------------

// A welded (n+1)^2-vertex grid over [0,1]^2, jittered in x/y, random heights; each quad split
// along a random diagonal; triangle order shuffled, corners rotated at random, and (if
// `flip_some`) some triangles wound the other way (inconsistent orientation).
PolyMesh jittered_grid(int n, uint32_t seed, bool flip_some = true) {
  Rng rng(seed, 11);
  PolyMesh m;
  m.name = "jittered_grid";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      float jx = (i > 0 && i < n) ? (rng.uniform() - 0.5f) * 0.6f : 0.0f;
      float jy = (j > 0 && j < n) ? (rng.uniform() - 0.5f) * 0.6f : 0.0f;
      m.positions.push_back({(i + jx) / n, (j + jy) / n, 0.1f * rng.uniform()});
    }
  std::vector<std::array<uint32_t, 3>> tris;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      if (rng.next() & 1) {
        tris.push_back({a, b, c});
        tris.push_back({a, c, d});
      } else {
        tris.push_back({a, b, d});
        tris.push_back({b, c, d});
      }
    }
  for (size_t i = tris.size(); i > 1; --i) std::swap(tris[i - 1], tris[rng.next() % i]);
  for (auto& t : tris) {
    int r = rng.next() % 3;
    std::rotate(t.begin(), t.begin() + r, t.end());
    if (flip_some && rng.next() % 4 == 0) std::swap(t[1], t[2]);
    m.face_indices.insert(m.face_indices.end(), t.begin(), t.end());
    m.face_sizes.push_back(3);
  }
  return m;
}

// The same triangles with 3 own vertices each (nothing welded), positions bit-identical.
PolyMesh unweld(const PolyMesh& m) {
  PolyMesh u;
  u.name = m.name + "_unwelded";
  for (uint32_t idx : m.face_indices) {
    u.face_indices.push_back(uint32_t(u.positions.size()));
    u.positions.push_back(m.positions[idx]);
  }
  u.face_sizes = m.face_sizes;
  return u;
}

// Closed cube-sphere: 6 faces of n x n quads projected to a jittered sphere, welded, split into
// triangles along alternating diagonals, shuffled.
PolyMesh closed_sphere(int n, uint32_t seed) {
  std::map<std::tuple<int, int, int>, uint32_t> ids;
  PolyMesh m;
  m.name = "cube_sphere";
  Rng rng(seed, 5);
  auto vertex = [&](int x, int y, int z) {  // integer lattice point on the cube surface
    auto key = std::make_tuple(x, y, z);
    auto it = ids.find(key);
    if (it != ids.end()) return it->second;
    Vec3f p(2.0f * x / n - 1.0f, 2.0f * y / n - 1.0f, 2.0f * z / n - 1.0f);
    m.positions.push_back(normalize(p) * (1.0f + 0.03f * (rng.uniform() - 0.5f)));
    return ids[key] = uint32_t(m.positions.size() - 1);
  };
  std::vector<std::array<uint32_t, 3>> tris;
  for (int axis = 0; axis < 3; ++axis)
    for (int side = 0; side < 2; ++side)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i) {
          auto at = [&](int a, int b) {
            int c[3];
            c[axis] = side * n;
            c[(axis + 1) % 3] = a;
            c[(axis + 2) % 3] = b;
            return vertex(c[0], c[1], c[2]);
          };
          uint32_t a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
          if (side == 0) std::swap(b, d);  // outward winding
          if ((i + j) & 1) {
            tris.push_back({a, b, c});
            tris.push_back({a, c, d});
          } else {
            tris.push_back({a, b, d});
            tris.push_back({b, c, d});
          }
        }
  for (size_t i = tris.size(); i > 1; --i) std::swap(tris[i - 1], tris[rng.next() % i]);
  for (auto& t : tris) {
    m.face_indices.insert(m.face_indices.end(), t.begin(), t.end());
    m.face_sizes.push_back(3);
  }
  return m;
}

// An n x n all-quad heightfield (faces in row order): the pre-scan's case.
PolyMesh quad_grid(int n, uint32_t seed) {
  Rng rng(seed, 2);
  PolyMesh m;
  m.name = "quad_grid";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      m.positions.push_back({float(i) / n, float(j) / n, 0.05f * rng.uniform()});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      uint32_t a = j * (n + 1) + i;
      m.face_indices.insert(m.face_indices.end(), {a, a + 1, a + n + 2, a + n + 1});
      m.face_sizes.push_back(4);
    }
  return m;
}

// ---- pairing helpers ---------------------------------------------------------------------------

struct Tri {
  TriangleMesh tm;
  PairingInput in() const {
    return {tm.vertices.data(), tm.vertices.size(), tm.tris.data(), tm.tri_count(),
            tm.geom_ids.data()};
  }
};
Tri triangulate(const PolyMesh& m) { return {triangulate_fan({&m})}; }

// Checks the pairing invariants (tests/pairing_reference.h); returns the pairs as a sorted set of
// (a, b).
PairSet check_pairing(const PairingInput& in, const PairingResult& r, bool by_position) {
  PairSet out;
  EXPECT_EQ(pairing_problem(in, r, by_position, &out), "");
  return out;
}

// ---- pairing tests -----------------------------------------------------------------------------

TEST(Pairing, MatchesSortReferenceAndInvariants) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    PolyMesh m = jittered_grid(40, seed);
    Tri t = triangulate(m);
    PairingResult r = pair_by_edge_heuristic(t.in(), false);
    auto got = check_pairing(t.in(), r, false);
    EXPECT_EQ(got, reference_pairs(t.in())) << "seed " << seed;
    for (EdgeOrder o : {EdgeOrder::FullTable, EdgeOrder::Local})
      EXPECT_EQ(check_pairing(t.in(), pair_in_order(t.in(), o), false), got)
          << "seed " << seed << " order " << int(o);
    EXPECT_GT(r.stats.paired_fraction, 0.9);
    EXPECT_EQ(r.stats.nonmanifold_edges, 0u);
  }
}

TEST(Pairing, LargeIndicesUseTheWideKey) {
  // > 2^16 vertices: the packed key needs more than 64 bits (hi part of the record).
  PolyMesh m = jittered_grid(300, 4);
  ASSERT_GT(m.positions.size(), 65536u);
  Tri t = triangulate(m);
  PairingResult r = pair_by_edge_heuristic(t.in(), false);
  auto ref = reference_pairs(t.in());
  EXPECT_EQ(check_pairing(t.in(), r, false), ref);
  for (EdgeOrder o : {EdgeOrder::FullTable, EdgeOrder::Local})
    EXPECT_EQ(check_pairing(t.in(), pair_in_order(t.in(), o), false), ref);
}

TEST(Pairing, NonManifoldRunsAllOrdersAgree) {
  // A third of the triangles duplicated (some flipped, corners rotated) and all shuffled: many
  // edges of 3 and 4 triangles, and coincident triangle pairs.
  for (uint32_t seed : {3u, 4u}) {
    PolyMesh m = jittered_grid(30, seed);
    Rng rng(seed, 9);
    const size_t F = m.face_count();
    for (size_t f = 0; f < F; ++f) {
      if (rng.next() % 3) continue;
      uint32_t a = m.face_indices[3 * f], b = m.face_indices[3 * f + 1],
               c = m.face_indices[3 * f + 2];
      if (rng.next() & 1) std::swap(b, c);
      m.face_indices.insert(m.face_indices.end(), {b, c, a});
      m.face_sizes.push_back(3);
    }
    Tri t = triangulate(m);
    auto ref = reference_pairs(t.in());
    for (EdgeOrder o : {EdgeOrder::FullTable, EdgeOrder::TwinSort, EdgeOrder::Local}) {
      PairingResult r = pair_in_order(t.in(), o);
      EXPECT_EQ(check_pairing(t.in(), r, false), ref) << "seed " << seed << " order " << int(o);
      EXPECT_GT(r.stats.nonmanifold_edges, 100u);
    }
  }
}

TEST(Pairing, RankSortOfTwinBuckets) {
  // simd::rank_sort16 (find_twins' bucket sort) against std::sort, every size 0..16, keys with
  // and without the top bit (the AVX2 path compares them signed after a bias).
  Rng rng(21, 3);
  for (int rep = 0; rep < 200; ++rep)
    for (size_t k = 0; k <= 16; ++k) {
      std::set<uint64_t> keys;
      while (keys.size() < k) {
        uint64_t x = uint64_t(rng.next()) << 32 | rng.next();
        if (rep % 3 == 0) x &= 0xffffffffull;  // small keys: the shape find_twins sorts
        if (rep % 3 == 1) x |= uint64_t(1) << 63;
        keys.insert(x);
      }
      std::vector<uint64_t> in(keys.begin(), keys.end());
      for (size_t i = in.size(); i > 1; --i) std::swap(in[i - 1], in[rng.next() % i]);
      uint64_t out[16] = {};
      simd::rank_sort16(in.data(), k, out);
      EXPECT_TRUE(std::equal(keys.begin(), keys.end(), out)) << "k " << k << " rep " << rep;
    }
}

TEST(Pairing, HighValenceFansAllOrdersAgree) {
  // Closed fans around a centre vertex of the smallest index: the centre's twin bucket holds
  // 2 x valence half-edges, valence 3..30, so every bucket-sort path of find_twins (rank sort up
  // to 16 entries, insertion sort beyond) meets the reference.
  PolyMesh m;
  Rng rng(17, 2);
  for (int valence = 3; valence <= 30; ++valence) {
    const uint32_t c = uint32_t(m.positions.size());
    const float x0 = float(valence) * 3.0f;
    m.positions.push_back({x0, 0.0f, 0.2f * rng.uniform()});
    for (int i = 0; i < valence; ++i) {
      const float a = 6.2831853f * (float(i) + 0.3f * rng.uniform()) / float(valence);
      m.positions.push_back({x0 + std::cos(a), std::sin(a), 0.2f * rng.uniform()});
    }
    for (int i = 0; i < valence; ++i) {
      const uint32_t f[3] = {c, c + 1 + uint32_t(i), c + 1 + uint32_t((i + 1) % valence)};
      const int r = int(rng.next() % 3);
      for (int k = 0; k < 3; ++k) m.face_indices.push_back(f[(k + r) % 3]);
      m.face_sizes.push_back(3);
    }
  }
  Tri t = triangulate(m);
  std::map<uint32_t, size_t> bucket;  // half-edges per smaller vertex
  for (size_t i = 0; i < t.tm.tris.size(); ++i)
    bucket[std::min(t.tm.tris[i], t.tm.tris[i - i % 3 + (i + 1) % 3])]++;
  size_t largest = 0;
  for (const auto& [v, k] : bucket) largest = std::max(largest, k);
  EXPECT_EQ(largest, 60u);
  auto ref = reference_pairs(t.in());
  EXPECT_GT(ref.size(), 150u);
  for (EdgeOrder o : {EdgeOrder::FullTable, EdgeOrder::TwinSort, EdgeOrder::Local})
    EXPECT_EQ(check_pairing(t.in(), pair_in_order(t.in(), o), false), ref) << "order " << int(o);
}

TEST(Pairing, Deterministic) {
  PolyMesh m = jittered_grid(50, 7);
  Tri t = triangulate(m);
  for (bool coord : {false, true}) {
    PairingResult a = pair_by_edge_heuristic(t.in(), coord);
    PairingResult b = pair_by_edge_heuristic(t.in(), coord);
    ASSERT_EQ(a.pairs.size(), b.pairs.size());
    for (size_t i = 0; i < a.pairs.size(); ++i) {
      EXPECT_EQ(a.pairs[i].a, b.pairs[i].a);
      EXPECT_EQ(a.pairs[i].b, b.pairs[i].b);
      EXPECT_EQ(a.pairs[i].ea, b.pairs[i].ea);
      EXPECT_EQ(a.pairs[i].eb, b.pairs[i].eb);
    }
    EXPECT_EQ(a.unpaired, b.unpaired);
  }
}

TEST(Pairing, CoordinateKeysGiveTheSamePairsOnAWeldedMesh) {
  for (uint32_t seed : {1u, 5u}) {
    PolyMesh m = jittered_grid(60, seed);
    Tri t = triangulate(m);
    auto by_index = check_pairing(t.in(), pair_by_edge_heuristic(t.in(), false), false);
    auto by_coord = check_pairing(t.in(), pair_by_edge_heuristic(t.in(), true), true);
    EXPECT_EQ(by_index, by_coord) << "seed " << seed;
  }
}

TEST(Pairing, UnweldedMeshCoordinateKeysAndWeld) {
  PolyMesh welded = jittered_grid(30, 9);
  PolyMesh m = unweld(welded);
  Tri tw = triangulate(welded), t = triangulate(m);
  auto ref = check_pairing(tw.in(), pair_by_edge_heuristic(tw.in(), false), false);
  // Index keys see no shared vertex at all.
  PairingResult none = pair_by_edge_heuristic(t.in(), false);
  EXPECT_EQ(none.pairs.size(), 0u);
  // Coordinate keys pair by position; weld + index keys pair like the welded mesh.
  PairingOptions o;
  o.augment = false;  // compare the paper's pairing alone
  o.coordinate_keys = true;
  PairingResult coord = pair_triangles(t.in(), o);
  EXPECT_EQ(check_pairing(t.in(), coord, true), ref);
  o.coordinate_keys = false;
  o.weld = true;
  PairingResult w = pair_triangles(t.in(), o);
  EXPECT_EQ(w.stats.welded_vertices, m.positions.size() - welded.positions.size());
  EXPECT_EQ(check_pairing(t.in(), w, true), ref);

  std::vector<uint32_t> remap;
  EXPECT_EQ(weld_positions(m.positions.data(), m.positions.size(), remap),
            m.positions.size() - welded.positions.size());
  for (size_t v = 0; v < remap.size(); ++v) {
    EXPECT_LE(remap[v], v);
    EXPECT_EQ(std::memcmp(&m.positions[v], &m.positions[remap[v]], 12), 0);
    EXPECT_EQ(remap[remap[v]], remap[v]);
  }
}

TEST(Pairing, NonManifoldAndDegenerateEdges) {
  // Four triangles on one edge (0,1), plus triangles with a repeated index.
  PolyMesh m;
  m.positions = {{0, 0, 0}, {1, 1, 0}, {0, 1, 1}, {1, 0, 1}, {1, 0, -1}, {0, 1, -1}, {2, 2, 2}};
  m.face_indices = {0, 1, 2, 1, 0, 3, 0, 1, 4, 1, 0, 5, 6, 6, 2, 2, 6, 6};
  m.face_sizes.assign(6, 3);
  Tri t = triangulate(m);
  PairingResult r = pair_by_edge_heuristic(t.in(), false);
  check_pairing(t.in(), r, false);
  // Runs of 3+ half-edges: (0,1) with 4 triangles, and (2,6) with two half-edges of each
  // degenerate triangle. The first two eligible on (0,1) pair up, then the next two; the
  // degenerate edge (6,6) pairs nothing, but the two degenerate triangles share (2,6).
  EXPECT_EQ(r.stats.nonmanifold_edges, 2u);
  EXPECT_EQ(r.pairs.size(), 3u);
  for (EdgeOrder o : {EdgeOrder::FullTable, EdgeOrder::Local})
    EXPECT_EQ(check_pairing(t.in(), pair_in_order(t.in(), o), false),
              check_pairing(t.in(), r, false));
  PairingResult rc = pair_by_edge_heuristic(t.in(), true);
  check_pairing(t.in(), rc, true);
}

TEST(Pairing, Window2BaselineAndPrescan) {
  // Fan-triangulated quads pair in input order: the pre-scan keeps them.
  PolyMesh q = quad_grid(20, 1);
  Tri t = triangulate(q);
  PairingResult w = window_pairs(t.in());
  check_pairing(t.in(), w, false);
  EXPECT_DOUBLE_EQ(w.stats.paired_fraction, 1.0);
  PairingResult r = pair_triangles(t.in());
  EXPECT_TRUE(r.stats.prescan_skipped);
  EXPECT_DOUBLE_EQ(r.stats.paired_fraction, 1.0);
  EXPECT_EQ(r.stats.half_edges, 0u);
  for (const TrianglePair& p : r.pairs) EXPECT_EQ(t.tm.prim_ids[p.a], t.tm.prim_ids[p.b]);

  // Shuffled triangles rarely pair in order; the heuristic runs and does much better.
  PolyMesh s = jittered_grid(40, 3);
  Tri ts = triangulate(s);
  PairingResult rs = pair_triangles(ts.in());
  EXPECT_FALSE(rs.stats.prescan_skipped);
  // The pre-scan stopped as soon as 1% of the triangles were left out: no full window-2 figure.
  EXPECT_TRUE(std::isnan(rs.stats.window2_paired_fraction));
  EXPECT_LT(pairing_stats(s).window2_paired_fraction, 0.2);
  EXPECT_GT(rs.stats.paired_fraction, 0.9);
  check_pairing(ts.in(), rs, false);

  // A hand-made strip: (0,1,2) (2,1,3) share 1-2; (4,5,6) is alone; (5,6,7) after it shares 5-6.
  PolyMesh h;
  for (int i = 0; i < 8; ++i) h.positions.push_back({float(i), float(i % 2), float(i * i % 3)});
  h.face_indices = {0, 1, 2, 2, 1, 3, 4, 5, 6, 0, 2, 4, 5, 6, 7};
  h.face_sizes.assign(5, 3);
  Tri th = triangulate(h);
  PairingResult wh = window_pairs(th.in());
  ASSERT_EQ(wh.pairs.size(), 1u);
  EXPECT_EQ(wh.pairs[0].a, 0u);
  EXPECT_EQ(wh.pairs[0].b, 1u);
}

TEST(Pairing, AugmentingPathsRepairTheGreedyResult) {
  // Strip t0 t1 t2 t3 (triangle i = p_i p_i+1 p_i+2): the t1-t2 edge has the largest box, so the
  // greedy scan pairs (t1, t2) and strands t0 and t3; the augmenting pass makes (t0,t1) (t2,t3).
  PolyMesh m;
  m.positions = {{-1, 0.5f, 0}, {0, 0, 0}, {0, 1, 0}, {1, 2, 1}, {1, 2, 0}, {2, 2, 0.5f}};
  m.face_indices = {0, 1, 2, 1, 2, 3, 2, 3, 4, 3, 4, 5};
  m.face_sizes.assign(4, 3);
  Tri t = triangulate(m);
  PairingResult g = pair_by_edge_heuristic(t.in(), false);
  ASSERT_EQ(g.pairs.size(), 1u);
  EXPECT_EQ(g.pairs[0].a, 1u);
  EXPECT_EQ(g.pairs[0].b, 2u);
  PairingOptions on;
  on.prescan_threshold = 2.0;  // the strip pairs in input order: no pre-scan shortcut here
  PairingResult r = pair_triangles(t.in(), on);
  auto got = check_pairing(t.in(), r, false);
  EXPECT_EQ(got, (std::set<std::pair<uint32_t, uint32_t>>{{0, 1}, {2, 3}}));
  EXPECT_EQ(r.stats.augmented_pairs, 1u);
  EXPECT_DOUBLE_EQ(r.stats.heuristic_paired_fraction, 0.5);
  EXPECT_DOUBLE_EQ(r.stats.paired_fraction, 1.0);
  PairingOptions off = on;
  off.augment = false;
  EXPECT_EQ(pair_triangles(t.in(), off).pairs.size(), 1u);

  // On larger meshes: never fewer pairs, invariants hold, deterministic.
  for (uint32_t seed : {1u, 2u}) {
    PolyMesh j = jittered_grid(50, seed);
    Tri tj = triangulate(j);
    PairingResult a = pair_triangles(tj.in()), b = pair_triangles(tj.in());
    auto pa = check_pairing(tj.in(), a, false);
    EXPECT_EQ(pa, check_pairing(tj.in(), b, false));
    EXPECT_EQ(a.pairs.size(),
              pair_by_edge_heuristic(tj.in(), false).pairs.size() + a.stats.augmented_pairs);
    PairingOptions c;
    c.coordinate_keys = true;
    check_pairing(tj.in(), pair_triangles(tj.in(), c), true);
  }
}

TEST(Pairing, PublicStats) {
  PolyMesh m = jittered_grid(30, 2);
  PairingStats s = pairing_stats(m);
  EXPECT_EQ(s.triangles, 2u * 30 * 30);
  EXPECT_EQ(s.pairs * 2 + s.unpaired, s.triangles);
  EXPECT_NEAR(s.paired_fraction, double(2 * s.pairs) / double(s.triangles), 1e-12);
  EXPECT_FALSE(s.prescan_skipped);
  EXPECT_LE(s.heuristic_paired_fraction, s.paired_fraction);
  EXPECT_NEAR(s.paired_fraction - s.heuristic_paired_fraction,
              2.0 * double(s.augmented_pairs) / double(s.triangles), 1e-12);
  EXPECT_EQ(s.half_edges, 3 * s.triangles);
  PairingStats q = pairing_stats(quad_grid(10, 1));
  EXPECT_TRUE(q.prescan_skipped);
  EXPECT_DOUBLE_EQ(q.window2_paired_fraction, 1.0);
  EXPECT_GT(q.heuristic_paired_fraction, 0.9);
  PairingStats e = pairing_stats(PolyMesh{});
  EXPECT_EQ(e.triangles, 0u);
}

// ---- pair leaves -------------------------------------------------------------------------------

double detail(const Scene& s, const std::string& key) {
  for (const auto& [k, v] : stat_details(s))
    if (k == key) return v;
  ADD_FAILURE() << "no detail " << key;
  return -1.0;
}

// The paired share of the baseline on the mesh's fan triangles.
double window_pairs_fraction(const PolyMesh& m) {
  Tri t = triangulate(m);
  return window_pairs(t.in()).stats.paired_fraction;
}

class PairConfigs : public ::testing::TestWithParam<const char*> {
 protected:
  // bvh8-pairs-w2: the same leaves over the paper's baseline pairing (in-order window N = 2).
  bool window2() const { return std::string(GetParam()) == "bvh8-pairs-w2"; }
};

TEST_P(PairConfigs, RandomSoupMatchesReference) {
  for (uint32_t seed : {1u, 2u}) {
    PolyMesh m = random_soup(3000, seed);
    Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    Agreement a = compare_with_reference(s, {&m}, 2000, seed);
    EXPECT_GT(a.hits, 500u);
    EXPECT_EQ(a.agree, a.rays) << GetParam() << " seed " << seed;
    // Random vertices: ties are impossible, every hit names the reference's face.
    EXPECT_EQ(a.same_face, a.hits) << GetParam() << " seed " << seed << ":" << a.wrong;
  }
}

TEST_P(PairConfigs, WeldedShuffledMeshMatchesReference) {
  for (uint32_t seed : {1u, 2u}) {
    PolyMesh m = jittered_grid(64, seed);
    Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << why;
    Agreement a = compare_with_reference(s, {&m}, 3000, seed + 10);
    EXPECT_GT(a.hits, 1000u);
    EXPECT_EQ(a.agree, a.rays) << GetParam() << " seed " << seed;
    // Welded: another face only at a shared edge or vertex (checked geometrically), rarely.
    EXPECT_EQ(a.same_face + a.ties, a.hits) << GetParam() << " seed " << seed << ":" << a.wrong;
    EXPECT_LE(a.ties, a.hits / 200) << GetParam() << " seed " << seed;
    auto get = [&](const char* k) { return detail(s, k); };
    if (window2()) {  // the shuffled order pairs poorly in a window of 2
      EXPECT_EQ(get("paired_fraction"), get("window2_paired_fraction"));
      EXPECT_EQ(get("paired_fraction"), window_pairs_fraction(m));
      EXPECT_LT(get("paired_fraction"), 0.5);
      for (const auto& [k, v] : stat_details(s))  // no pre-scan, no heuristic ran
        EXPECT_TRUE(k != "heuristic_paired_fraction" && k != "prescan_skipped") << k;
    } else {
      EXPECT_GT(get("paired_fraction"), 0.9);
      for (const auto& [k, v] : stat_details(s))  // the pre-scan stopped early: not known
        EXPECT_NE(k, "window2_paired_fraction");
    }
    get("pairing_s");  // reported (detail() fails otherwise); a timing, its value is not checked
    EXPECT_EQ(2 * get("pairs") + get("unpaired_triangles"), double(m.face_count()));
    EXPECT_EQ(s.stats().primitives, uint64_t(get("pairs") + get("unpaired_triangles")));
    EXPECT_EQ(s.memory().triangles, m.face_count());
    EXPECT_GT(s.memory().geometry_bytes, 0u);
  }
}

TEST_P(PairConfigs, MixedPolygonsAndSeveralMeshes) {
  PolyMesh a = random_soup(500, 9);
  PolyMesh b = quad_grid(24, 3);
  PolyMesh c = jittered_grid(16, 4);
  // Pentagons/hexagons (fans) of small random polygons.
  PolyMesh d;
  Rng rng(4);
  for (int f = 0; f < 300; ++f) {
    int n = 4 + f % 3;
    Vec3f ctr(rng.uniform(), rng.uniform(), rng.uniform());
    uint32_t base = uint32_t(d.positions.size());
    for (int k = 0; k < n; ++k) {
      float ang = 6.2831853f * k / n;
      d.positions.push_back(
          ctr + Vec3f(std::cos(ang), std::sin(ang), 0.3f * (rng.uniform() - 0.5f)) * 0.03f);
      d.face_indices.push_back(base + k);
    }
    d.face_sizes.push_back(n);
  }
  std::vector<const PolyMesh*> ms = {&a, &b, &c, &d};
  Scene s = Scene::build(ms, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  Agreement ag = compare_with_reference(s, ms, 3000, 5);
  EXPECT_EQ(ag.agree, ag.rays);
  EXPECT_EQ(ag.same_face + ag.ties, ag.hits) << GetParam() << ":" << ag.wrong;
  EXPECT_LE(ag.ties, ag.hits / 200) << GetParam();
  EXPECT_EQ(s.memory().triangles, a.fan_triangle_count() + b.fan_triangle_count() +
                                      c.fan_triangle_count() + d.fan_triangle_count());
}

TEST_P(PairConfigs, SameHitsAsTri4v) {
  // Same face -> the same normal bits (input corner order) and the same barycentrics (up to
  // rounding), and pairs report PrimKind::Pair.
  PolyMesh m = jittered_grid(48, 6);
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  Scene ref = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
  Rng rng(3);
  int same = 0, pairs = 0;
  for (int i = 0; i < 4000; ++i) {
    Ray r = random_ray(rng, s.bounds());
    Hit h = s.intersect(r), g = ref.intersect(r);
    ASSERT_EQ(h.valid(), g.valid());
    if (!h.valid() || h.primID != g.primID) continue;
    same++;
    pairs += h.kind == PrimKind::Pair;
    EXPECT_EQ(std::memcmp(&h.Ng, &g.Ng, sizeof(Vec3f)), 0) << i;
    EXPECT_NEAR(h.t, g.t, 1e-5f * std::max(1.0f, g.t));
    EXPECT_NEAR(h.u, g.u, 1e-4f);
    EXPECT_NEAR(h.v, g.v, 1e-4f);
    EXPECT_EQ(h.geomID, g.geomID);
  }
  EXPECT_GT(same, 1000);
  if (window2()) {
    EXPECT_GT(pairs, 0);
  } else {
    EXPECT_GT(pairs, same * 8 / 10);
  }
}

TEST_P(PairConfigs, DegenerateAndDuplicateTriangles) {
  PolyMesh m;
  for (int i = 0; i < 400; ++i) {
    uint32_t b = uint32_t(m.positions.size());
    m.positions.push_back({0, 0, 0});
    m.positions.push_back({1, 0, 0});
    m.positions.push_back(i % 2 ? Vec3f(0, 1, 0) : Vec3f(2, 0, 0));  // odd: real, even: degenerate
    m.face_sizes.push_back(3);
    m.face_indices.insert(m.face_indices.end(), {b, b + 1, b + 2});
  }
  // A triangle with a repeated index and a closed pair of coincident, opposite triangles.
  m.positions.push_back({5, 5, 5});
  uint32_t x = uint32_t(m.positions.size() - 1);
  m.face_sizes.insert(m.face_sizes.end(), {3, 3, 3});
  m.face_indices.insert(m.face_indices.end(), {x, x, 0, 1, 0, 2, 1, 2, 0});
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  Ray r;
  r.org = Vec3f(0.25f, 0.25f, 1);
  r.dir = Vec3f(0, 0, -1);
  Hit h = s.intersect(r);
  ASSERT_TRUE(h.valid());
  EXPECT_TRUE(h.primID % 2 == 1 || h.primID >= 400);
  EXPECT_FLOAT_EQ(h.t, 1.0f);
  EXPECT_TRUE(s.occluded(r));
}

TEST_P(PairConfigs, EmptyAndSingleTriangle) {
  PolyMesh empty;
  Scene s = Scene::build(empty, BuildOptions::from_config(GetParam()));
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << why;
  Ray r;
  r.org = Vec3f(0, 0, -1);
  r.dir = Vec3f(0, 0, 1);
  EXPECT_FALSE(s.intersect(r).valid());
  PolyMesh one;
  one.positions = {{-1, -1, 0}, {1, -1, 0}, {0, 1, 0}};
  one.face_sizes = {3};
  one.face_indices = {0, 1, 2};
  Scene s1 = Scene::build(one, BuildOptions::from_config(GetParam()));
  EXPECT_TRUE(s1.validate(&why)) << why;
  Hit h = s1.intersect(r);
  ASSERT_TRUE(h.valid());
  EXPECT_FLOAT_EQ(h.t, 1.0f);
  EXPECT_EQ(h.primID, 0u);
  EXPECT_EQ(h.kind, PrimKind::Triangle);
  EXPECT_GT(h.Ng.z, 0.0f);
}

TEST_P(PairConfigs, WatertightClosedSphere) {
  PolyMesh m = closed_sphere(48, 3);  // 27648 triangles
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  Rng rng(8, 1);
  uint64_t rays = 0, leaks = 0;
  auto inside = [&] {
    return Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f) * 0.8f;
  };
  auto shoot = [&](Vec3f org, Vec3f target) {
    Ray r;
    r.org = org;
    r.dir = target - org;  // aimed exactly at a vertex or an edge midpoint
    rays++;
    leaks += !s.intersect(r).valid();
    leaks += !s.occluded(r);
  };
  for (const Vec3f& p : m.positions) shoot(inside(), p);
  for (size_t i = 0; i < m.face_indices.size(); i += 3)
    for (int k = 0; k < 3; ++k)
      shoot(inside(),
            (m.positions[m.face_indices[i + k]] + m.positions[m.face_indices[i + (k + 1) % 3]]) *
                0.5f);
  for (int i = 0; i < 100000; ++i)
    shoot(inside(),
          inside() + Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f));
  EXPECT_EQ(leaks, 0u) << GetParam() << ": " << leaks << " of " << rays << " rays leaked";
}

TEST_P(PairConfigs, ProceduralTerrain) {
  const PolyMesh m = make_terrain(64);
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  Agreement a = compare_with_reference(s, {&m}, 1500, 4);
  EXPECT_EQ(a.agree, a.rays);
  EXPECT_EQ(a.same_face + a.ties, a.hits) << GetParam() << ":" << a.wrong;
  EXPECT_LE(a.ties, a.hits / 200) << GetParam();
  if (!window2()) {
    EXPECT_EQ(detail(s, "prescan_skipped"), 1.0);  // all quads, in order
  }
  EXPECT_EQ(detail(s, "paired_fraction"), 1.0);
}

TEST_P(PairConfigs, CountsTrianglesTested) {
  PolyMesh m = jittered_grid(48, 8);
  Scene s = Scene::build(m, BuildOptions::from_config(GetParam()));
  Scene t = Scene::build(m, BuildOptions::from_config("bvh8-tri4v"));
  TraversalCounters cs, ct;
  Rng rng(2);
  for (int i = 0; i < 3000; ++i) {
    Ray r = random_ray(rng, s.bounds());
    intersect_counted(s, r, cs);
    intersect_counted(t, r, ct);
  }
  EXPECT_EQ(cs.rays, ct.rays);
  EXPECT_GT(cs.prim_tests, 0u);
  EXPECT_GT(cs.box_tests, 0u);
  // Records: a pair counts once, a lone triangle once; without pairs, one per triangle.
  EXPECT_EQ(ct.prim_records, ct.prim_tests);
  EXPECT_LT(cs.prim_records, cs.prim_tests);
  EXPECT_GE(2 * cs.prim_records, cs.prim_tests);
  if (!window2()) {
    EXPECT_LT(cs.prim_records * 10, cs.prim_tests * 6);  // > 80% paired
  }
}

INSTANTIATE_TEST_SUITE_P(Pair, PairConfigs,
                         ::testing::Values("bvh8-pairs", "clbvh-pairs", "bvh8-pairs-w2"));

// Pair leaves under every node layout (the registry names BVH8 and compressed-leaf nodes; QBVH8
// is a combination without a row) hit what the fan triangles hit.
TEST(PairScene, EveryNodeLayout) {
  // Random soup: ties are practically impossible, so every ray agrees, with the same face.
  PolyMesh m = random_soup(300, 7);
  for (Nodes n : {Nodes::Bvh8, Nodes::QBvh8, Nodes::CompressedLeaf}) {
    BuildOptions o = BuildOptions::from_config("bvh8-pairs");
    o.nodes = n;
    Scene s = Scene::build(m, o);
    std::string why;
    ASSERT_TRUE(s.validate(&why)) << o.config_name() << ": " << why;
    const Agreement a = compare_with_reference(s, {&m}, 400, 5);
    EXPECT_EQ(a.agree, a.rays) << o.config_name();
    EXPECT_EQ(a.same_face, a.hits) << o.config_name();
    EXPECT_GT(a.hits, 20u) << o.config_name();
  }
}

TEST(PairScene, Pair2LeavesMatchReference) {
  // The 4-wide variant of the leaf (not used by the configurations, see api/scene_pairs.cpp).
  PolyMesh m = jittered_grid(40, 3);
  Tri t = triangulate(m);
  PairingResult pr = pair_triangles(t.in());
  std::vector<PairRef> refs;
  for (const TrianglePair& p : pr.pairs) refs.push_back({p.a, p.b, p.ea, p.eb});
  for (uint32_t u : pr.unpaired) refs.push_back({u, kLoneTriangle, 1, 0});
  const TriangleMesh& tm = t.tm;
  BvhScene<Pair2> s;
  s.build(PairSource{{tm.vertices.data(), tm.tris.data(), tm.geom_ids.data(), tm.prim_ids.data()},
                     refs.data()},
          uint32_t(refs.size()), BuildOptions{});
  std::string why;
  ASSERT_TRUE(s.validate(&why)) << why;
  std::vector<RefTri> ref = reference_triangles({&m});
  Rng rng(5);
  int agree = 0, n = 2000;
  for (int i = 0; i < n; ++i) {
    Ray r = random_ray(rng, s.bounds);
    TravRay tr;
    Hit h;
    if (make_trav_ray(r, RaySetupBounds(s.bounds), tr)) s.intersect(tr, h);
    agree += agrees(h, reference_intersect(ref, r));
    TravRay ta;
    bool occ = make_trav_ray(r, RaySetupBounds(s.bounds), ta) && s.occluded(ta);
    EXPECT_EQ(occ, h.valid());
  }
  EXPECT_EQ(agree, n);
}

TEST(PairScene, Pair4BlockSize) {
  EXPECT_EQ(sizeof(Pair4Block), 256u);
  EXPECT_EQ(Pair4::kBlockPrims, 4u);
  EXPECT_EQ(sizeof(Pair2Block), 128u);
  EXPECT_EQ(Pair2::kBlockPrims, 2u);
}

// ---- shared scans ------------------------------------------------------------------------------

class PairScans : public ::testing::TestWithParam<const char*> {};

TEST_P(PairScans, IrregularScansReach89Percent) {
  const std::string path = shared_data_dir() + "/" + GetParam();
  SLIM_REQUIRE_SHARED_FILE(path);
  const PolyMesh m = load(path);
  PairingStats s = pairing_stats(m);
  EXPECT_GE(s.paired_fraction, 0.89) << GetParam();
  EXPECT_GT(s.paired_fraction, s.window2_paired_fraction) << GetParam();
}

INSTANTIATE_TEST_SUITE_P(Pair, PairScans,
                         ::testing::Values("stanford_bunny.obj.xz", "igea.ply.xz",
                                           "nefertiti.obj.xz", "koala.obj.xz", "ogre.obj.xz"));

}  // namespace

// pair_quads (the pairs as Embree-order quads): every fan triangle of the mesh in exactly one
// quad, triangle 0 = (v0, v1, v3) and triangle 1 = (v2, v3, v1) holding the fan triangle's
// vertices, corner[h][k] naming the quad corner of fan corner k; lone triangles have v2 == v3;
// as many pairs as pairing_stats reports. On a jittered grid with a third of the triangles
// flipped (inconsistent windings: b's shared edge runs either way) and on fans of n-gons.
TEST(Pairing, PairQuadsCoverEveryFanTriangleOnce) {
  PolyMesh flipped = jittered_grid(24, 5);
  for (uint32_t f = 0; f < flipped.face_count(); f += 3)
    std::swap(flipped.face_indices[3 * f + 1], flipped.face_indices[3 * f + 2]);
  PolyMesh fans;
  Rng rng(6);
  for (int f = 0; f < 200; ++f) {
    const int n = 3 + f % 4;
    const Vec3f ctr(rng.uniform(), rng.uniform(), rng.uniform());
    const uint32_t base = uint32_t(fans.positions.size());
    for (int k = 0; k < n; ++k) {
      const float ang = 6.2831853f * float(k) / float(n);
      fans.positions.push_back(ctr + Vec3f(std::cos(ang), std::sin(ang), 0.2f * rng.uniform()));
      fans.face_indices.push_back(base + uint32_t(k));
    }
    fans.face_sizes.push_back(uint32_t(n));
  }
  for (const PolyMesh* m : {&flipped, &fans}) {
    std::vector<uint64_t> first(m->face_count() + 1, 0);
    for (uint32_t f = 0; f < m->face_count(); ++f) first[f + 1] = first[f] + m->face_sizes[f];
    std::set<std::pair<uint32_t, uint32_t>> seen;  // (face, fan)
    uint64_t lone = 0;
    const std::vector<PairedQuad> quads = pair_quads(*m);
    for (const PairedQuad& q : quads) {
      const uint32_t tri[2][3] = {{q.v[0], q.v[1], q.v[3]}, {q.v[2], q.v[3], q.v[1]}};
      for (int h = 0; h < 2; ++h) {
        if (h == 1 && q.face[1] == kInvalidID) {
          EXPECT_EQ(q.v[2], q.v[3]);
          ++lone;
          continue;
        }
        ASSERT_LT(q.face[h], m->face_count());
        ASSERT_LT(q.fan[h] + 2, m->face_sizes[q.face[h]]);
        EXPECT_TRUE(seen.insert({q.face[h], q.fan[h]}).second) << "fan triangle in two quads";
        const uint32_t* c = &m->face_indices[first[q.face[h]]];
        const uint32_t fan[3] = {c[0], c[q.fan[h] + 1], c[q.fan[h] + 2]};
        for (int k = 0; k < 3; ++k) {
          // Triangle 0 lies on quad corners 0, 1, 3 and triangle 1 on 2, 3, 1.
          ASSERT_NE(q.corner[h][k], h == 0 ? 2 : 0);
          ASSERT_LT(q.corner[h][k], 4);
          EXPECT_EQ(q.v[q.corner[h][k]], fan[k]) << "face " << q.face[h] << " corner " << k;
          // Quad corners of triangle h: the same three vertices.
          EXPECT_TRUE(std::count(tri[h], tri[h] + 3, fan[k]) == 1);
        }
      }
      // Triangle 0 keeps its input winding; so does triangle 1 in the consistently oriented fans.
      // Position of each quad corner in (v0, v1, v3) and in (v2, v3, v1):
      static constexpr int kPos[2][4] = {{0, 1, -1, 2}, {-1, 2, 0, 1}};
      for (int h = 0; h < (m == &fans && q.face[1] != kInvalidID ? 2 : 1); ++h)
        EXPECT_EQ((kPos[h][q.corner[h][1]] - kPos[h][q.corner[h][0]] + 3) % 3, 1) << h;
    }
    EXPECT_EQ(seen.size(), m->fan_triangle_count());
    const PairingStats s = pairing_stats(*m);
    EXPECT_EQ(quads.size(), s.pairs + s.unpaired);
    EXPECT_EQ(lone, s.unpaired);
  }
}
