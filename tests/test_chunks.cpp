// Face streams (io/face_stream.h) and the spatial chunking (mesh/chunks.h):
// every face of the in-memory load comes out of the stream, and lands in exactly one chunk, with
// its face id and positions bit for bit; bad files give the same errors as slim::load.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "io/face_stream.h"
#include "io/xz.h"
#include "mesh/chunks.h"
#include "mesh/procedural.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

namespace fs = std::filesystem;
using slim::PolyMesh;
using slim::Vec3f;
using namespace slim::detail;

using slim::test::error_of;
using slim::test::TempDir;

namespace {

bool same_bits(Vec3f a, Vec3f b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Checks that the faces handed to `add` (id, corners) are exactly the faces of `ref`, each once.
class FaceChecker {
 public:
  explicit FaceChecker(const PolyMesh& ref) : ref_(ref), off_(ref.face_offsets()) {
    seen_.assign(ref.face_count(), 0);
  }
  void add(uint64_t id, const Vec3f* corners, uint32_t n) {
    if (id >= seen_.size()) {
      if (bad_++ < 5) ADD_FAILURE() << "face id " << id << " >= " << seen_.size();
      return;
    }
    if (seen_[id]++ != 0 && bad_++ < 5) ADD_FAILURE() << "face " << id << " delivered twice";
    if (n != ref_.face_sizes[id]) {
      if (bad_++ < 5)
        ADD_FAILURE() << "face " << id << ": " << n << " corners, expected " << ref_.face_sizes[id];
      return;
    }
    for (uint32_t k = 0; k < n; ++k)
      if (!same_bits(corners[k], ref_.positions[ref_.face_indices[off_[id] + k]]) && bad_++ < 5)
        ADD_FAILURE() << "face " << id << " corner " << k << " differs";
  }
  void add(const FaceBatch& b) {
    const Vec3f* c = b.corners.data();
    for (size_t f = 0; f < b.face_count(); ++f) {
      add(b.face_ids[f], c, b.sizes[f]);
      c += b.sizes[f];
    }
  }
  void add(const Chunk& ch) {
    const auto off = ch.mesh.face_offsets();
    std::vector<Vec3f> c;
    for (size_t f = 0; f < ch.mesh.face_count(); ++f) {
      c.clear();
      for (uint64_t k = off[f]; k < off[f + 1]; ++k)
        c.push_back(ch.mesh.positions[ch.mesh.face_indices[k]]);
      add(ch.face_ids[f], c.data(), ch.mesh.face_sizes[f]);
    }
  }
  void expect_complete() const {
    uint64_t missing = 0;
    for (uint8_t s : seen_) missing += s == 0;
    EXPECT_EQ(missing, 0u) << "faces never delivered, of " << seen_.size();
    EXPECT_EQ(bad_, 0u);
  }

 private:
  const PolyMesh& ref_;
  std::vector<uint64_t> off_;
  std::vector<uint8_t> seen_;
  uint64_t bad_ = 0;
};

// Streams all of `s` twice (rewind in between), checking against `ref`; batches stay near
// `max_corners`.
void expect_stream_matches(FaceStream& s, const PolyMesh& ref, size_t max_corners) {
  for (int pass = 0; pass < 2; ++pass) {
    SCOPED_TRACE("pass " + std::to_string(pass));
    s.rewind();
    FaceChecker check(ref);
    FaceBatch b;
    while (s.next(b)) {
      ASSERT_GT(b.face_count(), 0u);
      if (b.face_count() > 1) {
        EXPECT_LE(b.corners.size(), max_corners + 8 * 16);
      }
      check.add(b);
    }
    EXPECT_EQ(b.face_count(), 0u);
    EXPECT_FALSE(s.next(b));
    check.expect_complete();
  }
}

// Chunks `name` and checks the union of the chunks against slim::load(name).
void expect_chunks_match(const std::string& name, const ChunkOptions& opt, size_t min_chunks,
                         size_t max_corners = 5000, size_t window = 4096) {
  SCOPED_TRACE(name);
  const PolyMesh ref = slim::load(name);
  auto s = open_face_stream(name, max_corners, window);
  size_t chunks = 0;
  {
    ChunkSet set(*s, opt);
    chunks = set.size();
    EXPECT_GE(set.size(), min_chunks);
    EXPECT_EQ(set.stats().faces, ref.face_count());
    EXPECT_EQ(set.stats().triangles, ref.fan_triangle_count());
    // The spill buffers stay within the budget (each gets at least 4 KiB).
    if (opt.memory_budget / set.size() >= 4096) {
      EXPECT_LE(set.stats().buffer_bytes, opt.memory_budget);
    }
    EXPECT_GT(set.stats().buffer_bytes, 0u);
    FaceChecker check(ref);
    for (size_t i = 0; i < set.size(); ++i) {
      const Chunk ch = set.load(i);
      EXPECT_EQ(ch.mesh.face_count(), set.info(i).faces);
      EXPECT_LE(set.info(i).triangles, opt.max_triangles) << "chunk " << i;
      EXPECT_EQ(ch.mesh.fan_triangle_count(), set.info(i).triangles);
      EXPECT_NO_THROW(slim::check_mesh(ch.mesh));
      check.add(ch);
    }
    check.expect_complete();
    EXPECT_TRUE(fs::exists(set.directory()));
  }
  EXPECT_GT(chunks, 0u);
}

// A small polygon mesh (3- to 6-gons, random positions with exact binary fractions and some
// arbitrary floats) written as PLY or OBJ below.
PolyMesh polygon_mesh(uint32_t faces, uint32_t seed) {
  std::mt19937 rng(seed);
  PolyMesh m;
  const uint32_t nv = faces + 10;
  for (uint32_t i = 0; i < nv; ++i) {
    auto r = [&] { return float(int32_t(rng() % 2000001) - 1000000) * 1e-6f + 1.0f / 3.0f; };
    m.positions.push_back({r(), r(), r()});
  }
  for (uint32_t f = 0; f < faces; ++f) {
    const uint32_t n = 3 + rng() % 4;
    m.face_sizes.push_back(n);
    for (uint32_t k = 0; k < n; ++k) m.face_indices.push_back(rng() % nv);
  }
  return m;
}

// %.9g round-trips every float.
std::string num(float v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.9g", double(v));
  return b;
}

template <class T>
void put(std::string& s, T v, bool be) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof v);
  if (be) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

// PLY with an extra vertex property, a 'material' element before the faces and an 'edge' element
// after them; `faces_first` puts the face element before the vertex element.
std::string ply_text(const PolyMesh& m, const std::string& format, bool faces_first = false) {
  const bool ascii = format == "ascii", be = format == "binary_big_endian";
  std::string h = "ply\nformat " + format + " 1.0\ncomment face stream test\n";
  std::string vert_h =
      "element vertex " + std::to_string(m.vertex_count()) +
      "\nproperty float x\nproperty float y\nproperty uchar flag\nproperty float z\n";
  std::string face_h = "element face " + std::to_string(m.face_count()) +
                       "\nproperty list uchar int vertex_indices\nproperty short tag\n";
  std::string mat_h = "element material 2\nproperty list ushort uchar name\n";
  std::string edge_h = "element edge 1\nproperty int a\nproperty int b\n";
  std::string verts, facesb, mat, edge;
  for (const Vec3f& p : m.positions) {
    if (ascii) {
      verts += num(p.x) + " " + num(p.y) + " 7 " + num(p.z) + "\n";
    } else {
      put(verts, p.x, be), put(verts, p.y, be), put(verts, uint8_t(7), be), put(verts, p.z, be);
    }
  }
  const auto off = m.face_offsets();
  for (size_t f = 0; f < m.face_count(); ++f) {
    if (ascii) {
      facesb += std::to_string(m.face_sizes[f]);
      for (uint64_t k = off[f]; k < off[f + 1]; ++k)
        facesb += (k % 7 == 3 ? "\n  " : " ") + std::to_string(m.face_indices[k]);
      facesb += " -3\n";
    } else {
      put(facesb, uint8_t(m.face_sizes[f]), be);
      for (uint64_t k = off[f]; k < off[f + 1]; ++k) put(facesb, int32_t(m.face_indices[k]), be);
      put(facesb, int16_t(-3), be);
    }
  }
  for (int i = 0; i < 2; ++i) {
    if (ascii) {
      mat += "3 65 66 67\n";
    } else {
      put(mat, uint16_t(3), be);
      mat += "ABC";
    }
  }
  if (ascii)
    edge = "0 1\n";
  else
    put(edge, int32_t(0), be), put(edge, int32_t(1), be);
  if (faces_first)
    return h + face_h + mat_h + vert_h + edge_h + "end_header\n" + facesb + mat + verts + edge;
  return h + vert_h + mat_h + face_h + edge_h + "end_header\n" + verts + mat + facesb + edge;
}

// OBJ with vt/vn, every corner form, negative indices, groups, comments and mixed line ends.
std::string obj_text(const PolyMesh& m) {
  std::string s = "# face stream test\r\nmtllib none.mtl\n";
  const auto off = m.face_offsets();
  size_t next_vertex = 0;
  const char* ends[3] = {"\n", "\r\n", "\r"};
  for (size_t f = 0; f < m.face_count(); ++f) {
    // Define vertices lazily, so that faces use vertices defined just before them.
    uint32_t need = 0;
    for (uint64_t k = off[f]; k < off[f + 1]; ++k) need = std::max(need, m.face_indices[k] + 1);
    while (next_vertex < need) {
      const Vec3f& p = m.positions[next_vertex++];
      s += "v " + num(p.x) + "  " + num(p.y) + "\t" + num(p.z) + ends[next_vertex % 3];
      s += "vt 0.5 0.25\nvn 0 0 1\n";
    }
    if (f % 50 == 0) s += "g part" + std::to_string(f / 100) + "\n";
    s += "f";
    for (uint64_t k = off[f]; k < off[f + 1]; ++k) {
      const uint32_t i = m.face_indices[k];
      const int64_t rel = int64_t(i) - int64_t(next_vertex);  // -N..-1
      switch ((f + k) % 4) {
        case 0:
          s += " " + std::to_string(i + 1);
          break;
        case 1:
          s += " " + std::to_string(rel) + "/" + std::to_string(i + 1);
          break;
        case 2:
          s += " " + std::to_string(i + 1) + "//" + std::to_string(rel);
          break;
        default:
          s += " " + std::to_string(i + 1) + "/1/" + std::to_string(i + 1);
          break;
      }
    }
    s += ends[f % 3];
  }
  // Vertices after the last face (unused) are fine.
  while (next_vertex < m.vertex_count()) {
    const Vec3f& p = m.positions[next_vertex++];
    s += "v " + num(p.x) + " " + num(p.y) + " " + num(p.z) + "\n";
  }
  return s;
}

// Runs fn; expects a slim::Error and returns its message.
// Streams all faces of `path` (for the error tests).
void drain(const std::string& path, size_t window = 4096) {
  auto s = open_face_stream(path, 64, window);
  FaceBatch b;
  while (s->next(b)) {
  }
}

}  // namespace

