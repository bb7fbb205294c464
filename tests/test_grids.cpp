// Grid primitives (C. Benthin, K. Vaidyanathan, S. Woop, "Ray Tracing Lossy Compressed Grid
// Primitives", Eurographics 2021 short papers): mesh -> grids, the displacement codes, the 128-byte
// layout, hits against the brute-force reference on the decompressed triangles, watertightness
// across sub-grid and grid borders, u,v and face mapping, attributes.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <random>

#include "mesh/grids.h"
#include "prim/lossy_subgrid.h"
#include "prim/subgrid.h"
#include "slimrt/grids.h"
#include "test_util.h"

using namespace slim;
using namespace slim::test;

namespace {

// Every grid configuration: the uncompressed grid and both encodings of the Listing 1 layout
// under every node layout, and the shared-corner layout (compressed-leaf nodes only) with both
// encodings.
std::vector<BuildOptions> grid_configs() {
  std::vector<BuildOptions> v;
  for (const char* name : {"grid", "lossy-grid", "lossy-grid-e2"}) {
    for (Nodes n : {Nodes::Bvh8, Nodes::QBvh8, Nodes::CompressedLeaf}) {
      BuildOptions o = BuildOptions::from_config(name);
      o.nodes = n;
      v.push_back(o);
    }
  }
  for (GridEncoding e : {GridEncoding::Octahedral, GridEncoding::SharedExponent}) {
    BuildOptions o = BuildOptions::from_config("lossy-grid-shared");
    o.grid_encoding = e;
    v.push_back(o);
  }
  return v;
}

std::string name_of(const BuildOptions& o) { return o.config_name(); }

// The decompressed triangles of a configuration as a triangle PolyMesh (face i = triangle i),
// for the brute-force reference; face_map[i] = input face.
PolyMesh decoded_mesh(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt,
                      std::vector<uint32_t>& face_map) {
  GridTriangles t = grid_triangles(meshes, opt);
  PolyMesh m;
  m.positions = t.vertices;
  for (size_t i = 0; i < t.size(); ++i) {
    m.face_sizes.push_back(3);
    for (int k = 0; k < 3; ++k) m.face_indices.push_back(uint32_t(3 * i + k));
  }
  face_map = t.face;
  return m;
}

// A quad mesh whose faces have their corner order rotated in some columns and rows: with the fan
// diagonal kept, those cells cannot join their neighbours' grid, so the surface is cut into many
// grids (borders between different grids everywhere).
PolyMesh rotate_some_faces(PolyMesh m, int n_x, int every_x, int every_y) {
  for (size_t f = 0; f < m.face_count(); ++f) {
    const int i = int(f % n_x), j = int(f / n_x);
    if (i % every_x == 1 || j % every_y == 2) {
      uint32_t* q = &m.face_indices[4 * f];
      std::rotate(q, q + 1, q + 4);
    }
  }
  return m;
}

// Per-corner uvs with a seam around every block of every_x x every_y faces: grids never cross an
// attribute seam, so the surface is cut into many grids (borders between different grids).
PolyMesh add_uv_seams(PolyMesh m, int n_x, int every_x, int every_y) {
  const uint32_t nv = uint32_t(m.positions.size());
  const int bx = (n_x + every_x - 1) / every_x;
  const int by = int(m.face_count() / n_x + every_y - 1) / every_y;
  m.uvs.assign(size_t(nv) * bx * by, Vec2f{0.5f, 0.5f});
  m.uv_indices.resize(m.face_indices.size());
  for (size_t f = 0; f < m.face_count(); ++f) {
    const int i = int(f % n_x), j = int(f / n_x);
    const uint32_t block = uint32_t(i / every_x + bx * (j / every_y));
    for (int k = 0; k < 4; ++k) m.uv_indices[4 * f + k] = m.face_indices[4 * f + k] + nv * block;
  }
  return m;
}

}  // namespace

TEST(GridLayout, StructSizes) {
  EXPECT_EQ(sizeof(LossySubGrid), 128u);  // paper Listing 1
  EXPECT_EQ(sizeof(LossySubGridShared), 68u);
  EXPECT_EQ(sizeof(SubGridRef), 16u);
  EXPECT_EQ(sizeof(GridInfo), 28u);
  EXPECT_EQ(sizeof(GridHot), 16u);
  EXPECT_EQ(offsetof(LossySubGrid, displ), 48u);
  EXPECT_EQ(offsetof(LossySubGrid, res), 111u);
  EXPECT_EQ(offsetof(LossySubGrid, object_id), 112u);
  EXPECT_EQ(offsetof(LossySubGrid, grid_x), 120u);
  for (int s = 0; s < 21; ++s) EXPECT_EQ(displ_position_slot(displ_slot_position(s)), s);
}

