// Robustness of the readers on untrusted bytes: every prefix and every single-byte
// change of one small valid file per input format, headers that claim 2^31-1 elements, and the
// inputs the fuzzers (fuzz/, ./fuzz.sh) found, kept as regression tests.
//
// tests/test_io.cpp already sweeps the prefixes of an OBJ, an ascii PLY, a little-endian PLY, a
// header-only GLB and an .obj.xz. This file completes the sweep with the files of
// fuzz/seed_files.h (the fuzzers' seeds): big-endian PLY, glTF JSON with an embedded buffer, a GLB
// with a real mesh, PLY and GLB inside .xz, and richer OBJ/PLY files.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "../fuzz/seed_files.h"
#include "io/gltf.h"
#include "io/obj.h"
#include "io/ply.h"
#include "io/xz.h"
#include "slimrt/analysis.h"
#include "temp_dir.h"

namespace fs = std::filesystem;
using slim::PolyMesh;

using slim::test::TempDir;

namespace {

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif

enum class Outcome { Loaded, Error, Other };

// What slim::load() does with a file `name` holding `bytes`, without the file (this filesystem
// takes milliseconds per write, the sweeps read tens of thousands of inputs): .xz layer, reader
// by extension, check_mesh. src/io/load.cpp is the same dispatch.
PolyMesh load_memory(const std::string& name, const std::string& bytes) {
  try {
    std::string data = bytes, stem = name;
    if (slim::detail::has_xz_suffix(name)) {
      data = slim::detail::xz_decompress(name, bytes.data(), bytes.size());
      stem.resize(stem.size() - 3);
    }
    const std::string ext = stem.substr(stem.rfind('.'));
    PolyMesh m = ext == ".obj"   ? slim::detail::read_obj(name, data)
                 : ext == ".ply" ? slim::detail::read_ply(name, data)
                                 : slim::detail::read_gltf(name, data, ext == ".glb",
                                                           "/nonexistent-slimrt-dir");
    slim::check_mesh(m);
    return m;
  } catch (const std::bad_alloc&) {
    throw slim::Error(name + ": out of memory while loading");
  }
}

// A mesh (which has passed check_mesh), or a slim::Error whose message starts with the file
// name and says something after it. Anything else is Other (and a test failure).
Outcome outcome_of(const std::string& name, const std::function<PolyMesh()>& fn,
                   PolyMesh* out = nullptr, std::string* msg = nullptr) {
  try {
    PolyMesh m = fn();
    if (out) *out = std::move(m);
    return Outcome::Loaded;
  } catch (const slim::Error& e) {
    const std::string w = e.what();
    if (msg) *msg = w;
    if (w.rfind(name, 0) != 0 || w.size() < name.size() + 8) {
      ADD_FAILURE() << "unclear error for " << name << ": " << w;
      return Outcome::Other;
    }
    return Outcome::Error;
  } catch (const std::exception& e) {
    ADD_FAILURE() << name << ": exception other than slim::Error: " << e.what();
    return Outcome::Other;
  }
}
Outcome load_outcome(const std::string& path, PolyMesh* out = nullptr, std::string* msg = nullptr) {
  return outcome_of(
      path, [&] { return slim::load(path); }, out, msg);
}
Outcome memory_outcome(const std::string& name, const std::string& bytes, PolyMesh* out = nullptr) {
  return outcome_of(
      name, [&] { return load_memory(name, bytes); }, out);
}

bool is_binary_format(const std::string& name) {
  // Formats with a length or a trailer that every prefix breaks: only the whole file loads.
  return name.find(".xz") != std::string::npos || name.find(".glb") != std::string::npos ||
         name.find(".gltf") != std::string::npos || name.find("_le.ply") != std::string::npos ||
         name.find("_be.ply") != std::string::npos;
}

}  // namespace

// ---------------------------------------------------------------- truncation sweep