// ---- procedural scenes ----

TEST(FaceStream, ProceduralMatchesLoad) {
  for (const char* name : {"terrain:37", "canyon:29", "torus:24", "terrain:1"}) {
    SCOPED_TRACE(name);
    const PolyMesh ref = slim::load(name);
    for (size_t batch : {size_t(1), size_t(100), size_t(1) << 20}) {
      auto s = open_face_stream(name, batch);
      EXPECT_EQ(s->declared_faces(), ref.face_count());
      expect_stream_matches(*s, ref, std::max<size_t>(batch, 4 * 37));
    }
  }
}

// A tile of a scene holds exactly the quads of that region of the whole mesh, bit for bit.
TEST(FaceStream, ProceduralTileIsTheRegion) {
  for (const char* name : {"terrain:40", "canyon:33", "torus:30"}) {
    SCOPED_TRACE(name);
    const PolyMesh ref = slim::load(name);
    const ProceduralGrid g(parse_procedural(name, 65534));
    const int i0 = 3, i1 = g.cells_x, j0 = 5, j1 = g.cells_y - 2;
    FaceBatch b;
    g.tile(i0, i1, j0, j1, b.sizes, b.face_ids, b.corners);
    ASSERT_EQ(b.face_count(), size_t(i1 - i0) * size_t(j1 - j0));
    const auto off = ref.face_offsets();
    for (size_t f = 0; f < b.face_count(); ++f) {
      const uint64_t id = b.face_ids[f];
      const int i = int(id % uint64_t(g.cells_x)), j = int(id / uint64_t(g.cells_x));
      EXPECT_TRUE(i >= i0 && i < i1 && j >= j0 && j < j1) << id;
      for (int k = 0; k < 4; ++k)
        ASSERT_TRUE(same_bits(b.corners[4 * f + k], ref.positions[ref.face_indices[off[id] + k]]))
            << "face " << id << " corner " << k;
    }
  }
}

