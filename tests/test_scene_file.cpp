// Scene files (Scene::save / Scene::open, src/api/scene_file.cpp): every configuration round-trips
// with identical hits and figures; damaged files give a slim::Error naming file, section and
// offset, never a crash.
#include <gtest/gtest.h>
#include <unistd.h>
#include <xxhash.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <string>
#include <vector>

#include "bvh/bvh8.h"
#include "prim/cluster.h"
#include "prim/costa_leaf.h"
#include "prim/lossy_subgrid.h"
#include "prim/subgrid.h"
#include "prim/triangles.h"
#include "slimrt/analysis.h"
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
  const StatDetails &da = stat_details(a), &db = stat_details(b);
  ASSERT_EQ(da.size(), db.size()) << what;
  for (size_t i = 0; i < da.size(); ++i) {
    EXPECT_EQ(da[i].first, db[i].first) << what;
    EXPECT_EQ(std::memcmp(&da[i].second, &db[i].second, 8), 0) << what;
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
  std::filesystem::remove(bad);
  std::filesystem::remove(s.path);
}

// ---- the structure check of every configuration ------------------------------------------------

// The meshes of the structure check's tests: a terrain (grids) and a few loose triangles (the
// grid formats' leftover triangles, geomID 1).
std::vector<PolyMesh> check_meshes(int n) {
  std::vector<PolyMesh> m{make_terrain(n, 2)};
  PolyMesh soup = test::random_soup(40, 7, 0.3f);
  for (Vec3f& p : soup.positions) p = p * float(n);
  m.push_back(soup);
  return m;
}

struct SectionInfo {
  std::string name;
  uint64_t offset, size;
};
std::vector<SectionInfo> sections_of(const std::string& b) {
  std::vector<SectionInfo> v;
  for (uint32_t k = 0; k < section_count(b); ++k)
    v.push_back(
        {std::string(b.data() + entry(k)), get64(b, entry(k) + 48), get64(b, entry(k) + 56)});
  return v;
}
SectionInfo section(const std::string& b, const std::string& name) {
  for (const SectionInfo& s : sections_of(b))
    if (s.name == name) return s;
  ADD_FAILURE() << "no section " << name;
  return {name, 0, 0};
}

OpenOptions structure_check() {
  OpenOptions oo;
  oo.verify_checksums = false;
  oo.check_structure = true;
  return oo;
}

// Scenes joined from chunk scenes of a few formats (Scene::build_chunked).
Scene joined_scene(const std::string& config, uint64_t max_chunk_triangles) {
  ChunkedBuildOptions chunking;
  chunking.max_chunk_triangles = max_chunk_triangles;
  return Scene::build_chunked("terrain:12", BuildOptions::from_config(config), chunking);
}
const char* const kJoinedConfigs[] = {"bvh8-tri4i", "lossy-grid-shared", "costa-PFV", "cluster"};

TEST(SceneFile, StructureCheckPassesEveryConfiguration) {
  const std::vector<PolyMesh> meshes = check_meshes(20);
  const std::string path = temp_path("check_all");
  int tested = 0;
  auto check = [&](const Scene& built, const std::string& what) {
    built.save(path);
    const Scene opened = Scene::open(path, structure_check());
    expect_same_hits(built, opened, test_rays(built.bounds(), 2000, 5), what);
    OpenOptions both;
    both.check_structure = true;
    EXPECT_NO_THROW((void)Scene::open(path, both)) << what;
    ++tested;
  };
  for (const std::string& name : all_config_names()) {
    SCOPED_TRACE(name);
    check(Scene::build(meshes, BuildOptions::from_config(name)), name);
  }
  EXPECT_EQ(tested, int(all_config_names().size()));
  for (const char* config : kJoinedConfigs)
    check(joined_scene(config, 64), "joined " + std::string(config));
  // The clusters' trees over kFloatNodePrims triangles or more: Node8 at the top, CQNode8 below.
  for (const char* config : {"cluster", "cluster-lossless"}) {
    const Scene s = Scene::build(load("torus:128"), BuildOptions::from_config(config));
    EXPECT_GT(test::detail_value(s, "node8_count"), 0) << config;
    check(s, std::string(config) + " over torus:128");
  }
  std::filesystem::remove(path);
}