TEST(GridCodec, UnitVectorTable) {
  const UnitVectorTable& t = kUnitVectors;
  for (int i = 0; i < 1024; ++i) {
    EXPECT_NEAR(t.x[i] * t.x[i] + t.y[i] * t.y[i] + t.z[i] * t.z[i], 1.0f, 1e-6f);
    EXPECT_GE(std::min(t.x[i], std::min(t.y[i], t.z[i])), 0.0f);
  }
  EXPECT_EQ(t.ring_start[UnitVectorTable::kRings], 1024);
  // The axes are in the table exactly.
  for (auto d : {std::array<double, 3>{0, 0, 1}, {1, 0, 0}, {0, 1, 0}}) {
    uint32_t k = t.nearest(d.data());
    EXPECT_EQ(float(d[0]), t.x[k]);
    EXPECT_EQ(float(d[1]), t.y[k]);
    EXPECT_EQ(float(d[2]), t.z[k]);
  }
  // nearest() against a brute-force search: the same entry almost always, never much worse, and
  // the largest angle to the nearest entry bounds the direction error of encoding 1.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> U(0, 1);
  int same = 0;
  double worst_angle = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    double d[3] = {std::fabs(U(rng) - 0.5), std::fabs(U(rng) - 0.5), std::fabs(U(rng) - 0.5)};
    const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (double& c : d) c /= len;
    uint32_t best = 0;
    double best_dot = -2;
    for (uint32_t k = 0; k < 1024; ++k) {
      const double dot = d[0] * t.x[k] + d[1] * t.y[k] + d[2] * t.z[k];
      if (dot > best_dot) best_dot = dot, best = k;
    }
    const uint32_t k = t.nearest(d);
    same += k == best;
    const double dot = d[0] * t.x[k] + d[1] * t.y[k] + d[2] * t.z[k];
    EXPECT_GT(dot, best_dot - 1e-4);
    worst_angle = std::max(worst_angle, std::acos(std::min(1.0, dot)));
  }
  EXPECT_GE(same, n * 99 / 100);
  EXPECT_LT(worst_angle, 0.04);
  std::printf("unit vectors: nearest found %.2f%%, worst angle %.4f rad\n", 100.0 * same / n,
              worst_angle);
}

