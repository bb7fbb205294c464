// Procedural scenes (src/mesh/procedural.cpp): determinism, counts, topology, orientation, bounds.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <utility>
#include <vector>

#include "slimrt/mesh.h"

namespace {

using slim::PolyMesh;
using slim::Vec3f;

bool bit_identical(const PolyMesh& a, const PolyMesh& b) {
  return a.name == b.name && a.positions.size() == b.positions.size() &&
         std::memcmp(a.positions.data(), b.positions.data(), a.positions.size() * sizeof(Vec3f)) ==
             0 &&
         a.face_sizes == b.face_sizes && a.face_indices == b.face_indices;
}

void expect_all_quads(const PolyMesh& m) {
  ASSERT_EQ(m.face_indices.size(), m.face_sizes.size() * 4);
  for (uint32_t s : m.face_sizes) ASSERT_EQ(s, 4u);
  for (uint32_t i : m.face_indices) ASSERT_LT(i, m.positions.size());
  for (const Vec3f& p : m.positions) ASSERT_TRUE(slim::is_finite(p));
}

// Quad normal from the diagonals (the Newell normal of a quad), not normalized.
Vec3f quad_normal(const PolyMesh& m, size_t f) {
  const uint32_t* q = &m.face_indices[f * 4];
  return cross(m.positions[q[2]] - m.positions[q[0]], m.positions[q[3]] - m.positions[q[1]]);
}

using Maker = PolyMesh (*)(int, uint32_t);

struct Kind {
  const char* name;
  Maker make;
  int n;
};
const Kind kKinds[] = {{"terrain", slim::make_terrain, 32},
                       {"torus", slim::make_torus, 32},
                       {"canyon", slim::make_canyon, 32}};

}  // namespace

TEST(Procedural, DeterministicAndSeeded) {
  for (const Kind& k : kKinds) {
    SCOPED_TRACE(k.name);
    PolyMesh a = k.make(k.n, 1), b = k.make(k.n, 1), c = k.make(k.n, 2);
    EXPECT_TRUE(bit_identical(a, b));
    EXPECT_EQ(a.face_indices, c.face_indices);  // same topology
    EXPECT_NE(
        0, std::memcmp(a.positions.data(), c.positions.data(), a.positions.size() * sizeof(Vec3f)));
    EXPECT_EQ(a.name, std::string(k.name) + ":" + std::to_string(k.n));
  }
}

// Golden values: the noise must give the same bits on every platform and compiler (the published
// benchmark checksums of terrain:N, canyon:N and torus:N rest on them). A change of the generator
// that is intended must update these. What the hashes stand for is checked independently below
// (VertexPositionsAtKnownParameters, the counts, topology, bounds and normals tests).
TEST(Procedural, GoldenHeights) {
  auto hash = [](const PolyMesh& m) {
    uint32_t h = 2166136261u;  // FNV-1a over the position bytes
    const auto* bytes = reinterpret_cast<const unsigned char*>(m.positions.data());
    for (size_t i = 0; i < m.positions.size() * sizeof(Vec3f); ++i) h = (h ^ bytes[i]) * 16777619u;
    return h;
  };
  EXPECT_EQ(hash(slim::make_terrain(8)), 990987539u) << "terrain: update if changed on purpose";
  EXPECT_EQ(hash(slim::make_canyon(8)), 2124817166u) << "canyon: update if changed on purpose";
  EXPECT_EQ(hash(slim::make_torus(8)), 4190336979u) << "torus: update if changed on purpose";
}

TEST(Procedural, AllQuadsAndCounts) {
  for (int n : {1, 2, 7, 64}) {
    PolyMesh t = slim::make_terrain(n), c = slim::make_canyon(n);
    for (const PolyMesh* m : {&t, &c}) {
      expect_all_quads(*m);
      EXPECT_EQ(m->face_count(), size_t(n) * n);
      EXPECT_EQ(m->vertex_count(), size_t(n + 1) * (n + 1));
    }
  }
  for (int n : {6, 8, 10, 64}) {
    PolyMesh m = slim::make_torus(n);
    expect_all_quads(m);
    EXPECT_EQ(m.face_count(), size_t(n) * (n / 2));
    EXPECT_EQ(m.vertex_count(), size_t(n) * (n / 2));
  }
}