// Flips `count` bytes at random positions of each section (and of the header, which its checksum
// guards) of a file, opens each with the structure check and without the checksums, and traces
// rays through what opens. Returns the opens that failed, and the flips tried.
std::pair<int, int> flip_sections(const Scene& built, const std::string& what,
                                  const std::string& tag, int count, uint32_t seed) {
  const std::string path = temp_path(tag), bad = temp_path(tag + "_bad");
  built.save(path);
  const std::string bytes = read_all(path);
  const std::vector<Ray> rays = test_rays(built.bounds(), 48, seed);
  const OpenOptions oo = structure_check();
  EXPECT_EQ(try_open(bad, bytes, oo, rays), "") << what;
  Rng rng(seed);
  int errors = 0, tried = 0;
  std::vector<SectionInfo> secs = sections_of(bytes);
  secs.push_back({"(header)", 0, get64(bytes, kHeaderBytesAt)});
  for (const SectionInfo& sec : secs) {
    if (sec.size == 0) continue;
    for (int i = 0; i < count; ++i) {
      std::string b = bytes;
      const uint64_t at = sec.offset + uint64_t(rng.uniform() * float(sec.size)) % sec.size;
      b[at] = char(b[at] ^ (1 + int(rng.uniform() * 254.0f)));
      const std::string msg = try_open(bad, b, oo, rays);
      ++tried;
      if (sec.name == "(header)") {
        EXPECT_FALSE(msg.empty()) << what << ": header flip at " << at << " opened";
      }
      if (!msg.empty()) {
        ++errors;
        EXPECT_NE(msg.find(bad), std::string::npos) << msg;
        EXPECT_NE(msg.find("offset"), std::string::npos) << msg;
      }
    }
  }
  std::filesystem::remove(path);
  std::filesystem::remove(bad);
  return {errors, tried};
}

TEST(SceneFile, SectionByteFlipsWithStructureCheckNeverCrash) {
  const std::vector<PolyMesh> meshes = check_meshes(6);
  uint32_t seed = 100;
  for (const std::string& name : all_config_names()) {
    SCOPED_TRACE(name);
    const auto [errors, tried] = flip_sections(
        Scene::build(meshes, BuildOptions::from_config(name)), name, "flipsec", 24, seed++);
    EXPECT_GT(errors, 0) << name << ": none of " << tried << " flips refused";
  }
  for (const char* config : kJoinedConfigs) {
    SCOPED_TRACE(config);
    const auto [errors, tried] = flip_sections(
        joined_scene(config, 96), std::string("joined ") + config, "flipsec_j", 6, seed++);
    EXPECT_GT(errors, 0) << config << ": none of " << tried << " flips refused";
  }
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
  for (const auto& [key, value] : stat_details(joined))
    if (key == "chunks") chunks = value;
  EXPECT_GE(chunks, 2) << "torus:128 in chunks of at most 4096 triangles";
  check(joined, "joined lossy-grid-shared");
  std::filesystem::remove(a);
  std::filesystem::remove(b);
}

// The first leaf reference of the BVH under `prefix` in a scene file's bytes, found from the root
// through the first used child of each node; 0 if the root is empty.
uint64_t first_leaf(const std::string& b, const std::string& prefix) {
  const SectionInfo meta = section(b, prefix + "bvh.meta"),
                    nodes = section(b, prefix + "bvh.nodes");
  uint64_t ref = get64(b, meta.offset);  // BvhMeta::root
  while (is_node_tag(NodeRef::tag(ref))) {
    uint64_t child[8];
    child_refs(ref,
               reinterpret_cast<const uint8_t*>(b.data()) + nodes.offset + NodeRef::offset(ref),
               child);
    uint64_t next = 0;
    for (int i = 0; i < 8 && next == 0; ++i) next = child[i];
    ref = next;
  }
  return ref;
}
// The file offset of the first block of that leaf (behind the header of a multi-leaf: a MultiLeaf8,
// or the lossy clusters' boxes).
uint64_t first_block(const std::string& b, const std::string& prefix,
                     uint64_t multileaf_header_bytes = sizeof(MultiLeaf8)) {
  const uint64_t ref = first_leaf(b, prefix);
  EXPECT_TRUE(NodeRef::tag(ref) == kRefLeaf || NodeRef::tag(ref) == kRefMulti);
  return section(b, prefix + "bvh.leaves").offset + NodeRef::offset(ref) +
         (NodeRef::tag(ref) == kRefMulti ? multileaf_header_bytes : 0);
}
void put32(std::string& s, uint64_t at, uint32_t v) { std::memcpy(s.data() + at, &v, 4); }
// A child reference of the first node of the BVH under `prefix` (its root), to `ref`.
void set_root_child(std::string& b, const std::string& prefix, uint64_t ref) {
  const uint64_t root = get64(b, section(b, prefix + "bvh.meta").offset);
  ASSERT_TRUE(NodeRef::tag(root) == kRefNode8 || NodeRef::tag(root) == kRefQNode8);
  const uint64_t child =
      section(b, prefix + "bvh.nodes").offset + NodeRef::offset(root) +
      (NodeRef::tag(root) == kRefNode8 ? offsetof(Node8, child) : offsetof(QNode8, child));
  put64(b, child, ref);
}
// The root of the BVH under `prefix`, a CQNode8: its file offset.
uint64_t cq_root(const std::string& b, const std::string& prefix) {
  const uint64_t root = get64(b, section(b, prefix + "bvh.meta").offset);
  EXPECT_EQ(NodeRef::tag(root), kRefCQNode8);
  return section(b, prefix + "bvh.nodes").offset + NodeRef::offset(root);
}