TEST(GridCodec, DisplacementRoundTrip) {
  const int bias = displacement_bias(2.0f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(-1, 1);
  double worst[3] = {0, 0, 0};
  for (int i = 0; i < 20000; ++i) {
    const float scale = std::pow(10.0f, -float(i % 6));  // 1 .. 1e-5
    const Vec3f patch(U(rng), U(rng), U(rng));
    Vec3f d(U(rng) * scale, U(rng) * scale, U(rng) * scale);
    if (i % 7 == 0) d.x = d.y = 0;  // heightfield-like displacements
    if (i % 11 == 0) d.z = 0;
    const Vec3f target = patch + d;
    const double len = length(target - patch);
    const double amax = reduce_max(abs(target - patch));
    const uint32_t c1 = encode_displacement1(patch, target, bias);
    const uint32_t c2 = encode_displacement2(patch, target, bias);
    EXPECT_NE(displ_exponent(c1), kDisplEscape);
    EXPECT_NE(displ_exponent(c2), kDisplEscape);
    const double e1 = length(decode_vertex<1>(patch, c1, bias) - target);
    const double e2 = length(decode_vertex<2>(patch, c2, bias) - target);
    // Encoding 1: direction within the table's cell (< 0.04 rad) and length within half a 5-bit
    // mantissa step; plus the rounding of patch + displacement.
    const double ulp = 2 * 6e-8 * reduce_max(abs(patch));
    EXPECT_LE(e1, len * (0.04 + 1.0 / 64) + ulp) << i;
    // Encoding 2: each component within half a step of 2^e, the step at most amax / 15.5.
    EXPECT_LE(e2, std::sqrt(3.0) * amax / 31.0 + ulp) << i;
    worst[0] = std::max(worst[0], e1 / len);
    worst[1] = std::max(worst[1], e2 / len);
  }
  std::printf("worst relative error: encoding 1 %.4f, encoding 2 %.4f\n", worst[0], worst[1]);
  // Zero displacement and escapes.
  const Vec3f p(0.25f, -3.0f, 7.5f);
  EXPECT_EQ(encode_displacement1(p, p, bias), 0u);
  EXPECT_EQ(encode_displacement2(p, p, bias), 0u);
  EXPECT_EQ(decode_vertex<1>(p, 0, bias), p);
  for (uint32_t idx : {0u, 1u, 8191u, 8192u, 100000u, kMaxExactIndex}) {
    const uint32_t c = escape_code(idx);
    EXPECT_EQ(displ_exponent(c), kDisplEscape);
    EXPECT_EQ(escape_index(c), idx);
    EXPECT_LT(c, 1u << 24);
  }
}

// A random res_x x res_y sub-grid (resolution from iter) encoded with encoding enc; with
// escapes, every 7th position (but corners) is an exact vertex (its index = its position).
struct TestSubGrid {
  SubGridInput in;
  uint8_t displ[64 + 16] = {};
  Vec3f c[4];
};
TestSubGrid make_test_subgrid(std::mt19937& rng, int iter, int enc, int bias, bool escapes) {
  std::uniform_real_distribution<float> U(-1, 1);
  TestSubGrid t;
  SubGridInput& in = t.in;
  in.res_x = 2 + iter % 4;
  in.res_y = 2 + (iter / 4) % 4;
  for (int k = 0; k < 25; ++k) {
    in.v[k] = Vec3f(float(k % 5) * 0.25f + 0.05f * U(rng), float(k / 5) * 0.25f + 0.05f * U(rng),
                    0.1f * U(rng));
    in.exact[k] = escapes && (k * 3 + iter) % 7 == 0 ? uint32_t(k) : kNotExact;
  }
  if (enc == 1)
    encode_subgrid<1>(in, bias, t.displ);
  else
    encode_subgrid<2>(in, bias, t.displ);
  const uint32_t rx = in.res_x, ry = in.res_y;
  t.c[0] = in.v[0];
  t.c[1] = in.v[rx - 1];
  t.c[2] = in.v[5 * (ry - 1)];
  t.c[3] = in.v[5 * (ry - 1) + rx - 1];
  return t;
}

// The SIMD decoder gives bit for bit what the scalar twin (used by the encoder) gives.
TEST(GridCodec, SimdDecodeMatchesScalar) {
  std::mt19937 rng(11);
  const int bias = displacement_bias(4.0f);
  for (int enc = 1; enc <= 2; ++enc)
    for (int iter = 0; iter < 300; ++iter) {
      const TestSubGrid t = make_test_subgrid(rng, iter, enc, bias, false);
      const SubGridInput& in = t.in;
      const uint8_t* displ = t.displ;
      const uint32_t rx = in.res_x, ry = in.res_y;
      const Vec3f* c = t.c;
      SubGridVerts w;
      uint32_t codes[32];
      const uint32_t esc = enc == 1 ? decode_subgrid<1>(c, displ, rx, ry, bias, w, codes)
                                    : decode_subgrid<2>(c, displ, rx, ry, bias, w, codes);
      EXPECT_EQ(esc, 0u);
      for (uint32_t j = 0; j < ry; ++j)
        for (uint32_t i = 0; i < rx; ++i) {
          const int k = int(5 * j + i);
          const int s = displ_position_slot(k);
          const uint32_t code = s < 0 ? 0 : load_code(displ + 3 * s);
          const Vec3f pp = patch_point(c, i, j, rx, ry);
          const Vec3f ref =
              enc == 1 ? decode_vertex<1>(pp, code, bias) : decode_vertex<2>(pp, code, bias);
          EXPECT_EQ(std::memcmp(&ref.x, &w.p[0][k], 4), 0);
          EXPECT_EQ(std::memcmp(&ref.y, &w.p[1][k], 4), 0);
          EXPECT_EQ(std::memcmp(&ref.z, &w.p[2][k], 4), 0);
          // Patch corners decode to the input vertex exactly.
          if ((i == 0 || i == rx - 1) && (j == 0 || j == ry - 1)) {
            EXPECT_EQ(detail::subgrid_vertex(w, k), in.v[k]);
          }
        }
    }
}

// The quarter decoder (one 8-lane decode per 2x2 cells, prim/subgrid.h) gives bit for bit the
// vertices the whole decoder gives at the same positions, escape codes included, for every
// resolution; lane 8 is the quarter's sub-grid corner.
TEST(GridCodec, QuarterDecodeMatchesWholeDecode) {
  std::mt19937 rng(12);
  const int bias = displacement_bias(4.0f);
  for (int enc = 1; enc <= 2; ++enc)
    for (int iter = 0; iter < 160; ++iter) {
      const TestSubGrid t = make_test_subgrid(rng, iter, enc, bias, true);
      const SubGridInput& in = t.in;
      const uint8_t* displ = t.displ;
      const uint32_t rx = in.res_x, ry = in.res_y;
      const Vec3f* c = t.c;
      SubGridVerts w;
      alignas(32) uint32_t codes[32];
      uint32_t esc = enc == 1 ? decode_subgrid<1>(c, displ, rx, ry, bias, w, codes)
                              : decode_subgrid<2>(c, displ, rx, ry, bias, w, codes);
      apply_escapes(esc, codes, in.v, w);
      int escaped = 0;
      for (uint32_t q = 0; q < 4; ++q) {
        QuarterVerts qv;
        alignas(32) uint32_t qcodes[8];
        const uint32_t qesc = enc == 1 ? decode_quarter<1>(c, displ, rx, ry, bias, q, qv, qcodes)
                                       : decode_quarter<2>(c, displ, rx, ry, bias, q, qv, qcodes);
        escaped += simd::popcount(qesc);
        apply_escapes(qesc, qcodes, in.v, qv);
        uint32_t i0, i1, j0, j1;
        subgrid_part_cells(4, q, rx, ry, i0, i1, j0, j1);
        if (i0 >= i1 || j0 >= j1) continue;  // no cell: never tested
        for (uint32_t b = 0; b <= j1 - j0; ++b)
          for (uint32_t a = 0; a <= i1 - i0; ++a) {
            const int l = kQuarterTables.lane[q][b][a];
            const int k = int(5 * (j0 + b) + i0 + a);
            ASSERT_EQ(kQuarterTables.position[q][l], k);
            for (int ax = 0; ax < 3; ++ax)
              EXPECT_EQ(std::memcmp(&qv.p[ax][l], &w.p[ax][k], 4), 0)
                  << "enc " << enc << " res " << rx << "x" << ry << " quarter " << q << " (" << a
                  << "," << b << ")";
          }
      }
      if (rx == 5 && ry == 5) {
        EXPECT_GT(escaped, 0);
      }
    }
}

TEST(GridKernel, DeinterleavesRowsOfFivePoints) {
  // simd::load_xyz5 (the `grid` decoder's whole-row path) against the plain copy, and
  // SubGridLeaf::decode of a full and a partial sub-grid against the vertex array.
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(-10, 10);
  float row[15];
  for (int it = 0; it < 100; ++it) {
    for (float& f : row) f = U(rng);
    simd::vfloat8 x, y, z;
    simd::load_xyz5(row, x, y, z);
    alignas(32) float out[3][8];
    x.store(out[0]), y.store(out[1]), z.store(out[2]);
    for (int i = 0; i < 5; ++i)
      for (int a = 0; a < 3; ++a) ASSERT_EQ(out[a][i], row[3 * i + a]) << i << " " << a;
  }
  std::vector<Vec3f> verts(7 * 6);
  for (Vec3f& p : verts) p = Vec3f(U(rng), U(rng), U(rng));
  for (uint8_t rx : {uint8_t(5), uint8_t(3)})
    for (uint8_t ry : {uint8_t(5), uint8_t(2)}) {
      SubGridLeaf::Context ctx;
      ctx.vertices = verts.data();
      const SubGridRef b{1 + 7, 0, 1, 1, 7, rx, ry};
      SubGridVerts w;
      for (int a = 0; a < 3; ++a)
        for (float& f : w.p[a]) f = std::nanf("");  // every lane must be written
      SubGridLeaf::decode(ctx, b, w);
      for (uint32_t j = 0; j < 5; ++j)
        for (uint32_t i = 0; i < 5; ++i) {
          const Vec3f& p =
              verts[b.vertex + std::min<uint32_t>(j, ry - 1) * 7 + std::min<uint32_t>(i, rx - 1)];
          for (int a = 0; a < 3; ++a) ASSERT_EQ(w.p[a][5 * j + i], p[a]) << i << "," << j;
        }
      for (int k = 25; k < 32; ++k)
        for (int a = 0; a < 3; ++a) EXPECT_EQ(w.p[a][k], 0.0f);
    }
}

// The kernel's ray-space transform is core/watertight.h's, bit for bit (shared vertices of grids
// and triangle leaves must land on the same ray-space values).
TEST(GridKernel, RaySpaceMatchesCore) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(-10, 10);
  for (int it = 0; it < 200; ++it) {
    SubGridVerts w;
    for (int a = 0; a < 3; ++a)
      for (int k = 0; k < 32; ++k) w.p[a][k] = U(rng);
    const Vec3f o(U(rng), U(rng), U(rng)), d = normalize(Vec3f(U(rng), U(rng), U(rng)));
    const WatertightRay wr(o, d);
    alignas(32) float r[3][32];
    subgrid_to_ray_space(wr, w, r);
    for (int k = 0; k < 32; ++k) {
      const RayVertex<float> v = to_ray_space(wr, w.p[0][k], w.p[1][k], w.p[2][k]);
      EXPECT_EQ(std::memcmp(&v.x, &r[0][k], 4), 0);
      EXPECT_EQ(std::memcmp(&v.y, &r[1][k], 4), 0);
      EXPECT_EQ(std::memcmp(&v.z, &r[2][k], 4), 0);
    }
  }
}