TEST(RobustTruncation, EveryPrefixOfOneFilePerFormat) {
  TempDir d{"slimrt_robust"};
  for (const slim::seeds::SeedFile& f : slim::seeds::one_per_format()) {
    SCOPED_TRACE(f.name);
    PolyMesh full, mem;
    ASSERT_EQ(load_outcome(d.write(f.name, f.bytes), &full), Outcome::Loaded);
    ASSERT_GT(full.face_count(), 0u);
    ASSERT_EQ(memory_outcome(f.name, f.bytes, &mem), Outcome::Loaded);
    EXPECT_EQ(mem.face_indices, full.face_indices);
    // The empty file and a cut in the middle through slim::load itself; every prefix in memory.
    EXPECT_NE(load_outcome(d.write(f.name, "")), Outcome::Other);
    EXPECT_NE(load_outcome(d.write(f.name, f.bytes.substr(0, f.bytes.size() / 2))), Outcome::Other);
    int loaded = 0, errors = 0;
    for (size_t n = 0; n < f.bytes.size(); ++n) {
      PolyMesh m;
      const Outcome o = memory_outcome(f.name, f.bytes.substr(0, n), &m);
      ASSERT_NE(o, Outcome::Other) << "prefix of " << n << " bytes";
      if (o == Outcome::Loaded) {
        ++loaded;
        EXPECT_LE(m.face_count(), full.face_count()) << "prefix of " << n << " bytes";
      } else {
        ++errors;
      }
    }
    std::printf("  %-18s %5zu prefixes: %5d load, %5d clean errors\n", f.name.c_str(),
                f.bytes.size(), loaded, errors);
    if (is_binary_format(f.name)) {
      EXPECT_EQ(loaded, 0) << "a proper prefix loaded";
    }
  }
}

// Every byte replaced by 0x00, 0xff and a digit, one at a time: loads or fails cleanly.
TEST(RobustTruncation, EverySingleByteChangeOfOneFilePerFormat) {
  for (const slim::seeds::SeedFile& f : slim::seeds::one_per_format()) {
    SCOPED_TRACE(f.name);
    int loaded = 0, errors = 0;
    for (size_t at = 0; at < f.bytes.size(); ++at)
      for (char c : {'\0', '\xff', '9'}) {
        if (f.bytes[at] == c) continue;
        std::string s = f.bytes;
        s[at] = c;
        const Outcome o = memory_outcome(f.name, s);
        ASSERT_NE(o, Outcome::Other) << "byte " << at << " set to " << int(uint8_t(c));
        (o == Outcome::Loaded ? loaded : errors)++;
      }
    std::printf("  %-18s %5zu bytes x 3 changes: %5d load, %5d clean errors\n", f.name.c_str(),
                f.bytes.size(), loaded, errors);
  }
}

// ---------------------------------------------------------------- counts of 2^31 - 1

namespace {

constexpr const char* kHuge = "2147483647";  // 2^31 - 1

std::string ply_header(const std::string& format, const std::string& vertices,
                       const std::string& faces) {
  return "ply\nformat " + format + " 1.0\nelement vertex " + vertices +
         "\nproperty float x\nproperty float y\nproperty float z\nelement face " + faces +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

// A binary little-endian body of 3 vertices and 1 triangle (the rest the header claims is
// missing).
std::string small_binary_body() {
  slim::seeds::ByteWriter w;
  for (float v : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) w.put(v);
  w.put(uint8_t(3));
  for (int32_t i : {0, 1, 2}) w.put(i);
  return w.bytes;
}

// Runs `fn` in a child process whose address space may grow by at most 512 MiB: a reader that
// allocated what a header claims (gigabytes) fails there. Skipped under sanitizers (their shadow
// memory does not fit an address-space limit); the error messages are checked in any build.
// The child ends with _Exit (no destructors): it removes `dir` itself, the temporary directory
// its own run of the test made (a "threadsafe" death test runs the test again in the child).
[[noreturn]] void run_with_address_space_limit(const std::function<bool()>& fn,
                                               const std::string& dir) {
  long pages = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld", &pages) != 1) pages = 0;
    std::fclose(f);
  }
  const rlim_t limit = rlim_t(pages) * rlim_t(sysconf(_SC_PAGESIZE)) + (rlim_t(512) << 20);
  struct rlimit rl;
  rl.rlim_cur = rl.rlim_max = limit;
  setrlimit(RLIMIT_AS, &rl);
  const bool ok = fn();
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  std::_Exit(ok ? 0 : 1);
}

void expect_refused_without_allocating(const std::function<bool()>& fn, const TempDir& d) {
  if (kSanitized) return;
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(run_with_address_space_limit(fn, d.dir()), ::testing::ExitedWithCode(0), "");
}

}  // namespace