// The clusters' multi-leaf boxes (cluster::LatticeBoxes8, cluster::ExactBoxes8: the planes come
// first in both, 6 or 8 bytes a plane, child 0's value in the first byte's low bits): a child box
// shrunk to a point (lossy: to its 3 lowest fine planes) is caught. Lossless: any 8-bit plane is
// safe to read, so it passes the structure check but not validate(), which decodes every child box
// as the traversal does and checks that it contains the child's triangles. Lossy clusters with
// per-child vertex ranges take the ranges from the planes: the vertex section's length changes with
// them, so the structure check (here: the strips no longer parse) or else validate() rejects the
// file.
class ClusterBoxShrunk : public ::testing::TestWithParam<const char*> {};
TEST_P(ClusterBoxShrunk, IsCaughtByValidate) {
  static_assert(offsetof(cluster::LatticeBoxes8, c) == 0 && offsetof(cluster::ExactBoxes8, q) == 0,
                "the planes come first");
  const int plane_bytes = std::string(GetParam()) == "cluster" ? cluster::kCoarsePlaneBits : 8;
  const std::string path = temp_path("clbox"), bad = temp_path("clbox_bad");
  const Scene built = Scene::build(load("torus:64"), BuildOptions::from_config(GetParam()));
  std::string why;
  ASSERT_TRUE(built.validate(&why)) << why;
  built.save(path);
  std::string b = read_all(path);
  const uint64_t ref = first_leaf(b, "");
  ASSERT_EQ(NodeRef::tag(ref), kRefMulti);
  const uint64_t at = section(b, "bvh.leaves").offset + NodeRef::offset(ref);
  for (int p = 0; p < 6; ++p) b[at + plane_bytes * p] = 0;
  write_all(bad, b);
  OpenOptions oo;
  oo.verify_checksums = false;
  oo.check_structure = true;
  try {
    const Scene s = Scene::open(bad, oo);
    EXPECT_FALSE(s.validate(&why));
    EXPECT_NE(why.find("primitive outside the box of its leaf"), std::string::npos) << why;
  } catch (const Error& e) {
    EXPECT_EQ(std::string(GetParam()), "cluster") << e.what();  // lossless: validate() only
    EXPECT_NE(std::string(e.what()).find("bvh.leaves"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("cluster:"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
  std::filesystem::remove(bad);
}
INSTANTIATE_TEST_SUITE_P(SceneFile, ClusterBoxShrunk,
                         ::testing::Values("cluster", "cluster-lossless"));

// For each format, one reference set out of range: the structure check names the section, the
// offset and what is wrong, where the checksums are off.
TEST(SceneFile, StructureCheckCatchesEachFormatsBadReferences) {
  const std::vector<PolyMesh> meshes = check_meshes(10);
  const std::string path = temp_path("badref"), bad = temp_path("badref_bad");
  struct Case {
    std::string config;
    std::string what;  // what the corruption does
    std::function<void(std::string&)> corrupt;
    std::string section, message;  // expected in the error
    int64_t field = -1;            // if >= 0: the offset in the section the error names
  };
  auto far_node = [](RefTag tag) {
    return [tag](std::string& b) {
      set_root_child(b, "", NodeRef::make(tag, (section(b, "bvh.nodes").size + 1024) & ~63ull));
    };
  };
  // The root CQNode8's second child: its first child (a multi-leaf) with `fewer` children less.
  auto root_multileaf_twice = [](uint32_t fewer) {
    return [fewer](std::string& b) {
      const uint64_t at = cq_root(b, "") + offsetof(CQNode8, child);
      uint32_t c0;
      std::memcpy(&c0, b.data() + at, 4);
      ASSERT_EQ(NodeRef::tag(c0), kRefMulti);
      ASSERT_GT(NodeRef::blocks(c0), fewer);
      put32(b, at + 4, c0 - (fewer << 3));  // the block count's field (bits 3..7)
    };
  };
  auto block_field = [](uint64_t field, uint32_t value) {
    return [field, value](std::string& b) { put32(b, first_block(b, "") + field, value); };
  };
  auto every = [](const std::string& name, uint64_t elem, uint64_t field, uint32_t value) {
    return [=](std::string& b) {
      const SectionInfo t = section(b, name);
      for (uint64_t at = 0; at + elem <= t.size; at += elem) put32(b, t.offset + at + field, value);
    };
  };
  const std::vector<Case> cases = {
      {"bvh8-tri4v", "Node8 child beyond the node arena", far_node(kRefNode8), "bvh.nodes",
       "node outside the node arena"},
      {"qbvh8-tri4v", "QNode8 child beyond the node arena", far_node(kRefQNode8), "bvh.nodes",
       "node outside the node arena"},
      {"clbvh-tri4v", "multi-leaf beyond the leaf arena",
       [](std::string& b) {
         set_root_child(b, "",
                        NodeRef::make(kRefMulti, (section(b, "bvh.leaves").size + 64) & ~63ull, 2));
       },
       "bvh.leaves", "multi-leaf outside the leaf arena"},
      {"bvh8-tri4v", "leaf of too many blocks",
       [](std::string& b) {
         set_root_child(b, "", NodeRef::make(kRefLeaf, section(b, "bvh.leaves").size & ~3ull, 1));
       },
       "bvh.leaves", "leaf block outside the arena"},
      {"bvh8-tri4i", "vertex index", block_field(offsetof(Tri4iBlock, v), 0xffffffffu),
       "bvh.leaves", "vertex index beyond the vertex array"},
      {"clbvh-compact", "vertex dictionary entry",
       [](std::string& b) {
         const uint64_t ref = first_leaf(b, "");
         const uint64_t at = section(b, "bvh.leaves").offset + NodeRef::offset(ref);
         if (NodeRef::tag(ref) == kRefMulti)  // the dictionary behind the k blocks
           put32(b, at + 72 + NodeRef::blocks(ref) * sizeof(Tri4iCompactBlock), 0xffffffffu);
         else
           put32(b, at, 0xffffffffu);
       },
       "bvh.leaves", "vertex index beyond the vertex array"},
      {"bvh8-pairs", "pair corner order", block_field(240, 0xffffffffu), "bvh.leaves",
       "pair corner order"},
      {"grid", "sub-grid vertex", block_field(offsetof(SubGridRef, vertex), 0xfffffff0u),
       "bvh.leaves", "grid.vertices"},
      {"grid", "sub-grid's grid", block_field(offsetof(SubGridRef, grid), 0xfffffff0u),
       "bvh.leaves", "grid index beyond the grid tables"},
      {"grid", "flip masks of every grid",
       every("grid.hot", sizeof(GridHot), offsetof(GridHot, flips), 0x7fffffffu), "bvh.leaves",
       "grid.flips"},
      {"lossy-grid", "sub-grid's grid",
       block_field(offsetof(LossySubGrid, primitive_id), 0xfffffff0u), "bvh.leaves",
       "grid index beyond the grid tables"},
      {"lossy-grid-e2", "sub-grid resolution",
       block_field(offsetof(LossySubGrid, res) - 3, 0xff000000u), "bvh.leaves", "resolution"},
      {"lossy-grid-qbvh8", "face tables of every grid",
       [](std::string& b) {
         const SectionInfo t = section(b, "grid.table");
         for (uint64_t at = 0; at + sizeof(GridInfo) <= t.size; at += sizeof(GridInfo)) {
           put32(b, t.offset + at + offsetof(GridInfo, flags), kGridFaceTable);
           put32(b, t.offset + at + offsetof(GridInfo, face0), 0x7fffffffu);
         }
       },
       "bvh.leaves", "grid.faces"},
      {"lossy-grid-qbvh8", "exact vertices of every grid",
       [](std::string& b) {
         // Every displacement code of the first block an escape, past the grid's exact vertices.
         const uint64_t at = first_block(b, "") + offsetof(LossySubGrid, displ);
         for (int k = 0; k < 21; ++k) {
           const uint32_t c = escape_code(kMaxExactIndex);
           b[at + 3 * k] = char(c), b[at + 3 * k + 1] = char(c >> 8),
                      b[at + 3 * k + 2] = char(c >> 16);
         }
       },
       "bvh.leaves", "grid.exact"},
      {"lossy-grid-shared", "lattice corner",
       block_field(offsetof(LossySubGridShared, corner), 0xfffffff0u), "bvh.leaves",
       "corner chunk table"},
      {"lossy-grid-shared", "corner chunk table", every("grid.corner_grid", 4, 0, 0x7fffffffu),
       "bvh.leaves", "grid.corner_grid"},
      {"lossy-grid-shared", "grid count",
       [](std::string& b) { put32(b, section(b, "grid.params").offset, 0x7fffffffu); },
       "grid.params", "grid count"},
      {"lossy-grid", "sub-grid parts",
       [](std::string& b) { put32(b, section(b, "grid.params").offset + 8, 3); }, "grid.params",
       "sub-grid parts"},
      {"grid", "leftover triangles' node child",
       [](std::string& b) {
         set_root_child(
             b, "tris.",
             NodeRef::make(kRefNode8, (section(b, "tris.bvh.nodes").size + 1024) & ~63ull));
       },
       "tris.bvh.nodes", "node outside the node arena"},
      {"cluster", "CQNode8 child beyond the node arena",
       [](std::string& b) {
         put32(b, cq_root(b, "") + offsetof(CQNode8, child), (0xfffff0u << 8) | kRefCQNode8);
       },
       "bvh.nodes", "node outside the node arena"},
      {"cluster", "CQNode8 child at a misaligned offset",
       [](std::string& b) {
         put32(b, cq_root(b, "") + offsetof(CQNode8, child),
               (sizeof(CQNode8) + 1) << 8 | kRefCQNode8);
       },
       "bvh.nodes", "misaligned node"},
      {"cluster", "CQNode8 child naming its own node",
       [](std::string& b) { put32(b, cq_root(b, "") + offsetof(CQNode8, child), kRefCQNode8); },
       "bvh.nodes", "node referenced twice"},
      // A multi-leaf named by two children of the root: with its own child count (the traversal
      // would take the same cluster twice) and with one child fewer (two counts for one cluster:
      // the cluster check accepts each count on its own, and the decode cache keeps one count's
      // view).
      {"cluster", "multi-leaf referenced twice", root_multileaf_twice(0), "bvh.leaves",
       "multi-leaf referenced twice"},
      {"cluster-lossless", "multi-leaf referenced twice with another child count",
       root_multileaf_twice(1), "bvh.leaves", "multi-leaf referenced twice"},
      {"bvh8-tri4v", "leaf referenced twice",
       [](std::string& b) {  // the first node whose first child is a leaf: its second child too
         const uint64_t nodes = section(b, "bvh.nodes").offset;
         uint64_t ref = get64(b, section(b, "bvh.meta").offset);
         ASSERT_EQ(NodeRef::tag(ref), kRefNode8);
         uint64_t at = nodes + NodeRef::offset(ref) + offsetof(Node8, child);
         while (NodeRef::tag(get64(b, at)) == kRefNode8)
           at = nodes + NodeRef::offset(get64(b, at)) + offsetof(Node8, child);
         ASSERT_EQ(NodeRef::tag(get64(b, at)), kRefLeaf);
         put64(b, at + 8, get64(b, at));
       },
       "bvh.leaves", "leaf referenced twice"},
      {"cluster-lossless", "CQNode8 leaf base beyond the leaf arena",
       [](std::string& b) { put32(b, cq_root(b, "") + offsetof(CQNode8, leaf_base), 0x7fffffffu); },
       "bvh.leaves", "outside the leaf arena"},
      {"cluster", "cluster header",
       [](std::string& b) { put32(b, first_block(b, "", sizeof(cluster::LatticeBoxes8)), 0); },
       "bvh.leaves", "cluster"},
      {"cluster", "multi-leaf box scale",
       [](std::string& b) {
         const uint64_t ref = first_leaf(b, "");
         ASSERT_EQ(NodeRef::tag(ref), kRefMulti);
         b[section(b, "bvh.leaves").offset + NodeRef::offset(ref) +
           offsetof(cluster::LatticeBoxes8, scale) + 1] = char(0xff);
       },
       "bvh.leaves", "multi-leaf box scale exponent 31 beyond 24"},
      {"cluster-lossless", "cluster header",
       [](std::string& b) { put32(b, first_block(b, "", sizeof(cluster::ExactBoxes8)), 0); },
       "bvh.leaves", "cluster"},
      {"cluster-lossless", "multi-leaf box extent",
       [](std::string& b) {
         const uint64_t ref = first_leaf(b, "");
         ASSERT_EQ(NodeRef::tag(ref), kRefMulti);
         const uint64_t at = section(b, "bvh.leaves").offset + NodeRef::offset(ref) +
                             offsetof(cluster::ExactBoxes8, extent) + 2;
         b[at] = char(0x80);  // bfloat16 0xff80: -inf
         b[at + 1] = char(0xff);
       },
       "bvh.leaves", "multi-leaf box extent 65408 (bfloat16 bits) not a positive normal float"},
      {"costa", "primitive range", block_field(offsetof(CostaBlock, first), 0xfffffff0u),
       "bvh.leaves", "primitive range beyond the store"},
      {"costa-PFV", "primitive count", block_field(offsetof(CostaBlock, count), 9), "bvh.leaves",
       "primitive count"},
      {"costa", "face entries", every("costa.faces", 4, 0, 0x7ffffff0u), "costa.faces",
       "face entry names a vertex beyond the vertex array"},
      {"costa", "second primitive offset",
       [](std::string& b) { put32(b, section(b, "costa.offsets").offset + 4, 1); }, "costa.offsets",
       "primitive of fewer than 3 face entries"},
      // decoded_triangles reads from the first offset on, also where no block names a primitive.
      {"costa", "first primitive offset",
       [](std::string& b) { put32(b, section(b, "costa.offsets").offset, 0x40000000u); },
       "costa.offsets", "first primitive offset not 0"},
      {"costa-P", "offset predictor",
       [](std::string& b) {
         put64(b, section(b, "costa.params").offset + offsetof(CostaParams, residual_min),
               uint64_t(1) << 61);
       },
       "costa.params", "offset predictor out of range", offsetof(CostaParams, residual_min)},
      {"costa-F", "packed face entries", every("costa.packed_faces", 4, 0, 0xffffffffu),
       "costa.packed_faces", "face entry"},
      // Entries of 0 bits would cost no bytes: a face range beyond any bound the file sets.
      {"costa-F", "packed face width 0",
       [](std::string& b) {
         put32(b, section(b, "costa.params").offset + offsetof(CostaParams, face_bits), 0);
       },
       "costa.params", "face entry width outside 1..32 bits", offsetof(CostaParams, face_bits)},
      {"costa-PFV", "face map",
       [](std::string& b) {
         put32(b, section(b, "costa.params").offset + offsetof(CostaParams, face_width), 40);
       },
       "costa.params", "face map width", offsetof(CostaParams, face_width)},
      {"costa-PF", "primitive count",
       [](std::string& b) {
         put32(b, section(b, "costa.params").offset + offsetof(CostaParams, prim_count),
               0x7fffffffu);
       },
       "costa.params", "primitive count beyond what the leaf blocks can hold",
       offsetof(CostaParams, prim_count)},
      // The lossy lattice's steps: (8 + m) 2^e / 8, m < 8 (box_extent's products exact).
      {"cluster", "lattice step",
       [](std::string& b) {
         put32(b, section(b, "cluster.lattice").offset + offsetof(ClusterLattice, step) + 4,
               0x3f800001u);
       },
       "cluster.lattice", "lattice step", offsetof(ClusterLattice, step) + 4},
      // A step with a mantissa on an axis of 21-bit codes: float(q) x step would round.
      {"cluster", "lattice step 1.375 with 21-bit codes",
       [](std::string& b) {
         const uint64_t lat = section(b, "cluster.lattice").offset;
         put32(b, lat + offsetof(ClusterLattice, step), 0x3fb00000u);  // 1.375f
         b[lat + offsetof(ClusterLattice, anchor_bits)] = 21;
       },
       "cluster.lattice", "beyond 20 bits with a step that is not a power of two",
       offsetof(ClusterLattice, anchor_bits)},
      // A power of two so large that the multi-leaves' scales would overflow its exponent.
      {"cluster", "lattice step 2^127",
       [](std::string& b) {
         put32(b, section(b, "cluster.lattice").offset + offsetof(ClusterLattice, step),
               0x7f000000u);
       },
       "cluster.lattice", "is not (8 + m) 2^e / 8 (m < 8) in [2^-126, 2^102]",
       offsetof(ClusterLattice, step)},
  };
  int checked = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.config + ": " + c.what);
    const Scene built = Scene::build(meshes, BuildOptions::from_config(c.config));
    built.save(path);
    std::string b = read_all(path);
    const std::vector<Ray> rays = test_rays(built.bounds(), 32, 9);
    ASSERT_EQ(try_open(bad, b, structure_check(), rays), "");
    c.corrupt(b);
    ASSERT_NE(b, read_all(path)) << "nothing corrupted";
    const std::string msg = try_open(bad, b, structure_check(), rays);
    EXPECT_NE(msg.find(bad), std::string::npos) << msg;
    EXPECT_NE(msg.find("section '" + c.section + "', offset"), std::string::npos) << msg;
    EXPECT_NE(msg.find(c.message), std::string::npos) << msg;
    if (c.field >= 0) {
      const uint64_t at = section(read_all(path), c.section).offset + uint64_t(c.field);
      EXPECT_NE(msg.find("offset " + std::to_string(at) + ":"), std::string::npos) << msg;
    }
    // Without the structure check, the section checksums catch the same bytes.
    EXPECT_NE(try_open(bad, b, {}, rays).find("checksum"), std::string::npos);
    ++checked;
  }
  EXPECT_EQ(checked, int(cases.size()));
  // A chunk of a joined scene: the section under the chunk's prefix.
  const Scene joined = joined_scene("lossy-grid-shared", 96);
  joined.save(path);
  std::string b = read_all(path);
  put32(b, first_block(b, "c0.") + offsetof(LossySubGridShared, corner), 0xfffffff0u);
  const std::string msg = try_open(bad, b, structure_check(), {});
  EXPECT_NE(msg.find("section 'c0.bvh.leaves', offset"), std::string::npos) << msg;
  std::filesystem::remove(path);
  std::filesystem::remove(bad);
}

// Scenes without triangles (a mesh of vertices only) of every configuration open with the
// structure check, and decode no triangles.
TEST(SceneFile, EmptyScenesPassTheStructureCheck) {
  PolyMesh verts;
  verts.positions = {{0, 0, 0}, {1, 2, 3}};
  const std::string path = temp_path("check_empty");
  int tested = 0;
  for (const std::string& name : all_config_names()) {
    SCOPED_TRACE(name);
    Scene::build(verts, BuildOptions::from_config(name)).save(path);
    const Scene opened = Scene::open(path, structure_check());
    EXPECT_EQ(opened.stats().triangles, 0u);
    Ray r;
    r.org = {0, 0, -1};
    r.dir = {0, 0, 1};
    EXPECT_FALSE(opened.intersect(r).valid());
    if (const std::optional<DecodedTriangles> d = opened.decoded_triangles()) {
      EXPECT_TRUE(d->face.empty());
    }
    ++tested;
  }
  EXPECT_EQ(tested, int(all_config_names().size()));
  // An empty costa-F store with 0-bit face entries (as written before entries took 1+ bits).
  Scene::build(verts, BuildOptions::from_config("costa-F")).save(path);
  std::string b = read_all(path);
  put32(b, section(b, "costa.params").offset + 44, 0);
  EXPECT_EQ(try_open(temp_path("check_empty_bad"), b, structure_check(), {}), "");
  std::filesystem::remove(temp_path("check_empty_bad"));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace slim
