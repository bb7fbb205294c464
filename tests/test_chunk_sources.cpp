// Generated chunk sources (mesh/chunk_sources.h): procedural tiles give
// exactly the in-memory mesh's faces; subdivided meshes give every base triangle's 4^levels
// triangles once, with the documented face ids, the base area, and a closed surface over a
// closed base mesh (displaced or not).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mesh/chunk_sources.h"
#include "mesh/procedural.h"
#include "slimrt/slimrt.h"
#include "test_util.h"

using slim::Box3f;
using slim::PolyMesh;
using slim::Vec3f;
using namespace slim::detail;
using slim::test::error_of;

namespace {

bool same_bits(Vec3f a, Vec3f b) { return std::memcmp(&a, &b, sizeof a) == 0; }

std::array<uint32_t, 3> bits(Vec3f p) {
  std::array<uint32_t, 3> b;
  std::memcpy(b.data(), &p, sizeof p);
  return b;
}

// Box of the positions a mesh's faces use.
Box3f used_bounds(const PolyMesh& m) {
  Box3f b;
  for (uint32_t v : m.face_indices)
    if (slim::is_finite(m.positions[v])) b.extend(m.positions[v]);
  return b;
}

void expect_same_box(const Box3f& a, const Box3f& b, const std::string& what) {
  EXPECT_TRUE(a.lo.x == b.lo.x && a.lo.y == b.lo.y && a.lo.z == b.lo.z && a.hi.x == b.hi.x &&
              a.hi.y == b.hi.y && a.hi.z == b.hi.z)
      << what << ": [" << a.lo.x << " " << a.lo.y << " " << a.lo.z << "] - [" << a.hi.x << " "
      << a.hi.y << " " << a.hi.z << "] vs [" << b.lo.x << " " << b.lo.y << " " << b.lo.z << "] - ["
      << b.hi.x << " " << b.hi.y << " " << b.hi.z << "]";
}

// Every chunk: a valid mesh, its info right (counts, exact bounds), at most `max` triangles
// (`floor` more when a single unit is larger).
void check_chunk(const ChunkSource& src, size_t i, const Chunk& ch, uint64_t max, uint64_t unit) {
  const ChunkInfo& ci = src.info(i);
  EXPECT_EQ(error_of([&] { slim::check_mesh(ch.mesh); }), "") << "chunk " << i;
  EXPECT_EQ(ch.face_ids.size(), ch.mesh.face_count());
  EXPECT_EQ(ci.faces, ch.mesh.face_count()) << "chunk " << i;
  EXPECT_EQ(ci.triangles, ch.mesh.fan_triangle_count()) << "chunk " << i;
  EXPECT_EQ(ci.corners, ch.mesh.face_indices.size()) << "chunk " << i;
  EXPECT_LE(ci.triangles, std::max(max, unit)) << "chunk " << i;
  expect_same_box(ci.bounds, used_bounds(ch.mesh), "chunk " + std::to_string(i) + " bounds");
  // Welded: every position used, no two with the same bits.
  std::vector<uint8_t> used(ch.mesh.positions.size(), 0);
  for (uint32_t v : ch.mesh.face_indices) used[v] = 1;
  size_t unused = 0;
  for (uint8_t u : used) unused += u == 0;
  EXPECT_EQ(unused, 0u) << "chunk " << i << ": positions no face uses";
  std::map<std::array<uint32_t, 3>, int> seen;
  for (const Vec3f& p : ch.mesh.positions) ++seen[bits(p)];
  EXPECT_EQ(seen.size(), ch.mesh.positions.size()) << "chunk " << i << ": duplicated positions";
}

// ---- procedural tiles ----

void check_procedural(const std::string& spec, uint64_t max) {
  SCOPED_TRACE(spec + " in chunks of " + std::to_string(max));
  const PolyMesh ref = slim::load(spec);
  const auto off = ref.face_offsets();
  auto src = open_procedural_chunks(spec, max);
  EXPECT_EQ(src->faces(), ref.face_count());
  EXPECT_EQ(src->triangles(), ref.fan_triangle_count());
  expect_same_box(src->bounds(), ref.bounds(), "scene bounds");
  std::vector<uint8_t> seen(ref.face_count(), 0);
  uint64_t bad = 0, faces = 0;
  for (size_t i = 0; i < src->size(); ++i) {
    const Chunk ch = src->load(i);
    check_chunk(*src, i, ch, max, 2);
    faces += ch.mesh.face_count();
    for (size_t f = 0; f < ch.mesh.face_count(); ++f) {
      const uint64_t id = ch.face_ids[f];
      ASSERT_LT(id, ref.face_count());
      if (seen[id]++ != 0 && bad++ < 5) ADD_FAILURE() << "face " << id << " twice";
      ASSERT_EQ(ch.mesh.face_sizes[f], 4u);
      for (int k = 0; k < 4; ++k)
        if (!same_bits(ch.mesh.positions[ch.mesh.face_indices[4 * f + k]],
                       ref.positions[ref.face_indices[off[id] + k]]) &&
            bad++ < 5)
          ADD_FAILURE() << "face " << id << " corner " << k << " differs";
    }
  }
  EXPECT_EQ(faces, ref.face_count());
  EXPECT_EQ(bad, 0u);
  for (size_t f = 0; f < seen.size(); ++f)
    if (seen[f] == 0) {
      ADD_FAILURE() << "face " << f << " in no chunk";
      break;
    }
}

TEST(ChunkSources, ProceduralTilesAreTheInMemoryMesh) {
  for (const char* spec : {"terrain:64", "canyon:50", "torus:64"})
    for (uint64_t max : {uint64_t(1), uint64_t(7), uint64_t(300), uint64_t(1000000)})
      check_procedural(spec, max);
}

TEST(ChunkSources, ProceduralTilesAreNearlySquareAndCoverTheGrid) {
  // 300 triangles: tiles of at most 150 quads. 64 x 64 quads need at least 28; as rectangles of
  // near-equal sides 30 (6 x 5 or 5 x 6, sides 10-11 x 12-13).
  ProceduralChunks src("terrain:64", 300);
  EXPECT_EQ(src.size(), 30u);
  EXPECT_EQ(uint64_t(src.tiles_x()) * uint64_t(src.tiles_y()), 30u);
  for (size_t i = 0; i < src.size(); ++i) {
    const auto& t = src.tile(i);
    const int w = t.i1 - t.i0, h = t.j1 - t.j0;
    EXPECT_LE(w * h, 150) << "tile " << i;
    EXPECT_LE(std::max(w, h), 13) << "tile " << i;
    EXPECT_GE(std::min(w, h), 10) << "tile " << i;
  }
  // torus:64 (64 x 32 quads) in 2 tiles of 32 x 32: each spans every row, so its last vertex
  // row is its first (the minor seam, welded within the tile); the second one also reaches the
  // major seam, whose column is column 0.
  ProceduralChunks halves("torus:64", 2048);
  EXPECT_EQ(halves.tiles_x(), 2);
  EXPECT_EQ(halves.tiles_y(), 1);
  EXPECT_EQ(halves.load(0).mesh.positions.size(), 33u * 32u);
  EXPECT_EQ(halves.load(1).mesh.positions.size(), 33u * 32u);
  // One tile holds the whole torus, both seams inside it.
  ProceduralChunks whole("torus:64", 1 << 20);
  EXPECT_EQ(whole.size(), 1u);
  EXPECT_EQ(whole.load(0).mesh.positions.size(), 64u * 32u);
}

TEST(ChunkSources, ProceduralErrors) {
  EXPECT_NE(error_of([] { open_procedural_chunks("terrain:0", 100); }), "");
  EXPECT_NE(error_of([] { open_procedural_chunks("torus:7", 100); }), "");
  EXPECT_NE(error_of([] { open_procedural_chunks("bunny.ply", 100); }), "");
  EXPECT_NE(error_of([] { open_procedural_chunks("terrain:64", 0); }), "");
  EXPECT_NE(error_of([] { open_procedural_chunks("terrain:65534", 1); }).find("2^24"),
            std::string::npos);
  EXPECT_EQ(open_generated_chunks("mesh.ply", 100), nullptr);
  EXPECT_NE(open_generated_chunks("terrain:8", 100), nullptr);
}

// ---- subdivided meshes ----

TEST(ChunkSources, SubdivisionSpecs) {
  SubdivisionSpec s = parse_subdivision("subdiv:2:torus:64");
  EXPECT_EQ(s.levels, 2);
  EXPECT_EQ(s.path, "torus:64");
  EXPECT_TRUE(s.displaced);
  s = parse_subdivision("subdiv-flat:0:/a/b.ply");
  EXPECT_EQ(s.levels, 0);
  EXPECT_EQ(s.path, "/a/b.ply");
  EXPECT_FALSE(s.displaced);
  EXPECT_EQ(parse_subdivision("subdiv:12:x.obj").levels, 12);
  for (const char* bad : {"subdiv:13:x.obj", "subdiv::x.obj", "subdiv:2:", "subdiv:02:x.obj",
                          "subdiv:2", "subdiv:-1:x.obj", "subdivide:2:x.obj", "subdiv:2x:y"})
    EXPECT_NE(error_of([&] { parse_subdivision(bad); }), "") << bad;
  EXPECT_TRUE(is_subdivision("subdiv:2:x"));
  EXPECT_TRUE(is_subdivision("subdiv-flat:2:x"));
  EXPECT_FALSE(is_subdivision("terrain:2"));
  EXPECT_NE(error_of([] { open_subdivided_chunks("torus:8", 2, 0); }), "");
  EXPECT_NE(error_of([] { open_subdivided_chunks("torus:8", 13, 100); }), "");
  EXPECT_NE(error_of([] { open_subdivided_chunks("no_such_file.ply", 1, 100); }), "");
}

// The base mesh's fan triangles, as the source documents them.
std::vector<std::array<Vec3f, 3>> fan_triangles(const PolyMesh& m) {
  std::vector<std::array<Vec3f, 3>> t;
  uint64_t c = 0;
  for (uint32_t n : m.face_sizes) {
    const uint32_t* f = m.face_indices.data() + c;
    for (uint32_t k = 1; k + 1 < n; ++k)
      t.push_back({m.positions[f[0]], m.positions[f[k]], m.positions[f[k + 1]]});
    c += n;
  }
  return t;
}

double area(Vec3f a, Vec3f b, Vec3f c) {
  const double ux = double(b.x) - a.x, uy = double(b.y) - a.y, uz = double(b.z) - a.z;
  const double vx = double(c.x) - a.x, vy = double(c.y) - a.y, vz = double(c.z) - a.z;
  const double x = uy * vz - uz * vy, y = uz * vx - ux * vz, z = ux * vy - uy * vx;
  return 0.5 * std::sqrt(x * x + y * y + z * z);
}

// Lattice point (u, v) of (a, b, c), n per side, in double.
std::array<double, 3> lattice(const std::array<Vec3f, 3>& t, int n, int u, int v) {
  std::array<double, 3> p;
  for (int k = 0; k < 3; ++k)
    p[k] = ((n - u - v) * double(t[0][k]) + u * double(t[1][k]) + v * double(t[2][k])) / n;
  return p;
}

// Local triangle `local` of an n x n lattice as documented: (u, v, up).
void local_triangle(int n, uint64_t local, int& u, int& v, bool& up) {
  v = 0;
  while (uint64_t(v + 1) * uint64_t(2 * n - v - 1) <= local) ++v;
  const uint64_t r = local - uint64_t(v) * uint64_t(2 * n - v);
  u = int(r / 2);
  up = r % 2 == 0;
}

struct SubdivisionCheck {
  uint64_t faces = 0, chunks = 0;
  size_t open_edges = 0, unpaired_directed = 0;
  std::vector<double> base_area, sub_area;
  double max_lattice_error = 0;  // distance of the corners from the flat lattice, / base edge
};

// Loads every chunk of `src` over `base`: each face id once, the corners at the documented
// lattice points (flat) or near them (displaced), areas per base triangle, edges by bits.
SubdivisionCheck check_subdivided(const ChunkSource& src, const PolyMesh& base, int levels,
                                  uint64_t max) {
  SubdivisionCheck r;
  const auto tris = fan_triangles(base);
  const int n = 1 << levels;
  const uint64_t sub = uint64_t(n) * uint64_t(n);
  std::vector<uint8_t> seen(tris.size() * sub, 0);
  r.base_area.resize(tris.size());
  r.sub_area.assign(tris.size(), 0.0);
  for (size_t t = 0; t < tris.size(); ++t)
    r.base_area[t] = area(tris[t][0], tris[t][1], tris[t][2]);
  std::map<std::array<uint32_t, 6>, int> directed;
  uint64_t bad = 0;
  for (size_t i = 0; i < src.size(); ++i) {
    const Chunk ch = src.load(i);
    check_chunk(src, i, ch, max, sub);
    r.faces += ch.mesh.face_count();
    ++r.chunks;
    for (size_t f = 0; f < ch.mesh.face_count(); ++f) {
      const uint64_t id = ch.face_ids[f];
      if (id >= seen.size()) {
        if (bad++ < 5) ADD_FAILURE() << "face id " << id << " out of range";
        continue;
      }
      if (seen[id]++ && bad++ < 5) ADD_FAILURE() << "face id " << id << " twice";
      const uint64_t t = id / sub;
      Vec3f c[3];
      for (int k = 0; k < 3; ++k) c[k] = ch.mesh.positions[ch.mesh.face_indices[3 * f + k]];
      r.sub_area[t] += area(c[0], c[1], c[2]);
      int u, v;
      bool up;
      local_triangle(n, id % sub, u, v, up);
      const int lu[3] = {up ? u : u + 1, u + 1, u}, lv[3] = {v, up ? v : v + 1, v + 1};
      double edge = 0;
      for (int k = 0; k < 3; ++k) {
        const Vec3f& a = tris[t][k];
        const Vec3f& b = tris[t][(k + 1) % 3];
        edge = std::max(edge, double(std::sqrt((b - a).x * (b - a).x + (b - a).y * (b - a).y +
                                               (b - a).z * (b - a).z)));
      }
      for (int k = 0; k < 3; ++k) {
        const auto p = lattice(tris[t], n, lu[k], lv[k]);
        double d2 = 0;
        for (int a = 0; a < 3; ++a) d2 += (p[a] - c[k][a]) * (p[a] - c[k][a]);
        if (edge > 0) r.max_lattice_error = std::max(r.max_lattice_error, std::sqrt(d2) / edge);
      }
      for (int k = 0; k < 3; ++k) {
        const auto a = bits(c[k]), b = bits(c[(k + 1) % 3]);
        ++directed[{a[0], a[1], a[2], b[0], b[1], b[2]}];
      }
    }
  }
  EXPECT_EQ(bad, 0u);
  for (size_t id = 0; id < seen.size(); ++id)
    if (!seen[id]) {
      ADD_FAILURE() << "face id " << id << " in no chunk";
      break;
    }
  for (const auto& [e, count] : directed) {
    const std::array<uint32_t, 6> rev = {e[3], e[4], e[5], e[0], e[1], e[2]};
    const auto it = directed.find(rev);
    const int back = it == directed.end() ? 0 : it->second;
    r.open_edges += count + back != 2;
    r.unpaired_directed += count != 1 || back != 1;
  }
  return r;
}

TEST(ChunkSources, SubdividedFlatTorusKeepsAreaIdsAndClosure) {
  const PolyMesh base = slim::load("torus:12");  // 72 quads, 144 fan triangles, closed
  for (int levels : {0, 1, 2, 3}) {
    SCOPED_TRACE("levels " + std::to_string(levels));
    // At least 10 base triangles a chunk, so that base edges are shared within chunks too.
    const uint64_t max = std::max<uint64_t>(100, uint64_t(10) << (2 * levels));
    SubdividedChunks src(base, levels, false, max);
    EXPECT_EQ(src.base_triangles(), 144u);
    EXPECT_EQ(src.faces(), 144u << (2 * levels));
    EXPECT_GT(src.size(), 1u);
    expect_same_box(src.bounds(), base.bounds(), "flat: the base box");
    const SubdivisionCheck r = check_subdivided(src, base, levels, max);
    EXPECT_EQ(r.faces, src.faces());
    for (size_t t = 0; t < r.base_area.size(); ++t)
      EXPECT_NEAR(r.sub_area[t], r.base_area[t], 1e-5 * r.base_area[t]) << "base triangle " << t;
    EXPECT_LT(r.max_lattice_error, 1e-6);  // the documented order and corners
    EXPECT_EQ(r.open_edges, 0u);
    EXPECT_EQ(r.unpaired_directed, 0u);  // and consistently wound, as the torus is
  }
}

TEST(ChunkSources, SubdividedDisplacedTorusIsClosedAndNotFlat) {
  const PolyMesh base = slim::load("torus:12");
  const int levels = 3;
  SubdividedChunks src(base, levels, true, 500);
  const SubdivisionCheck r = check_subdivided(src, base, levels, 500);
  EXPECT_EQ(r.faces, src.faces());
  EXPECT_EQ(r.open_edges, 0u);
  EXPECT_EQ(r.unpaired_directed, 0u);
  // Off the flat lattice (each point by at most kDisplacement * sqrt(3) of a lattice edge), so
  // not planar, and by no more than that.
  EXPECT_GT(r.max_lattice_error, 1e-3);
  EXPECT_LT(r.max_lattice_error, kDisplacement * 1.8 / (1 << levels));
  // The same bits however the base triangles are grouped into chunks.
  SubdividedChunks one(base, levels, true, 1 << 20);
  ASSERT_EQ(one.size(), 1u);
  const Chunk all = one.load(0);
  std::vector<std::array<Vec3f, 3>> by_id(all.face_ids.size());
  for (size_t f = 0; f < all.face_ids.size(); ++f)
    for (int k = 0; k < 3; ++k)
      by_id[all.face_ids[f]][k] = all.mesh.positions[all.mesh.face_indices[3 * f + k]];
  uint64_t differ = 0;
  for (size_t i = 0; i < src.size(); ++i) {
    const Chunk ch = src.load(i);
    for (size_t f = 0; f < ch.face_ids.size(); ++f)
      for (int k = 0; k < 3; ++k)
        differ += !same_bits(by_id[ch.face_ids[f]][k],
                             ch.mesh.positions[ch.mesh.face_indices[3 * f + k]]);
  }
  EXPECT_EQ(differ, 0u);
}

TEST(ChunkSources, SubdividedScanIsClosed) {
  // spot_quadrangulated.obj: a closed all-quad manifold (MANIFEST).
  const std::string path = slim::test::shared_data_dir() + "/spot_quadrangulated.obj";
  SLIM_REQUIRE_SHARED_FILE(path);
  const PolyMesh base = slim::load(path);
  for (bool displaced : {false, true}) {
    SCOPED_TRACE(displaced ? "displaced" : "flat");
    const int levels = 2;
    auto src = open_subdivided_chunks(path, levels, 20000, displaced);
    EXPECT_EQ(src->faces(), base.fan_triangle_count() * 16);
    const SubdivisionCheck r = check_subdivided(*src, base, levels, 20000);
    EXPECT_EQ(r.faces, src->faces());
    EXPECT_GT(r.chunks, 3u);
    EXPECT_EQ(r.open_edges, 0u);
    if (!displaced) {
      for (size_t t = 0; t < r.base_area.size(); ++t)
        EXPECT_NEAR(r.sub_area[t], r.base_area[t], 1e-5 * r.base_area[t]) << "base triangle " << t;
    }
  }
  // The scene-name form.
  auto named = open_generated_chunks("subdiv:1:" + path, 1 << 20);
  ASSERT_NE(named, nullptr);
  EXPECT_EQ(named->faces(), base.fan_triangle_count() * 4);
}

// `slimrt info SCENE --chunks N --json`: procedural scenes and subdiv: are generated, --spill
// streams a procedural scene instead; both give the same faces.
nlohmann::json info_chunks_json(const std::string& args) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("slimrt_info_chunks_" + std::to_string(getpid()) + ".json"))
                               .string();
  const std::string cmd = std::string(SLIM_CLI_PATH) + " info " + args + " --json > " + path;
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  std::ifstream in(path);
  nlohmann::json j = nlohmann::json::parse(in, nullptr, false);
  std::filesystem::remove(path);
  return j;
}