// Headers and accessors claiming 2^31 - 1 faces or vertices on a file of a few hundred bytes:
// a clean slim::Error naming the count, decided from the file size before any allocation (a
// header count is never trusted: counts are checked against the file size before allocating).
TEST(RobustLimits, HeaderClaimingTwoToThe31FacesIsAnErrorNotAnAllocation) {
  TempDir d{"slimrt_robust"};
  struct Case {
    std::string name, bytes, expect;
  };
  std::vector<Case> cases = {
      {"faces_le.ply", ply_header("binary_little_endian", "3", kHuge) + small_binary_body(), kHuge},
      {"verts_le.ply", ply_header("binary_little_endian", kHuge, "1") + small_binary_body(), kHuge},
      {"faces_ascii.ply", ply_header("ascii", "3", kHuge) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
       kHuge},
      {"verts_ascii.ply", ply_header("ascii", kHuge, "1") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
       kHuge},
  };
  // glTF: an index accessor of 2^31 - 1 uint32 entries in a 112-byte buffer.
  std::string gltf = slim::seeds::gltf_embedded();
  const std::string from = R"("componentType": 5123, "count": 6)";
  gltf.replace(gltf.find(from), from.size(), R"("componentType": 5123, "count": 2147483647)");
  cases.push_back({"count.gltf", gltf, "accessors[1]"});
  // GLB: a BIN chunk declaring 2^31 - 1 bytes.
  std::string glb = slim::seeds::glb_scene();
  const size_t json_len = uint8_t(glb[12]) | uint8_t(glb[13]) << 8 | uint8_t(glb[14]) << 16;
  const size_t bin_at = 20 + json_len;
  glb[bin_at] = '\xff', glb[bin_at + 1] = '\xff', glb[bin_at + 2] = '\xff',
  glb[bin_at + 3] = '\x7f';
  cases.push_back({"chunk.glb", glb, "byte"});
  // OBJ: a face using vertex 2^31 - 1.
  cases.push_back({"index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2147483647\n", ":4:"});

  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = d.write(c.name, c.bytes);
    std::string msg;
    ASSERT_EQ(load_outcome(path, nullptr, &msg), Outcome::Error);
    EXPECT_NE(msg.find(c.expect), std::string::npos) << msg;
    EXPECT_EQ(msg.find("out of memory"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("too large to hold"), std::string::npos) << msg;
    expect_refused_without_allocating(
        [path, expect = c.expect] {
          try {
            slim::load(path);
          } catch (const slim::Error& e) {
            return std::string(e.what()).find(expect) != std::string::npos &&
                   std::string(e.what()).find("out of memory") == std::string::npos;
          }
          return false;
        },
        d);
  }
}

// ---------------------------------------------------------------- fuzzer findings

namespace {

// A fuzzer input as bytes, fed to the in-memory reader of its target exactly as the target does.
struct Finding {
  const char* target;  // obj, ply, gltf, glb
  std::string bytes;
};

PolyMesh read_as(const Finding& f) {
  if (std::string(f.target) == "obj") return slim::detail::read_obj("finding.obj", f.bytes);
  if (std::string(f.target) == "ply") return slim::detail::read_ply("finding.ply", f.bytes);
  return slim::detail::read_gltf(std::string("finding.") + f.target, f.bytes,
                                 std::string(f.target) == "glb", "/nonexistent-slimrt-dir");
}

}  // namespace