// Scenes beyond the in-memory limit (16384) stream: the 1 G-triangle terrain.
TEST(FaceStream, ProceduralBeyondTheInMemoryLimit) {
  auto s = open_face_stream("terrain:22361");
  EXPECT_EQ(s->declared_faces(), uint64_t(22361) * 22361);
  FaceBatch b;
  ASSERT_TRUE(s->next(b));
  ASSERT_GT(b.face_count(), 22361u);
  EXPECT_EQ(b.face_count() % 22361, 0u);  // whole rows
  for (size_t f = 0; f < b.face_count(); ++f) ASSERT_EQ(b.face_ids[f], f);
  EXPECT_LE(b.corners.size(), kDefaultBatchCorners);
  EXPECT_LT(s->resident_bytes(), uint64_t(16) << 20);
}

TEST(FaceStream, ProceduralBadSpec) {
  for (const char* spec : {"terrain:0", "terrain:65535", "torus:7", "canyon:-3", "terrain:01"})
    EXPECT_NE(error_of([&] { open_face_stream(spec); }).find(spec), std::string::npos) << spec;
}

// ---- PLY and OBJ files ----

TEST(FaceStream, PlyAllFormatsMatchLoad) {
  TempDir d{"slimrt_chunks"};
  const PolyMesh m = polygon_mesh(3000, 11);
  for (const char* fmt : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    for (bool faces_first : {false, true}) {
      SCOPED_TRACE(std::string(fmt) + (faces_first ? " faces first" : ""));
      const std::string path = d.write(std::string(fmt) + (faces_first ? "_ff" : "") + ".ply",
                                       ply_text(m, fmt, faces_first));
      const PolyMesh ref = slim::load(path);
      ASSERT_EQ(ref.face_count(), m.face_count());
      for (size_t window : {size_t(4096), size_t(5000), size_t(1) << 22}) {
        auto s = open_face_stream(path, 500, window);
        EXPECT_EQ(s->declared_faces(), ref.face_count());
        expect_stream_matches(*s, ref, 500);
      }
    }
  }
  // .ply.xz files are decompressed into memory and read by the same parser: Chunks.RealMeshes.
}