TEST(ChunkSources, InfoCli) {
  const nlohmann::json gen = info_chunks_json("terrain:40 --chunks 300");
  ASSERT_FALSE(gen.is_discarded());
  EXPECT_EQ(gen["source"], "generated");
  EXPECT_EQ(gen["faces"].get<uint64_t>(), 1600u);
  EXPECT_EQ(gen["chunks"].get<uint64_t>(), ProceduralChunks("terrain:40", 300).size());
  const nlohmann::json spilled = info_chunks_json("terrain:40 --chunks 300 --spill");
  ASSERT_FALSE(spilled.is_discarded());
  EXPECT_EQ(spilled["source"], "spilled");
  EXPECT_EQ(spilled["faces"], gen["faces"]);
  EXPECT_EQ(spilled["bounds"], gen["bounds"]);
  const nlohmann::json sub = info_chunks_json("subdiv:2:torus:8 --chunks 100");
  ASSERT_FALSE(sub.is_discarded());
  EXPECT_EQ(sub["source"], "generated");
  EXPECT_EQ(sub["triangles"].get<uint64_t>(), 8u * 4 * 2 * 16);
  EXPECT_EQ(sub["chunks"].get<uint64_t>(), 11u);  // 64 base triangles, 6 a chunk
}

}  // namespace