TEST(Procedural, HeightfieldCornerOrder) {
  const int n = 5;
  PolyMesh m = slim::make_terrain(n);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const uint32_t* q = &m.face_indices[size_t(j * n + i) * 4];
      EXPECT_EQ(q[0], uint32_t(j * (n + 1) + i));
      EXPECT_EQ(q[1], uint32_t(j * (n + 1) + i + 1));
      EXPECT_EQ(q[2], uint32_t((j + 1) * (n + 1) + i + 1));
      EXPECT_EQ(q[3], uint32_t((j + 1) * (n + 1) + i));
    }
  // Vertex (i, j) sits at (i/n, j/n).
  EXPECT_EQ(m.positions[0].x, 0.0f);
  EXPECT_EQ(m.positions[0].y, 0.0f);
  EXPECT_EQ(m.positions[n].x, 1.0f);
  EXPECT_EQ(m.positions[size_t(n) * (n + 1)].y, 1.0f);
  EXPECT_FLOAT_EQ(m.positions[size_t(2) * (n + 1) + 3].x, 3.0f / n);
  EXPECT_FLOAT_EQ(m.positions[size_t(2) * (n + 1) + 3].y, 2.0f / n);
}

// Every vertex where its parameters put it, computed here from the definitions in mesh.h (not from
// the generator): heightfield vertex (i, j) at (i/n, j/n); torus vertex (i, j) (index j * n + i)
// on the normal line of the undisplaced torus of radii 1 and 0.4 at angles 2 pi i / n around the
// major circle and 2 pi j / (n/2) around the minor one, displaced along that normal by less than
// 0.07 (0.12 x the fBm's range of about +-0.5).
TEST(Procedural, VertexPositionsAtKnownParameters) {
  for (int n : {1, 7, 64, 100}) {
    SCOPED_TRACE(n);
    for (const PolyMesh& m : {slim::make_terrain(n), slim::make_canyon(n)}) {
      ASSERT_EQ(m.positions.size(), size_t(n + 1) * (n + 1));
      for (int j = 0; j <= n; ++j)
        for (int i = 0; i <= n; ++i) {
          const Vec3f& p = m.positions[size_t(j) * (n + 1) + i];
          ASSERT_NEAR(p.x, double(i) / n, 1e-7) << m.name << " " << i << "," << j;
          ASSERT_NEAR(p.y, double(j) / n, 1e-7) << m.name << " " << i << "," << j;
        }
    }
  }
  const double kPi = 3.14159265358979323846;
  for (int n : {6, 8, 64}) {
    SCOPED_TRACE(n);
    const PolyMesh m = slim::make_torus(n);
    const int nu = n, nv = n / 2;
    ASSERT_EQ(m.positions.size(), size_t(nu) * nv);
    double largest = 0;
    for (int j = 0; j < nv; ++j)
      for (int i = 0; i < nu; ++i) {
        const double u = 2 * kPi * i / nu, v = 2 * kPi * j / nv;
        const double nx = std::cos(v) * std::cos(u), ny = std::cos(v) * std::sin(u),
                     nz = std::sin(v);
        const double ox = (1 + 0.4 * std::cos(v)) * std::cos(u),
                     oy = (1 + 0.4 * std::cos(v)) * std::sin(u), oz = 0.4 * std::sin(v);
        const Vec3f& p = m.positions[size_t(j) * nu + i];
        const double dx = p.x - ox, dy = p.y - oy, dz = p.z - oz;
        const double along = dx * nx + dy * ny + dz * nz;  // the displacement
        const double off = std::sqrt(std::max(0.0, dx * dx + dy * dy + dz * dz - along * along));
        ASSERT_LT(off, 1e-5) << "vertex " << i << "," << j << " off its normal line";
        ASSERT_LT(std::fabs(along), 0.07) << "vertex " << i << "," << j;
        largest = std::max(largest, std::fabs(along));
      }
    EXPECT_GT(largest, 0.005) << "the torus is displaced";
  }
}

TEST(Procedural, RejectsBadN) {
  EXPECT_THROW(slim::make_terrain(0), slim::Error);
  EXPECT_THROW(slim::make_terrain(-3), slim::Error);
  EXPECT_THROW(slim::make_canyon(0), slim::Error);
  EXPECT_THROW(slim::make_torus(5), slim::Error);  // odd
  EXPECT_THROW(slim::make_torus(4), slim::Error);  // 2-gon minor circle: not a manifold
  EXPECT_THROW(slim::make_torus(0), slim::Error);
  EXPECT_THROW(slim::make_torus(-8), slim::Error);
  EXPECT_THROW(slim::make_terrain(1 << 20), slim::Error);  // vertex indices overflow 32 bits
}

TEST(Procedural, IsProcedural) {
  EXPECT_TRUE(slim::is_procedural("terrain:1024"));
  EXPECT_TRUE(slim::is_procedural("torus:16"));
  EXPECT_TRUE(slim::is_procedural("canyon:8"));
  EXPECT_FALSE(slim::is_procedural("dragon.ply"));
  EXPECT_FALSE(slim::is_procedural("sphere:10"));
}