TEST(GridConversion, ProceduralScenesAreOneGrid) {
  struct Case {
    PolyMesh m;
    uint32_t rx, ry;
  };
  std::vector<Case> cases;
  cases.push_back({make_terrain(37), 38, 38});
  cases.push_back({make_canyon(40), 41, 41});
  cases.push_back({make_torus(36), 37, 19});
  for (const Case& c : cases) {
    GridSet gs = make_grids({&c.m});
    ASSERT_EQ(gs.grids.size(), 1u) << c.m.name;
    EXPECT_EQ(gs.multi_cell_grids, 1u);
    EXPECT_TRUE(gs.triangles.empty());
    EXPECT_EQ(gs.grids[0].res_x, c.rx) << c.m.name;
    EXPECT_EQ(gs.grids[0].res_y, c.ry) << c.m.name;
    // Every face exactly once.
    std::vector<int> seen(c.m.face_count(), 0);
    for (uint32_t y = 0; y + 1 < gs.grids[0].res_y; ++y)
      for (uint32_t x = 0; x + 1 < gs.grids[0].res_x; ++x) {
        EXPECT_EQ(gs.cell_face(gs.grids[0], x, y, 0), gs.cell_face(gs.grids[0], x, y, 1));
        seen[gs.cell_face(gs.grids[0], x, y, 0)]++;
      }
    for (int s : seen) EXPECT_EQ(s, 1);
    GridStats st = grid_stats({&c.m});
    EXPECT_EQ(st.grids, 1u);
    EXPECT_EQ(st.single_cells + st.leftover_triangles, 0u);
  }
  // The torus grid wraps: its last column/row repeat the first (the same vertices).
  PolyMesh t = make_torus(36);
  GridSet gs = make_grids({&t});
  const VertexGrid& g = gs.grids[0];
  for (uint32_t y = 0; y < g.res_y; ++y)
    EXPECT_EQ(gs.vertex(g, 0, y), gs.vertex(g, g.res_x - 1, y));
  for (uint32_t x = 0; x < g.res_x; ++x)
    EXPECT_EQ(gs.vertex(g, x, 0), gs.vertex(g, x, g.res_y - 1));
  // No vertex of a single closed grid needs to be stored exactly.
  EXPECT_TRUE(find_exact_positions(gs, {&t}).pos.empty());
}