TEST(FaceStream, ObjMatchesLoad) {
  TempDir d{"slimrt_chunks"};
  const PolyMesh m = polygon_mesh(2000, 12);
  const std::string path = d.write("m.obj", obj_text(m));
  const PolyMesh ref = slim::load(path);
  ASSERT_EQ(ref.face_count(), m.face_count());
  for (size_t window : {size_t(4096), size_t(4099), size_t(1) << 22}) {
    auto s = open_face_stream(path, 300, window);
    expect_stream_matches(*s, ref, 300);
  }
}

// Bad files: the stream gives slim::load's message (file and line or byte offset), before or
// while streaming.
TEST(FaceStream, BadFilesGiveLoadErrors) {
  TempDir d{"slimrt_chunks"};
  const PolyMesh m = polygon_mesh(400, 13);
  std::vector<std::string> bad;
  for (const char* fmt : {"binary_little_endian", "binary_big_endian", "ascii"}) {
    const std::string good = ply_text(m, fmt);
    const std::string f = std::string(fmt);
    bad.push_back(d.write(f + "_trunc.ply", good.substr(0, good.size() * 2 / 3)));
    bad.push_back(d.write(f + "_short.ply", good.substr(0, good.size() - 3)));
    std::string lie = good;  // a header that claims more faces than there are
    lie.replace(lie.find("element face 400"), 16, "element face 401");
    bad.push_back(d.write(f + "_lie.ply", lie));
    std::string idx = good;  // a vertex index past the vertices, late in the file
    if (f == "ascii") {
      const size_t at = idx.rfind(" -3\n", idx.rfind(" -3\n") - 1);
      idx.replace(idx.rfind(' ', at - 1), at - idx.rfind(' ', at - 1), " 99999");
    } else {
      const size_t at = idx.size() - 8 - 2 - 4;  // last index of the last face
      int32_t v = 99999;
      char b[4];
      std::memcpy(b, &v, 4);
      if (f == "binary_big_endian") std::reverse(b, b + 4);
      idx.replace(at, 4, b, 4);
    }
    bad.push_back(d.write(f + "_index.ply", idx));
  }
  bad.push_back(d.write("empty.ply", ""));
  bad.push_back(d.write("noend.ply", "ply\nformat ascii 1.0\nelement vertex 3\n"));
  bad.push_back(d.write("huge.ply",
                        "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n"
                        "property float x\nproperty float y\nproperty float z\nend_header\n"));
  const std::string obj = obj_text(m);
  bad.push_back(d.write("index.obj", obj + "f 1 2 999999\n"));
  bad.push_back(d.write("neg.obj", obj + "f 1 2 -999999\n"));
  bad.push_back(d.write("two.obj", obj + "v 1 2 3\nf 1 2\n"));
  bad.push_back(d.write("nul.obj", obj + std::string("v 1 2\0 3\n", 9)));
  bad.push_back(d.write("coord.obj", "v 1 2\nf 1 1 1\n"));
  bad.push_back(d.write("overflow.obj", obj + "v 1e39 0 0\n"));
  for (const std::string& path : bad) {
    SCOPED_TRACE(path);
    const std::string expected = error_of([&] { slim::load(path); });
    ASSERT_EQ(expected.rfind(path, 0), 0u) << expected;
    for (size_t window : {size_t(4096), size_t(1) << 22})
      EXPECT_EQ(error_of([&] { drain(path, window); }), expected);
  }
  EXPECT_NE(error_of([&] { open_face_stream(d.path("missing.ply")); }).find("missing.ply"),
            std::string::npos);
  // A FIFO without a writer: refused by its type before it is opened (an open would block), with
  // load()'s message; so is a missing file.
  const std::string fifo = d.path("pipe.ply");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {fifo, d.path("missing.ply")}) {
    const std::string expected = error_of([&] { slim::load(path); });
    EXPECT_EQ(expected.rfind(path, 0), 0u) << expected;
    EXPECT_EQ(error_of([&] { open_face_stream(path); }), expected);
  }
  EXPECT_NE(error_of([&] { open_face_stream(d.write("a.gltf", "{}")); }).find("a.gltf"),
            std::string::npos);
}