TEST(Procedural, TorusClosedManifoldOriented) {
  for (int n : {6, 8, 12, 40}) {
    SCOPED_TRACE(n);
    PolyMesh m = slim::make_torus(n);
    std::map<std::pair<uint32_t, uint32_t>, int> directed;
    for (size_t f = 0; f < m.face_count(); ++f) {
      const uint32_t* q = &m.face_indices[f * 4];
      for (int e = 0; e < 4; ++e) {
        ASSERT_NE(q[e], q[(e + 1) % 4]) << "degenerate edge in face " << f;
        directed[{q[e], q[(e + 1) % 4]}]++;
      }
    }
    // Each directed edge once and its twin once: every undirected edge is shared by exactly two
    // faces that traverse it in opposite directions (closed, manifold, consistently oriented).
    for (const auto& [edge, count] : directed) {
      ASSERT_EQ(count, 1) << edge.first << "->" << edge.second;
      auto twin = directed.find({edge.second, edge.first});
      ASSERT_TRUE(twin != directed.end()) << "boundary edge " << edge.first << "-" << edge.second;
    }
    EXPECT_EQ(directed.size(), m.face_count() * 4);
    // Euler characteristic of a torus: V - E + F = 0.
    int64_t v = int64_t(m.vertex_count()), e = int64_t(directed.size() / 2),
            f = int64_t(m.face_count());
    EXPECT_EQ(v - e + f, 0);
    // No two vertices at the same place: the seams are welded, not duplicated.
    std::vector<Vec3f> p = m.positions;
    std::sort(p.begin(), p.end(), [](Vec3f a, Vec3f b) {
      return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
    });
    EXPECT_TRUE(std::adjacent_find(p.begin(), p.end()) == p.end());
  }
}

TEST(Procedural, TorusNormalsOutwardAndDisplaced) {
  PolyMesh m = slim::make_torus(64);
  size_t outward = 0;
  for (size_t f = 0; f < m.face_count(); ++f) {
    const uint32_t* q = &m.face_indices[f * 4];
    Vec3f c =
        (m.positions[q[0]] + m.positions[q[1]] + m.positions[q[2]] + m.positions[q[3]]) * 0.25f;
    float rxy = std::sqrt(c.x * c.x + c.y * c.y);
    Vec3f on_core(c.x / rxy, c.y / rxy, 0.0f);  // nearest point of the major circle (radius 1)
    if (dot(quad_normal(m, f), c - on_core) > 0) ++outward;
  }
  EXPECT_GE(outward, m.face_count() * 99 / 100);
  // Displaced: the distance to the core circle varies around the minor radius 0.4.
  float lo = 1e9f, hi = -1e9f;
  for (const Vec3f& p : m.positions) {
    float rxy = std::sqrt(p.x * p.x + p.y * p.y);
    float d = std::sqrt((rxy - 1.0f) * (rxy - 1.0f) + p.z * p.z);
    lo = std::min(lo, d);
    hi = std::max(hi, d);
  }
  EXPECT_LT(lo, 0.39f);
  EXPECT_GT(hi, 0.41f);
  EXPECT_GT(lo, 0.2f);
  EXPECT_LT(hi, 0.6f);
}

TEST(Procedural, TerrainBoundsAndNormalsUp) {
  PolyMesh m = slim::make_terrain(128);
  slim::Box3f b = m.bounds();
  EXPECT_EQ(b.lo.x, 0.0f);
  EXPECT_EQ(b.lo.y, 0.0f);
  EXPECT_EQ(b.hi.x, 1.0f);
  EXPECT_EQ(b.hi.y, 1.0f);
  float range = b.hi.z - b.lo.z;  // "amplitude about 5% of the extent"
  EXPECT_GT(range, 0.03f);
  EXPECT_LT(range, 0.10f);
  for (size_t f = 0; f < m.face_count(); ++f) ASSERT_GT(quad_normal(m, f).z, 0.0f) << f;
}

TEST(Procedural, CanyonSteepAndNormalsUp) {
  PolyMesh m = slim::make_canyon(128);
  slim::Box3f b = m.bounds();
  EXPECT_EQ(b.lo.x, 0.0f);
  EXPECT_EQ(b.hi.y, 1.0f);
  float range = b.hi.z - b.lo.z;
  EXPECT_GT(range, 0.15f);
  EXPECT_LT(range, 0.40f);
  size_t steep = 0;
  for (size_t f = 0; f < m.face_count(); ++f) {
    Vec3f n = quad_normal(m, f);
    ASSERT_GT(n.z, 0.0f) << f;
    if (n.z < 0.7071f * length(n)) ++steep;  // slope above 45 degrees
  }
  EXPECT_GT(steep, m.face_count() / 20) << "canyon should have cliffs";
}