TEST(GridConversion, MixedMeshesLeftoversAndPairs) {
  // A triangulated terrain (pairs become cells: one grid again), plus n-gons and lone triangles.
  PolyMesh q = make_terrain(12);
  PolyMesh tri;
  tri.positions = q.positions;
  for (size_t f = 0; f < q.face_count(); ++f) {
    const uint32_t* v = &q.face_indices[4 * f];
    for (uint32_t k : {v[0], v[1], v[2], v[0], v[2], v[3]}) tri.face_indices.push_back(k);
    tri.face_sizes.insert(tri.face_sizes.end(), {3, 3});
  }
  GridSet gs = make_grids({&tri});
  EXPECT_EQ(gs.figures.paired_cells, 144u);
  // A quad mesh with a NaN vertex: its faces are skipped, the rest still forms grids.
  PolyMesh nan = make_terrain(8);
  nan.positions[40].y = std::nanf("");
  GridSet gn = make_grids({&nan});
  EXPECT_EQ(gn.figures.skipped_faces, 4u);
  EXPECT_EQ(gn.figures.grid_cells + gn.figures.single_cells, 60u);
  Scene sn = Scene::build(nan, BuildOptions::from_config("lossy-grid"));
  std::string why;
  EXPECT_TRUE(sn.validate(&why)) << why;
  EXPECT_EQ(sn.stats().skipped_faces, 4u);
  ASSERT_EQ(gs.multi_cell_grids, 1u);
  EXPECT_EQ(gs.grids[0].res_x, 13u);
  for (uint32_t y = 0; y < 12; ++y)
    for (uint32_t x = 0; x < 12; ++x) {
      const uint32_t a = gs.cell_face(gs.grids[0], x, y, 0), b = gs.cell_face(gs.grids[0], x, y, 1);
      EXPECT_EQ(a / 2, y * 12 + x);
      EXPECT_NE(a, b);
      EXPECT_EQ(a / 2, b / 2);
    }
}

// Hits of every grid configuration equal the brute-force reference run on its own decompressed
// triangles (same face, same t); the lossless `grid` also equals the input's reference.
// Both ways of storing leftovers (Scene::build picks one by memory; BuildOptions::grid_leftovers
// forces one).
class GridLeftoverPolicy : public ::testing::TestWithParam<slim::GridLeftovers> {};