// ---- chunking ----

TEST(Chunks, ProceduralUnionIsTheMesh) {
  TempDir d{"slimrt_chunks"};
  ChunkOptions opt;
  opt.spill_dir = d.dir();
  opt.max_triangles = 500;
  opt.memory_budget = 64 << 10;  // tiny buffers: many flushes
  expect_chunks_match("terrain:64", opt, 16);
  expect_chunks_match("canyon:50", opt, 10);
  opt.morton_bits = 2;  // coarse cells: most cells are split into pieces
  expect_chunks_match("torus:64", opt, 8);
  EXPECT_EQ(d.entries(), 0u) << "spill directories left behind";
}

// The case: torus:512 in at least 16 chunks, each within the triangle limit.
TEST(Chunks, Torus512InAtLeast16Chunks) {
  TempDir d{"slimrt_chunks"};
  ChunkOptions opt;
  opt.spill_dir = d.dir();
  opt.max_triangles = 512 * 256 * 2 / 20;
  expect_chunks_match("torus:512", opt, 16, 1 << 16);
  EXPECT_EQ(d.entries(), 0u);
}

TEST(Chunks, FilesUnionIsTheMesh) {
  TempDir d{"slimrt_chunks"};
  const PolyMesh m = polygon_mesh(3000, 21);
  const TempDir spill{"slimrt_spill"};
  ChunkOptions opt;
  opt.spill_dir = spill.dir();
  opt.max_triangles = 400;
  for (const char* fmt : {"binary_little_endian", "binary_big_endian", "ascii"})
    expect_chunks_match(d.write(std::string(fmt) + ".ply", ply_text(m, fmt)), opt, 8);
  expect_chunks_match(d.write("m.obj", obj_text(m)), opt, 8);
  EXPECT_EQ(spill.entries(), 0u);
}

TEST(Chunks, RealMeshes) {
  SLIM_REQUIRE_SHARED_DATA();
  TempDir d{"slimrt_chunks"};
  ChunkOptions opt;
  opt.spill_dir = d.dir();
  const std::string data = slim::test::shared_data_dir();
  const std::string obj = data + "/spot_quadrangulated.obj", ply = data + "/igea.ply.xz";
  SLIM_REQUIRE_SHARED_FILE(obj);
  SLIM_REQUIRE_SHARED_FILE(ply);
  opt.max_triangles = 500;
  expect_chunks_match(obj, opt, 8, 1 << 14, 1 << 16);  // plain OBJ through the window
  opt.max_triangles = 20000;
  expect_chunks_match(ply, opt, 8, 1 << 16);  // .ply.xz, in memory
  // The same PLY decompressed, through the window.
  const FileBytes bytes = read_file(ply);
  const std::string plain = d.write("igea.ply", std::string(bytes.view()));
  expect_chunks_match(plain, opt, 8, 1 << 16, 1 << 16);
}

