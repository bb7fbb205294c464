// Scene files (Scene::save / Scene::open, src/api/scene_file.cpp): every configuration round-trips
// with identical hits and figures; damaged files give a slim::Error naming file, section and
// offset, never a crash.
#include <gtest/gtest.h>
#include <unistd.h>
#include <xxhash.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "slimrt/render.h"
#include "slimrt/slimrt.h"
#include "test_util.h"

namespace slim {
namespace {

std::string temp_path(const std::string& tag) {
  return (std::filesystem::temp_directory_path() /
          ("slimrt_scene_file_" + std::to_string(::getpid()) + "_" + tag + ".slim"))
      .string();
}

std::string read_all(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), {});
}
void write_all(const std::string& p, const std::string& s) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(s.data(), std::streamsize(s.size()));
}

uint64_t get64(const std::string& s, size_t at) {
  uint64_t v;
  std::memcpy(&v, s.data() + at, 8);
  return v;
}
void put64(std::string& s, size_t at, uint64_t v) { std::memcpy(s.data() + at, &v, 8); }

// Header layout (scene_file.cpp): header_bytes at 24, header checksum at 32, section count at 40,
// the section table (80-byte entries: name[48], offset, size, checksum, elem) at 512.
constexpr size_t kHeaderBytesAt = 24, kChecksumAt = 32, kCountAt = 40, kTableAt = 512;
void fix_header_checksum(std::string& s) {
  const uint64_t hb = get64(s, kHeaderBytesAt);
  put64(s, kChecksumAt, 0);
  put64(s, kChecksumAt, XXH3_64bits(s.data(), hb));
}
uint32_t section_count(const std::string& s) {
  uint32_t n;
  std::memcpy(&n, s.data() + kCountAt, 4);
  return n;
}
size_t entry(uint32_t i) { return kTableAt + 80 * size_t(i); }

PolyMesh test_mesh() {
  // Quads (grid formats), a second mesh of random triangles (geomID 1, leftovers for the grids).
  PolyMesh m = make_terrain(20, 3);
  return m;
}

std::vector<Ray> test_rays(const Box3f& b, int n, uint32_t seed) {
  Rng rng(seed);
  std::vector<Ray> rays;
  const Vec3f c = (b.lo + b.hi) * 0.5f, e = b.hi - b.lo;
  const float r = std::max({e.x, e.y, e.z});
  for (int i = 0; i < n; ++i) {
    Vec3f o(c.x + (rng.uniform() - 0.5f) * 2 * r, c.y + (rng.uniform() - 0.5f) * 2 * r,
            c.z + r * (0.6f + rng.uniform()));
    if (i % 3 == 0)
      o = Vec3f(c.x + (rng.uniform() - 0.5f) * e.x, c.y + (rng.uniform() - 0.5f) * e.y,
                c.z + (rng.uniform() - 0.5f) * e.z);
    Vec3f t(b.lo.x + rng.uniform() * e.x, b.lo.y + rng.uniform() * e.y,
            b.lo.z + rng.uniform() * e.z);
    Ray ray;
    ray.org = o;
    ray.dir = t - o;
    if (i % 3 == 0)
      ray.dir = Vec3f(rng.uniform() - 0.5f, rng.uniform() - 0.5f, rng.uniform() - 0.5f);
    rays.push_back(ray);
  }
  return rays;
}