// Inputs found by ./fuzz.sh. Each must give a slim::Error or a mesh that passes check_mesh.
TEST(RobustFuzzFindings, CrashingInputsStayFixed) {
  const std::vector<Finding> findings = {
      {"obj", "f 1 2 3\n"},
      // fuzz_obj, 150 s run: a 'vw' joint id beyond int range (tinyobjloader converted the float
      // to int: UBSan "inf is outside the range of representable values of type 'int'").
      {"obj", "v 0 0 0\nvw 0 111111111111111111111111111111111111111111111111 8 4\n"},
      {"obj", "v 0 0 0\nvw 0 1e300 0.5\n"},
      // fuzz_obj, CI: an exponent of 10 digits overflowed tinyobjloader's int exponent (UBSan
      // "signed integer overflow: 2147483640 + 9").
      {"obj", "v 0e2147483649 0 0\n"},
      {"obj", "v 0 0 0\nvt 1e-2147483649 0\n"},
      {"obj", "t crease 0/1/0 1e+0002147483649\n"},
      // fuzz_obj: "0e3805" is 0 to strtod but 0 * 5^3805 = NaN to tinyobjloader, whose 'vw' joint
      // id was then converted to int (UBSan "-nan is outside the range of ... 'int'").
      {"obj", "vt \nvw 1 0e3805\n\n"},
      // fuzz_obj, CI: a joint id below 2^31 as a double that tinyobjloader rounds to float 2^31
      // before converting to int (UBSan "2.14748e+09 is outside the range ... 'int'").
      {"obj", "v 0 0 0\nvw 0 2147483600 1\n"},
      {"ply",
       "ply\nformat binary_little_endian 1.0\nelement face 1\n"
       "property list uchar int vertex_indices\nend_header\n\x03"},
      // fuzz_gltf, 840 s run: an external buffer URI that decodes to "./" (a directory); seeking
      // to its end gave tinygltf 2^63 - 1 bytes to allocate (ASan: allocation-size-too-big). Only
      // the sanitizer build sees the allocation; the test below checks the refusal itself.
      {"gltf",
       "{\n  \"asset\": {\"version\": \"2.0\"},\n  \"scene\": 0,\n  \"scenes\": [{\"nodes\": [0, "
       "3]}],\n  \"nodes\": [\n    {\"nameet\": 60, \"byteLength\": 48},\n    {\"buffer\": 0, "
       "\"byteOffset\": 108, \"byteLength\": 4}\n  ],\n  \"buffers\": [{\"byteLength\": 112, "
       "\"uri\": "
       "\"%%%%%%%%%%%%%%%%%%%%%%%%%%%%%AAAA%AAAAABAAIAAAACAAMAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA/"
       "AAAAAAAAAAA=AIA/AA@AAAAAAAAAAIA/AAECAw==\"}]\n}"},
  };
  for (const Finding& f : findings) {
    try {
      slim::check_mesh(read_as(f));
    } catch (const slim::Error&) {
    } catch (const std::exception& e) {
      ADD_FAILURE() << f.target << ": exception other than slim::Error: " << e.what();
    }
  }
  // External buffers are read only from regular files: a URI naming a directory is an error
  // (before the fix: a 2^63-byte allocation, or bad_alloc turned into an unrelated error).
  {
    const std::string dir = "/";  // short: the error message is cut at 200 characters
    const std::string gltf =
        R"({"asset": {"version": "2.0"}, "buffers": [{"byteLength": 4, "uri": "."}]})";
    try {
      slim::detail::read_gltf("dir.gltf", gltf, false, dir);
      ADD_FAILURE() << "a buffer URI naming a directory was accepted";
    } catch (const slim::Error& e) {
      EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
    }
  }
  // The 'vw' findings are refused by the pre-scan, before tinyobjloader sees them.
  for (const char* text : {"v 0 0 0\nvw 0 1e300 0.5\n", "v 0 0 0\nvw 0 2147483600 1\n"}) {
    try {
      read_as({"obj", text});
      ADD_FAILURE() << "vw with an out-of-range joint id was accepted: " << text;
    } catch (const slim::Error& e) {
      EXPECT_NE(std::string(e.what()).find("finding.obj:2:"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();
    }
  }
}