// An error while streaming (here a truncated file) leaves no spill file behind.
TEST(Chunks, ErrorsRemoveSpillFiles) {
  TempDir d{"slimrt_chunks"};
  const PolyMesh m = polygon_mesh(2000, 22);
  std::string good = ply_text(m, "binary_little_endian");
  const std::string path = d.write("late.ply", good.substr(0, good.size() - 20));
  const TempDir spill{"slimrt_spill"};
  ChunkOptions opt;
  opt.spill_dir = spill.dir();
  opt.max_triangles = 300;
  const std::string expected = error_of([&] { slim::load(path); });
  auto s = open_face_stream(path, 256, 4096);
  EXPECT_EQ(error_of([&] { ChunkSet set(*s, opt); }), expected);
  EXPECT_EQ(spill.entries(), 0u);
  opt.spill_dir = d.path("no/such/dir");
  auto t = open_face_stream("terrain:8");
  EXPECT_NE(error_of([&] { ChunkSet set(*t, opt); }).find("no/such/dir"), std::string::npos);
}

// Each chunk built alone with a lossless configuration; the closest hit over all chunk scenes is
// the in-memory scene's hit (same face, same t) up to ties checked geometrically (another face
// only where the ray passes through an edge or vertex it shares with the in-memory hit's face),
// bounded. A stand-in for the top-level BVH,
// which joins the chunk roots later.
TEST(Chunks, ClosestHitOverChunksEqualsInMemory) {
  TempDir d{"slimrt_chunks"};
  const std::string name = "torus:512";
  const PolyMesh ref = slim::load(name);
  const slim::BuildOptions bo = slim::BuildOptions::from_config("bvh8-tri4v");
  const slim::Scene whole = slim::Scene::build(ref, bo);
  ChunkOptions opt;
  opt.spill_dir = d.dir();
  opt.max_triangles = 512 * 256 * 2 / 20;
  auto s = open_face_stream(name);
  ChunkSet set(*s, opt);
  ASSERT_GE(set.size(), 16u);
  std::vector<slim::Scene> scenes;
  std::vector<std::vector<uint64_t>> ids;
  for (size_t i = 0; i < set.size(); ++i) {
    Chunk c = set.load(i);
    scenes.push_back(slim::Scene::build(c.mesh, bo));
    ids.push_back(std::move(c.face_ids));
  }
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  const std::vector<slim::test::RefTri> tris = slim::test::reference_triangles({&ref});
  int hits = 0, ties = 0, wrong = 0;
  for (int r = 0; r < 20000; ++r) {
    slim::Ray ray;
    ray.org = Vec3f(u(rng) * 2.0f, u(rng) * 2.0f, u(rng) * 1.0f);
    const Vec3f target(u(rng) * 1.4f, u(rng) * 1.4f, u(rng) * 0.4f);  // within the torus' box
    ray.dir = target - ray.org;
    const slim::Hit a = whole.intersect(ray);
    slim::Hit best;
    uint64_t best_face = ~uint64_t(0);
    for (size_t i = 0; i < scenes.size(); ++i) {
      const slim::Hit h = scenes[i].intersect(ray);
      if (h.valid() && h.t < best.t) {
        best = h;
        best_face = ids[i][h.primID];
      }
    }
    ASSERT_EQ(a.valid(), best.valid()) << "ray " << r;
    if (!a.valid()) continue;
    ++hits;
    ASSERT_EQ(a.t, best.t) << "ray " << r;
    if (best_face == a.primID) continue;
    // Same t, another face: a tie only through an edge or vertex the two faces share.
    ASSERT_LT(best_face, ref.face_count());
    slim::test::RefHit at;
    at.t = a.t;
    at.geom = 0;
    at.prim = a.primID;
    if (slim::test::geometric_tie(tris, ray, at, 0, uint32_t(best_face),
                                  slim::test::tie_delta(ray, a.t)) == slim::test::TieKind::Edge)
      ++ties;
    else if (wrong++ < 3)
      ADD_FAILURE() << "ray " << r << ": face " << best_face << " instead of " << a.primID
                    << " at t " << a.t << ", not through an edge or vertex they share";
  }
  std::printf("[ chunks   ] %s in %zu chunks: %d of 20000 rays hit, %d ties on another face\n",
              name.c_str(), set.size(), hits, ties);
  EXPECT_GT(hits, 10000);
  EXPECT_EQ(wrong, 0);
  EXPECT_LE(ties, hits / 1000 + 2);
}