uint32_t bits(float f) {
  uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

void expect_same_hits(const Scene& a, const Scene& b, const std::vector<Ray>& rays,
                      const std::string& what) {
  int hits = 0, diffs = 0;
  for (const Ray& r : rays) {
    const Hit ha = a.intersect(r), hb = b.intersect(r);
    hits += ha.valid();
    if (bits(ha.t) != bits(hb.t) || ha.geomID != hb.geomID || ha.primID != hb.primID ||
        bits(ha.u) != bits(hb.u) || bits(ha.v) != bits(hb.v) || ha.kind != hb.kind ||
        a.occluded(r) != b.occluded(r))
      ++diffs;
  }
  EXPECT_EQ(diffs, 0) << what;
  EXPECT_GT(hits, int(rays.size()) / 10) << what << ": too few hits to compare";
}

void expect_same_figures(const Scene& a, const Scene& b, const std::string& what) {
  const MemoryStats ma = a.memory(), mb = b.memory();
  EXPECT_EQ(ma.geometry_bytes, mb.geometry_bytes) << what;
  EXPECT_EQ(ma.bvh_bytes, mb.bvh_bytes) << what;
  EXPECT_EQ(ma.other_bytes, mb.other_bytes) << what;
  EXPECT_EQ(ma.triangles, mb.triangles) << what;
  const SceneStats &sa = a.stats(), &sb = b.stats();
  EXPECT_EQ(sa.input_faces, sb.input_faces) << what;
  EXPECT_EQ(sa.triangles, sb.triangles) << what;
  EXPECT_EQ(sa.skipped_faces, sb.skipped_faces) << what;
  EXPECT_EQ(sa.primitives, sb.primitives) << what;
  EXPECT_EQ(sa.build_seconds, sb.build_seconds) << what;
  ASSERT_EQ(sa.details.size(), sb.details.size()) << what;
  for (size_t i = 0; i < sa.details.size(); ++i) {
    EXPECT_EQ(sa.details[i].first, sb.details[i].first) << what;
    EXPECT_EQ(std::memcmp(&sa.details[i].second, &sb.details[i].second, 8), 0) << what;
  }
  EXPECT_EQ(a.error_bound(), b.error_bound()) << what;
  const Box3f ba = a.bounds(), bb = b.bounds();
  EXPECT_EQ(std::memcmp(&ba, &bb, sizeof ba), 0) << what;
  EXPECT_EQ(a.options().config_name(), b.options().config_name()) << what;
  EXPECT_EQ(a.is_lossy(), b.is_lossy()) << what;
}

TEST(SceneFile, EveryConfigurationRoundTrips) {
  const PolyMesh terrain = test_mesh();
  const PolyMesh soup = test::random_soup(300, 5, 0.2f);
  std::vector<PolyMesh> meshes{terrain};
  // A second mesh of loose triangles: geomID 1, and leftover triangles for the grid formats.
  PolyMesh s2 = soup;
  for (Vec3f& p : s2.positions) p = p * 20.0f;
  meshes.push_back(s2);
  const std::string path = temp_path("all");
  int tested = 0;
  for (const std::string& name : all_config_names()) {
    SCOPED_TRACE(name);
    Scene built;
    try {
      built = Scene::build(meshes, BuildOptions::from_config(name));
    } catch (const NotApplicable&) {
      continue;
    }
    built.save(path);
    const std::vector<Ray> rays = test_rays(built.bounds(), 3000, 11);
    for (int mode = 0; mode < 2; ++mode) {
      OpenOptions oo;
      oo.verify_checksums = mode == 0;
      const Scene opened = Scene::open(path, oo);
      EXPECT_EQ(opened.file(), path);
      expect_same_hits(built, opened, rays, name);
      expect_same_figures(built, opened, name);
      std::string why;
      EXPECT_TRUE(opened.validate(&why)) << why;
    }
    ++tested;
  }
  std::filesystem::remove(path);
  EXPECT_EQ(tested, int(all_config_names().size()));
}

// The triangles a format with its own geometry intersects: the opened scene decodes the same ones
// from the mapping as the built scene from its memory (same order, same bits).
TEST(SceneFile, OpenedScenesDecodeTheTrianglesOfTheBuiltOnes) {
  const PolyMesh terrain = test_mesh();
  const std::string path = temp_path("decoded");
  int compared = 0;
  for (const ConfigInfo& c : configs()) {
    if (!c.own_geometry) continue;
    SCOPED_TRACE(c.name);
    Scene built;
    try {
      built = Scene::build(terrain, BuildOptions::from_config(c.name));
    } catch (const NotApplicable&) {
      continue;
    }
    built.save(path);
    const Scene opened = Scene::open(path);
    std::optional<DecodedTriangles> a;
    try {
      a = built.decoded_triangles();
    } catch (const Error&) {
      // A format that cannot decode its leaves says so the same way when opened.
      EXPECT_THROW((void)opened.decoded_triangles(), Error);
      continue;
    }
    const std::optional<DecodedTriangles> b = opened.decoded_triangles();
    ASSERT_EQ(a.has_value(), b.has_value());
    if (!a) continue;
    ASSERT_EQ(a->vertices.size(), b->vertices.size());
    EXPECT_EQ(
        std::memcmp(a->vertices.data(), b->vertices.data(), a->vertices.size() * sizeof(Vec3f)), 0);
    EXPECT_EQ(a->geom, b->geom);
    EXPECT_EQ(a->face, b->face);
    ++compared;
  }
  std::filesystem::remove(path);
  EXPECT_GT(compared, 0);
}

// A small file of a configuration the structure check covers, and its bytes.
struct Small {
  std::string path, bytes;
  Scene built;
  std::vector<Ray> rays;
};
Small small_file(const std::string& config, const std::string& tag) {
  Small s;
  s.path = temp_path(tag);
  s.built = Scene::build(make_terrain(6, 2), BuildOptions::from_config(config));
  s.built.save(s.path);
  s.bytes = read_all(s.path);
  s.rays = test_rays(s.built.bounds(), 64, 3);
  return s;
}

// Opens `bytes` (written to `path`) and traces the rays; returns the error message or "".
std::string try_open(const std::string& path, const std::string& bytes, const OpenOptions& oo,
                     const std::vector<Ray>& rays) {
  write_all(path, bytes);
  try {
    const Scene s = Scene::open(path, oo);
    for (const Ray& r : rays) {
      (void)s.intersect(r);
      (void)s.occluded(r);
    }
    return "";
  } catch (const Error& e) {
    return e.what();
  }
}

TEST(SceneFile, EveryTruncationIsAnError) {
  Small s = small_file("bvh8-tri4i", "trunc");
  const std::string cut = temp_path("trunc_cut");
  ASSERT_GT(s.bytes.size(), 1000u);
  // Every length inside the header and table, then every 29th byte (and the last one below).
  const size_t hb = get64(s.bytes, kHeaderBytesAt);
  for (size_t n = 0; n < s.bytes.size(); n += (n < hb + 256 ? 1 : 29)) {
    for (bool verify : {true, false}) {
      OpenOptions oo;
      oo.verify_checksums = verify;
      const std::string msg = try_open(cut, s.bytes.substr(0, n), oo, s.rays);
      ASSERT_FALSE(msg.empty()) << "truncated to " << n << " bytes opened";
      EXPECT_NE(msg.find(cut), std::string::npos) << msg;
      EXPECT_NE(msg.find("offset"), std::string::npos) << msg;
    }
  }
  const std::string msg = try_open(cut, s.bytes.substr(0, s.bytes.size() - 1), {}, s.rays);
  EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
  std::filesystem::remove(cut);
  std::filesystem::remove(s.path);
}

TEST(SceneFile, ByteFlipsAreCaughtByTheChecksums) {
  for (const std::string config :
       {"bvh8-tri4v", "clbvh-compact", "lossy-grid-shared", "costa-PFV", "cluster"}) {
    Small s = small_file(config, "flip");
    const std::string bad = temp_path("flip_bad");
    Rng rng(17);
    for (int i = 0; i < 300; ++i) {
      std::string b = s.bytes;
      const size_t at = size_t(rng.uniform() * float(b.size())) % b.size();
      b[at] = char(b[at] ^ (1 + int(rng.uniform() * 254.0f)));
      const std::string msg = try_open(bad, b, {}, s.rays);
      if (msg.empty()) {
        // Only a flip in the zero padding between sections goes unnoticed: nothing reads it.
        bool in_section = false;
        for (uint32_t k = 0; k < section_count(s.bytes); ++k) {
          const uint64_t off = get64(s.bytes, entry(k) + 48), size = get64(s.bytes, entry(k) + 56);
          in_section |= at >= off && at < off + size;
        }
        EXPECT_FALSE(in_section || at < get64(s.bytes, kHeaderBytesAt))
            << config << ": flip at " << at << " not detected";
      } else {
        EXPECT_NE(msg.find(bad), std::string::npos) << msg;
      }
    }
    std::filesystem::remove(bad);
    std::filesystem::remove(s.path);
  }
}

TEST(SceneFile, ByteFlipsWithoutChecksumsNeverCrash) {
  // Header and table flips: always an error (the header checksum is always verified). Section
  // flips: the structure check turns bad references into errors, the rest traces.
  for (const std::string config :
       {"bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "clbvh-tri4i", "clbvh-compact", "bvh8-pairs"}) {
    Small s = small_file(config, "flip_nc");
    const std::string bad = temp_path("flip_nc_bad");
    const size_t hb = get64(s.bytes, kHeaderBytesAt);
    OpenOptions oo;
    oo.verify_checksums = false;
    oo.check_structure = true;
    EXPECT_EQ(try_open(bad, s.bytes, oo, s.rays), "") << config;
    Rng rng(23);
    int errors = 0;
    for (int i = 0; i < 600; ++i) {
      std::string b = s.bytes;
      const bool header = i % 4 == 0;
      const size_t at = header
                            ? size_t(rng.uniform() * float(hb)) % hb
                            : hb + size_t(rng.uniform() * float(b.size() - hb)) % (b.size() - hb);
      b[at] = char(b[at] ^ (1 + int(rng.uniform() * 254.0f)));
      const std::string msg = try_open(bad, b, oo, s.rays);
      if (header) {
        EXPECT_FALSE(msg.empty()) << config << ": header flip at " << at << " opened";
      }
      if (!msg.empty()) {
        ++errors;
        EXPECT_NE(msg.find(bad), std::string::npos) << msg;
      }
    }
    EXPECT_GT(errors, 150) << config;
    std::filesystem::remove(bad);
    std::filesystem::remove(s.path);
  }
}

TEST(SceneFile, StructureCheckNamesSectionAndOffset) {
  Small s = small_file("bvh8-tri4i", "struct");
  const std::string bad = temp_path("struct_bad");
  // The vertex indices of the first leaf block point past the vertex array.
  std::string b = s.bytes;
  uint64_t leaves = 0;
  for (uint32_t k = 0; k < section_count(b); ++k)
    if (std::string(b.data() + entry(k)) == "bvh.leaves") leaves = get64(b, entry(k) + 48);
  ASSERT_GT(leaves, 0u);
  std::memset(b.data() + leaves, 0xff, 4);
  OpenOptions oo;
  oo.verify_checksums = false;
  oo.check_structure = true;
  const std::string msg = try_open(bad, b, oo, s.rays);
  EXPECT_NE(msg.find("section 'bvh.leaves'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("offset " + std::to_string(leaves)), std::string::npos) << msg;
  EXPECT_NE(msg.find("vertex index"), std::string::npos) << msg;
  // With checksums: the checksum of that section.
  const std::string msg2 = try_open(bad, b, {}, s.rays);
  EXPECT_NE(msg2.find("section 'bvh.leaves'"), std::string::npos) << msg2;
  EXPECT_NE(msg2.find("checksum"), std::string::npos) << msg2;
  // Pairs: an order field beyond the 3 corners of a triangle (corner() would index past the
  // block's vertices; found by fuzz_scene_file).
  Small pr = small_file("bvh8-pairs", "struct_pairs");
  std::string pb = pr.bytes;
  uint64_t pleaves = 0;
  for (uint32_t k = 0; k < section_count(pb); ++k)
    if (std::string(pb.data() + entry(k)) == "bvh.leaves") pleaves = get64(pb, entry(k) + 48);
  ASSERT_GT(pleaves, 0u);
  pb[pleaves + 240] = char(0xff);  // PairBlock<4>::order[0] (192 + 32 + 16 bytes in)
  const std::string msg4 = try_open(bad, pb, oo, pr.rays);
  EXPECT_NE(msg4.find("pair corner order"), std::string::npos) << msg4;
  std::filesystem::remove(pr.path);
  // A format the check does not cover says so.
  Small g = small_file("lossy-grid", "struct_grid");
  const std::string msg3 = try_open(bad, g.bytes, oo, g.rays);
  EXPECT_NE(msg3.find("not available"), std::string::npos) << msg3;
  std::filesystem::remove(bad);
  std::filesystem::remove(s.path);
  std::filesystem::remove(g.path);
}

TEST(SceneFile, HeaderErrorsAreClear) {
  Small s = small_file("bvh8-tri4v", "hdr");
  const std::string bad = temp_path("hdr_bad");
  auto open_msg = [&](std::string b, bool fix) {
    if (fix) fix_header_checksum(b);
    return try_open(bad, b, {}, s.rays);
  };
  std::string b = s.bytes;
  b[0] = 'X';
  EXPECT_NE(open_msg(b, false).find("wrong magic"), std::string::npos);
  b = s.bytes;
  b[8] = 99;  // version
  EXPECT_NE(open_msg(b, false).find("format version 99"), std::string::npos);
  b = s.bytes;
  std::swap(b[12], b[15]);  // byte-order mark 0x01020304 read the other way round
  std::swap(b[13], b[14]);
  EXPECT_NE(open_msg(b, false).find("other byte order"), std::string::npos);
  b = s.bytes;
  std::memcpy(b.data() + 56, "avx9000\0", 8);  // instruction set
  EXPECT_NE(open_msg(b, true).find("avx9000 instruction set, which this CPU lacks"),
            std::string::npos);
  b = s.bytes;
  b[100] = char(b[100] ^ 1);  // a flip in the header (the configuration name)
  EXPECT_NE(open_msg(b, false).find("header checksum mismatch"), std::string::npos);
  // Table: a section past the end, a misaligned one, an overlap, a size not a multiple of its
  // element size, a missing section.
  const uint32_t n = section_count(s.bytes);
  ASSERT_GE(n, 3u);
  b = s.bytes;
  put64(b, entry(n - 1) + 56, get64(b, entry(n - 1) + 56) + 64);
  std::string m = open_msg(b, true);
  EXPECT_NE(m.find("runs past the end of the file"), std::string::npos) << m;
  EXPECT_NE(m.find("section '"), std::string::npos) << m;
  b = s.bytes;
  put64(b, entry(1) + 48, get64(b, entry(1) + 48) + 8);
  m = open_msg(b, true);
  EXPECT_NE(m.find("not 64-byte aligned"), std::string::npos) << m;
  b = s.bytes;
  put64(b, entry(1) + 48, get64(b, entry(0) + 48));
  m = open_msg(b, true);
  EXPECT_NE(m.find("overlaps"), std::string::npos) << m;
  b = s.bytes;
  uint32_t elem = 0x7fffffff;  // divides no size of this small file
  for (uint32_t k = 0; k < n; ++k)
    if (std::string(b.data() + entry(k)) == "bvh.nodes")
      std::memcpy(b.data() + entry(k) + 72, &elem, 4);
  m = open_msg(b, true);
  EXPECT_NE(m.find("not a multiple of its element size"), std::string::npos) << m;
  b = s.bytes;
  for (uint32_t k = 0; k < n; ++k)
    if (std::string(b.data() + entry(k)) == "bvh.expected") b[entry(k)] = 'X';
  m = open_msg(b, true);
  EXPECT_NE(m.find("section 'bvh.expected', offset"), std::string::npos) << m;
  EXPECT_NE(m.find("missing"), std::string::npos) << m;
  // Not a file at all.
  EXPECT_THROW(Scene::open(bad + ".does-not-exist"), Error);
  std::filesystem::remove(bad);
  std::filesystem::remove(s.path);
}

TEST(SceneFile, SaveIsAtomicAndRefusesUnbuiltScenes) {
  Scene empty;
  EXPECT_THROW(empty.save(temp_path("unbuilt")), Error);
  EXPECT_FALSE(std::filesystem::exists(temp_path("unbuilt")));
  EXPECT_THROW(Scene::build(make_terrain(4, 1)).save("/nonexistent-dir/x.slim"), Error);
}

// Scene::save of an opened scene (its arrays are views of the mapping) writes the file it was
// opened from, byte for byte: every configuration and a joined scene.
TEST(SceneFile, SavingAnOpenedSceneWritesTheSameBytes) {
  std::vector<PolyMesh> meshes{test_mesh()};
  PolyMesh s2 = test::random_soup(300, 5, 0.2f);
  for (Vec3f& p : s2.positions) p = p * 20.0f;
  meshes.push_back(s2);
  const std::string a = temp_path("resave_a"), b = temp_path("resave_b");
  auto check = [&](const Scene& built, const std::string& what) {
    built.save(a);
    for (int mode = 0; mode < 2; ++mode) {
      OpenOptions oo;
      oo.verify_checksums = mode == 0;
      Scene::open(a, oo).save(b);
      const std::string x = read_all(a), y = read_all(b);
      EXPECT_EQ(x.size(), y.size()) << what;
      EXPECT_TRUE(x == y) << what << ": the re-saved file differs";
    }
  };
  int tested = 0;
  for (const std::string& name : all_config_names()) {
    Scene built;
    try {
      built = Scene::build(meshes, BuildOptions::from_config(name));
    } catch (const NotApplicable&) {
      continue;
    }
    check(built, name);
    ++tested;
  }
  EXPECT_EQ(tested, int(all_config_names().size()));
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = 4096;
  const Scene joined =
      Scene::build_chunked("torus:128", BuildOptions::from_config("lossy-grid-shared"), chunking);
  double chunks = 0;
  for (const auto& [key, value] : joined.stats().details)
    if (key == "chunks") chunks = value;
  EXPECT_GE(chunks, 2) << "torus:128 in chunks of at most 4096 triangles";
  check(joined, "joined lossy-grid-shared");
  std::filesystem::remove(a);
  std::filesystem::remove(b);
}

}  // namespace
}  // namespace slim