TEST_P(GridLeftoverPolicy, MatchReferenceOnDecompressedTriangles) {
  std::vector<PolyMesh> scenes;
  scenes.push_back(make_terrain(30));  // partial sub-grids: 31 = 4*7 + 3
  scenes.push_back(make_torus(22));
  scenes.push_back(add_uv_seams(rotate_some_faces(make_terrain(17), 17, 5, 4), 17, 6, 5));
  {
    PolyMesh m = make_canyon(9);  // plus a second mesh of triangles and a pentagon
    scenes.push_back(m);
  }
  PolyMesh extra = random_soup(40, 5, 0.2f);
  extra.positions.push_back({0.1f, 0.1f, 0.5f});
  extra.positions.push_back({0.3f, 0.1f, 0.55f});
  extra.positions.push_back({0.35f, 0.3f, 0.5f});
  extra.positions.push_back({0.2f, 0.4f, 0.45f});
  extra.positions.push_back({0.05f, 0.3f, 0.5f});
  for (uint32_t k = 0; k < 5; ++k) extra.face_indices.push_back(120 + k);
  extra.face_sizes.push_back(5);
  for (BuildOptions opt : grid_configs()) {
    opt.grid_leftovers = GetParam();
    for (size_t si = 0; si < scenes.size(); ++si) {
      std::vector<const PolyMesh*> meshes{&scenes[si]};
      if (si == 3) meshes.push_back(&extra);
      Scene s = Scene::build(meshes, opt);
      std::string why;
      ASSERT_TRUE(s.validate(&why)) << name_of(opt) << " scene " << si << ": " << why;
      std::vector<uint32_t> face_map;
      PolyMesh dm = decoded_mesh(meshes, opt, face_map);
      std::vector<RefTri> ref = reference_triangles({&dm});
      GridTriangles gt = grid_triangles(meshes, opt);
      Rng rng(uint32_t(17 + si));
      auto input_of = [&](const RefTri& t) {
        return std::make_pair(gt.geom[t.prim], face_map[t.prim]);
      };
      int hits = 0, agree = 0, same = 0, ties = 0, n = 600;
      for (int i = 0; i < n; ++i) {
        Ray r = random_ray(rng, s.bounds());
        Hit h = s.intersect(r);
        RefHit rh = reference_intersect(ref, r);
        EXPECT_EQ(s.occluded(r), h.valid());
        if (rh.valid()) hits++;
        const bool ok = agrees(h, rh, 1e-4);
        agree += ok;
        if (ok && h.valid()) {
          const bool same_face = face_map[rh.prim] == h.primID && gt.geom[rh.prim] == h.geomID;
          same += same_face;
          // Another input face only as a tie at an edge or vertex the two faces share, checked
          // geometrically on the decoded triangles.
          if (!same_face)
            ties += input_face_tie(ref, r, rh, input_of, h.geomID, h.primID, tie_delta(r, rh.t)) ==
                    TieKind::Edge;
          EXPECT_TRUE(h.kind == PrimKind::Grid || h.kind == PrimKind::Triangle);
          EXPECT_GE(h.u, -1e-5f);
          EXPECT_LE(h.u, 1 + 1e-5f);
        }
      }
      EXPECT_GT(hits, n / 10) << name_of(opt);
      EXPECT_EQ(agree, n) << name_of(opt) << " scene " << si;
      EXPECT_EQ(same + ties, hits) << name_of(opt) << " scene " << si;
      EXPECT_LE(ties, 1 + hits / 100) << name_of(opt) << " scene " << si;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Grid, GridLeftoverPolicy,
                         ::testing::Values(slim::GridLeftovers::Grids,
                                           slim::GridLeftovers::Triangles));

// Lossless grids intersect exactly the fan triangles of the input (same face, same t).
TEST(GridHits, LosslessGridMatchesInputReference) {
  std::vector<PolyMesh> scenes{make_terrain(21), make_torus(20),
                               rotate_some_faces(make_canyon(15), 15, 4, 3),
                               add_uv_seams(rotate_some_faces(make_torus(24), 24, 3, 5), 24, 5, 4)};
  for (const PolyMesh& m : scenes) {
    Scene s = Scene::build(m, BuildOptions::from_config("grid"));
    std::vector<RefTri> ref = reference_triangles({&m});
    Rng rng(5);
    int agree = 0, same = 0, hits = 0, ties = 0;
    for (int i = 0; i < 800; ++i) {
      Ray r = random_ray(rng, s.bounds());
      Hit h = s.intersect(r);
      RefHit rh = reference_intersect(ref, r);
      agree += agrees(h, rh);
      hits += rh.valid();
      same += h.valid() && rh.valid() && h.primID == rh.prim;
      // Another face only as a tie at a shared edge or vertex, checked geometrically.
      if (h.valid() && rh.valid() && h.primID != rh.prim)
        ties += is_geometric_tie(ref, r, rh, 0, h.primID, tie_delta(r, rh.t));
    }
    EXPECT_EQ(agree, 800) << m.name;
    EXPECT_EQ(same + ties, hits) << m.name;
    EXPECT_LE(ties, hits / 100) << m.name;
  }
}

// Per-grid u,v (section 5) and the face mapping: on a terrain, grid u,v is the hit's x,y.
TEST(GridHits, UVAndFaceMapping) {
  PolyMesh m = make_terrain(26);
  for (const BuildOptions& opt : grid_configs()) {
    Scene s = Scene::build(m, opt);
    Rng rng(9);
    int checked = 0;
    for (int i = 0; i < 2000; ++i) {
      Ray r;
      r.org = Vec3f(rng.uniform(), rng.uniform(), 2.0f);
      r.dir = normalize(Vec3f(0.1f * (rng.uniform() - 0.5f), 0.1f * (rng.uniform() - 0.5f), -1.0f));
      Hit h = s.intersect(r);
      if (!h.valid()) continue;
      const Vec3f p = r.org + r.dir * h.t;
      ASSERT_EQ(h.kind, PrimKind::Grid);
      EXPECT_NEAR(h.u, p.x, 2e-3f) << name_of(opt);
      EXPECT_NEAR(h.v, p.y, 2e-3f) << name_of(opt);
      // Face j*N + i contains the hit.
      const uint32_t fi = h.primID % 26, fj = h.primID / 26;
      EXPECT_GE(p.x, fi / 26.0f - 2e-3f);
      EXPECT_LE(p.x, (fi + 1) / 26.0f + 2e-3f);
      EXPECT_GE(p.y, fj / 26.0f - 2e-3f);
      EXPECT_LE(p.y, (fj + 1) / 26.0f + 2e-3f);
      EXPECT_GT(h.Ng.z, 0.0f);  // counter-clockwise seen from above, as the input faces
      checked++;
    }
    EXPECT_GT(checked, 1500);
  }
}

TEST(GridHits, AttributeInterpolation) {
  PolyMesh m = make_terrain(19);
  for (const Vec3f& p : m.positions) m.uvs.push_back({p.x, 1.0f - p.y});
  GridAttributes ga = GridAttributes::build({&m});
  std::vector<Vec2f> uv = ga.grid_ordered(0, m.uvs, m.uv_indices);
  ASSERT_EQ(uv.size(), ga.grid_vertex_count());
  Scene s = Scene::build(m, BuildOptions::from_config("lossy-grid"));
  Rng rng(3);
  for (int i = 0; i < 500; ++i) {
    Ray r;
    r.org = Vec3f(rng.uniform(), rng.uniform(), 2.0f);
    r.dir = Vec3f(0, 0, -1);
    Hit h = s.intersect(r);
    ASSERT_TRUE(h.valid());
    Vec2f t;
    ASSERT_TRUE(ga.interpolate(uv, h, t));
    EXPECT_NEAR(t.x, r.org.x, 1e-3f);
    EXPECT_NEAR(t.y, 1.0f - r.org.y, 1e-3f);
  }
}

// Every input vertex decodes to the same bits in every sub-grid, grid and leftover that uses it
// (border vertices shared by different grids decode identically on both sides, so that the
// surface stays closed there).
TEST(GridWatertight, SharedVerticesDecodeIdentically) {
  const PolyMesh m = add_uv_seams(rotate_some_faces(make_torus(48), 48, 5, 4), 48, 7, 5);
  ASSERT_GT(make_grids({&m}).multi_cell_grids, 10u);
  for (const BuildOptions& opt : grid_configs()) {
    GridTriangles t = grid_triangles({&m}, opt);
    // Each decoded corner belongs to the nearest input vertex (decoding errors are far below the
    // vertex spacing); all decoded copies of one input vertex must be bit-identical.
    std::vector<int> first_copy(m.positions.size(), -1);
    uint64_t copies = 0, mismatches = 0;
    for (size_t i = 0; i < t.vertices.size(); ++i) {
      const Vec3f& p = t.vertices[i];
      if (i % 3 == 2 && t.vertices[i] == t.vertices[i - 1]) continue;
      size_t best = 0;
      float best_d = kInf;
      for (size_t v = 0; v < m.positions.size(); ++v) {
        const float d = length(m.positions[v] - p);
        if (d < best_d) best_d = d, best = v;
      }
      ASSERT_LT(best_d, 0.01f);
      if (first_copy[best] < 0) {
        first_copy[best] = int(i);
      } else {
        copies++;
        mismatches += std::memcmp(&t.vertices[first_copy[best]], &p, sizeof(Vec3f)) != 0;
      }
    }
    EXPECT_GT(copies, m.positions.size());
    EXPECT_EQ(mismatches, 0u) << name_of(opt);
  }
}

// Watertightness (section 5): rays from inside a closed displaced torus towards points on triangle
// edges and vertices of its decoded geometry (sub-grid borders and borders between different grids
// among them) all hit. The second torus is cut into many grids (uv seams) with flipped cells
// (rotated faces), and 3-cell-wide strips give partial sub-grids.
TEST(GridWatertight, ClosedTorusNoLeaks) {
  // 2 x 10^5 rays for lossy-grid (compressed-leaf BVH), 10 times fewer for the others;
  // SLIM_GRID_LEAK_RAYS overrides (the 10^6 run of the report).
  const int kRays =
      std::getenv("SLIM_GRID_LEAK_RAYS") ? std::atoi(std::getenv("SLIM_GRID_LEAK_RAYS")) : 200000;
  std::vector<PolyMesh> tori{make_torus(64),
                             add_uv_seams(rotate_some_faces(make_torus(64), 64, 6, 5), 64, 7, 3)};
  for (size_t ti = 0; ti < tori.size(); ++ti) {
    const PolyMesh& m = tori[ti];
    if (ti == 1) {
      GridSet gs = make_grids({&m});
      EXPECT_GT(gs.multi_cell_grids, 20u);
      EXPECT_GT(gs.figures.flipped_cells, 100u);
      EXPECT_GT(find_exact_positions(gs, {&m}).pos.size(), 100u);
    }
    for (const BuildOptions& opt : grid_configs()) {
      Scene s = Scene::build(m, opt);
      GridTriangles t = grid_triangles({&m}, opt);
      Rng rng(uint32_t(101 + ti));
      uint64_t leaks = 0;
      const int n =
          opt.leaf == Leaf::LossyGrids && opt.nodes == Nodes::CompressedLeaf ? kRays : kRays / 10;
      for (int i = 0; i < n; ++i) {
        const size_t tri = size_t(rng.next() % t.size());
        const Vec3f* v = &t.vertices[3 * tri];
        Vec3f target;
        const float a = rng.uniform();
        switch (i % 3) {
          case 0:
            target = v[i % 9 / 3];
            break;  // a vertex
          case 1:
            target = v[0] * (1 - a) + v[1] * a;
            break;  // points on edges
          default:
            target = v[1] * (1 - a) + v[2] * a;
            break;
        }
        // From the core circle of the torus (inside the tube) at the target's angle.
        const float ang = std::atan2(target.y, target.x);
        Ray r;
        r.org = Vec3f(std::cos(ang), std::sin(ang), 0.0f);
        r.dir = normalize(target - r.org);
        if (!s.intersect(r).valid()) leaks++;
      }
      EXPECT_EQ(leaks, 0u) << name_of(opt) << " torus " << ti << ": " << leaks << " of " << n;
    }
  }
}

// The 68-byte shared-corner block has no grid field: LossySharedLeaf::grid finds the grid from the
// lattice corner (a chunk table, then at most 4 steps). Many grids of the smallest lattice (2 x 2
// corners: 4 lattices start in each 16-corner chunk) are its worst case: 3000 soup triangles stored
// as 2x2 grids, one ray at each triangle's centroid. Both layouts decode to the same vertices, so
// each hit must equal lossy-grid's bit for bit (t, u, v, face, mesh).
TEST(GridHits, SharedLayoutFindsTheGridOfEveryBlock) {
  const PolyMesh soup = random_soup(3000, 11, 0.02f);
  PolyMesh terrain = make_terrain(9);
  std::vector<const PolyMesh*> meshes{&terrain, &soup};
  BuildOptions lossy = BuildOptions::from_config("lossy-grid");
  BuildOptions shared_opt = BuildOptions::from_config("lossy-grid-shared");
  lossy.grid_leftovers = shared_opt.grid_leftovers = slim::GridLeftovers::Grids;
  Scene ref = Scene::build(meshes, lossy);
  Scene shared = Scene::build(meshes, shared_opt);
  std::string why;
  ASSERT_TRUE(shared.validate(&why)) << why;
  int hits = 0;
  for (uint32_t f = 0; f < soup.face_count(); ++f) {
    Vec3f c{0, 0, 0};
    for (int k = 0; k < 3; ++k) c = c + soup.positions[soup.face_indices[3 * f + k]];
    c = c * (1.0f / 3.0f);
    const Ray r{c + Vec3f{0.01f, 0.02f, 1.5f}, 0.0f, Vec3f{-0.01f, -0.02f, -1.5f}, kInf};
    const Hit a = ref.intersect(r), b = shared.intersect(r);
    ASSERT_EQ(a.valid(), b.valid()) << "face " << f;
    if (!a.valid()) continue;
    hits++;
    EXPECT_EQ(a.t, b.t) << "face " << f;
    EXPECT_EQ(a.u, b.u) << "face " << f;
    EXPECT_EQ(a.v, b.v) << "face " << f;
    EXPECT_EQ(a.primID, b.primID) << "face " << f;
    EXPECT_EQ(a.geomID, b.geomID) << "face " << f;
  }
  EXPECT_GT(hits, 2900);
}

// Sub-grid parts (prim/subgrid.h): under the compressed-leaf BVH each sub-grid of a multi-leaf
// gets two (cell rows 0-1 and 2-3) or four (2x2 cells) child boxes over one block. The hits must be
// exactly those of whole sub-grids (same decoded vertices, same triangles with the same corners),
// partial sub-grids with empty parts included (19 cells: the last sub-grid row and column have 3
// cells; the seamed torus has 3-cell strips and flipped cells), and each multi-leaf holds at most
// 8 / parts sub-grids.
TEST(GridHits, SubGridPartChildrenMatchWholeSubGrids) {
  std::vector<PolyMesh> meshes{make_terrain(19),
                               add_uv_seams(rotate_some_faces(make_torus(64), 64, 6, 5), 64, 7, 3)};
  for (const PolyMesh& m : meshes) {
    for (const char* config : {"lossy-grid", "lossy-grid-e2", "lossy-grid-shared"}) {
      BuildOptions opt = BuildOptions::from_config(config);
      opt.grid_parts = 1;
      Scene whole = Scene::build(m, opt);
      ASSERT_EQ(detail_value(whole, "subgrid_parts"), 1.0) << config;
      for (int parts : {2, 4}) {
        opt.grid_parts = parts;
        Scene parted = Scene::build(m, opt);
        ASSERT_EQ(detail_value(parted, "subgrid_parts"), double(parts)) << config;
        std::string why;
        EXPECT_TRUE(parted.validate(&why)) << config << " " << parts << ": " << why;
        const double ml = detail_value(parted, "multileaf_count");
        ASSERT_GT(ml, 0.0) << config;
        EXPECT_LE(detail_value(parted, "leaves_in_multileaf"), 8.0 / parts * ml) << config;
        const Box3f box = parted.bounds();
        Rng rng(77);
        int hits = 0;
        for (int i = 0; i < 20000; ++i) {
          const Ray r = random_ray(rng, box);
          const Hit a = whole.intersect(r), b = parted.intersect(r);
          ASSERT_EQ(a.valid(), b.valid()) << config << " ray " << i;
          EXPECT_EQ(whole.occluded(r), parted.occluded(r)) << config << " ray " << i;
          if (!a.valid()) continue;
          hits++;
          EXPECT_EQ(a.t, b.t) << config << " ray " << i;
          EXPECT_EQ(a.primID, b.primID) << config << " ray " << i;
          EXPECT_EQ(a.geomID, b.geomID) << config << " ray " << i;
          EXPECT_EQ(a.u, b.u) << config << " ray " << i;
          EXPECT_EQ(a.v, b.v) << config << " ray " << i;
          EXPECT_EQ(a.Ng.x, b.Ng.x) << config << " ray " << i;
          EXPECT_EQ(a.Ng.y, b.Ng.y) << config << " ray " << i;
          EXPECT_EQ(a.Ng.z, b.Ng.z) << config << " ray " << i;
        }
        EXPECT_GT(hits, 2000) << config;
      }
    }
  }
}
