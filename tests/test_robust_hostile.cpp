// Hostile inputs and failing disks: deep JSON, integers and floats beyond their types,
// outputs on a full or missing disk, memory limits, messages that say what was expected.
#include <gtest/gtest.h>
#include <lzma.h>
#include <sys/mount.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cfloat>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "bench_plot.h"
#include "bench_runner.h"
#include "bvh/build.h"
#include "io/gltf.h"
#include "io/obj.h"
#include "io/ply.h"
#include "io/xz.h"
#include "slimrt/output.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

namespace fs = std::filesystem;

using slim::test::error_of;
using slim::test::TempDir;

namespace {

using namespace slim;

// The message of the slim::Error thrown by fn, or "" if none was thrown.
struct Cli {
  int exit_code = -1;
  std::string err;  // stderr
};

// Runs `slimrt ARGS` through sh (prefix: shell commands before it, e.g. "ulimit -f 8;").
Cli run_cli(const std::string& args, const std::string& prefix = "") {
  const fs::path err_file =
      fs::temp_directory_path() / ("slim_hostile_err_" + std::to_string(::getpid()));
  const std::string cmd = "(" + prefix + " exec " + std::string(SLIM_CLI_PATH) + " " + args +
                          ") >/dev/null 2>" + err_file.string();
  Cli r;
  const int status = std::system(cmd.c_str());
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  std::ifstream in(err_file);
  r.err.assign(std::istreambuf_iterator<char>(in), {});
  fs::remove(err_file);
  return r;
}

// A file size limit (RLIMIT_FSIZE) for this process: writes beyond it fail with EFBIG, like a
// full disk. SIGXFSZ is ignored so that the write fails instead of killing the test.
class FileSizeLimit {
 public:
  explicit FileSizeLimit(rlim_t bytes) {
    getrlimit(RLIMIT_FSIZE, &old_);
    old_handler_ = std::signal(SIGXFSZ, SIG_IGN);
    rlimit r = old_;
    r.rlim_cur = bytes;
    setrlimit(RLIMIT_FSIZE, &r);
  }
  ~FileSizeLimit() {
    setrlimit(RLIMIT_FSIZE, &old_);
    std::signal(SIGXFSZ, old_handler_);
  }

 private:
  rlimit old_{};
  void (*old_handler_)(int) = nullptr;
};

Image noise_image(int w, int h) {
  Image img;
  img.width = w;
  img.height = h;
  img.rgb.resize(size_t(w) * size_t(h) * 3);
  Rng rng(7);
  for (float& v : img.rgb) v = rng.uniform();
  return img;
}

// ---- 1. no recursion on input depth ----

TEST(RobustHostile, JsonNestedAMillionLevelsIsAnErrorNotAStackOverflow) {
  const size_t n = 1000000;
  for (char open : {'[', '{'}) {
    std::string nest;
    if (open == '[') {
      nest = std::string(n, '[') + std::string(n, ']');
    } else {
      for (size_t i = 0; i < n; ++i) nest += "{\"a\":";
      nest += "0" + std::string(n, '}');
    }
    const std::string json = "{\"asset\":{\"version\":\"2.0\",\"extras\":" + nest + "}}";
    const std::string msg = error_of([&] { detail::read_gltf("deep.gltf", json, false, "."); });
    EXPECT_NE(msg.find("deep.gltf:1: JSON nests arrays/objects more than 1000 levels"),
              std::string::npos)
        << msg;
  }
  // Brackets inside strings do not count.
  const std::string in_string =
      "{\"asset\":{\"version\":\"2.0\",\"extras\":\"" + std::string(5000, '[') + "\"}}";
  EXPECT_EQ(error_of([&] { detail::read_gltf("s.gltf", in_string, false, "."); }), "");
}

TEST(RobustHostile, GlbJsonChunkNestedTooDeepIsAnError) {
  std::string json = "{\"asset\":{\"version\":\"2.0\",\"extras\":" + std::string(100000, '[') +
                     std::string(100000, ']') + "}}";
  while (json.size() % 4) json += ' ';
  std::string glb(20, '\0');
  auto put = [&](size_t at, uint32_t v) { std::memcpy(&glb[at], &v, 4); };
  put(0, 0x46546C67);
  put(4, 2);
  put(8, uint32_t(20 + json.size()));
  put(12, uint32_t(json.size()));
  put(16, 0x4E4F534A);
  glb += json;
  const std::string msg = error_of([&] { detail::read_gltf("deep.glb", glb, true, "."); });
  EXPECT_NE(msg.find("deep.glb: byte "), std::string::npos) << msg;
  EXPECT_NE(msg.find("more than 1000 levels"), std::string::npos) << msg;
}

// ---- 2. integers and floats beyond their types ----

TEST(RobustHostile, ObjIndicesBeyond2To32AreErrorsNotWrapped) {
  const std::string v = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  for (const char* f : {"f 4294967297 4294967298 4294967299\n", "f 1 2 99999999999999999999999\n",
                        "f -4294967297 2 3\n", "f 1/4294967297 2 3\n", "f 1//4294967297 2 3\n"}) {
    const std::string msg = error_of([&] { detail::read_obj("w.obj", v + f); });
    EXPECT_NE(msg.find("w.obj:4: "), std::string::npos) << f << msg;
    EXPECT_NE(msg.find("index out of range"), std::string::npos) << f << msg;
  }
  const std::string zero = error_of([&] { detail::read_obj("z.obj", v + "f 1 2 0\n"); });
  EXPECT_NE(zero.find("z.obj:4: vertex index out of range: '0' in face 'f 1 2 0'"),
            std::string::npos)
      << zero;
  EXPECT_NE(zero.find("expected a nonzero index from 1 to 3 or from -3 to -1"), std::string::npos)
      << zero;
  // In range, relative and absolute: still loads.
  EXPECT_EQ(error_of([&] { detail::read_obj("ok.obj", v + "f 1 -2 3\n"); }), "");
}

TEST(RobustHostile, FloatOverflowIsAnErrorNamingTheLine) {
  // 3.4028236e38 lies beyond FLT_MAX plus half an ulp: it would round to inf.
  for (const char* line :
       {"v 1e39 0 0\n", "v 0 -1e39 0\n", "vn 0 0 1e40\n", "vt 1e39 0\n", "v 3.4028236e38 0 0\n"}) {
    const std::string obj = std::string("v 0 0 0\nv 1 0 0\nv 0 1 0\n") + line + "f 1 2 3\n";
    const std::string msg = error_of([&] { detail::read_obj("o.obj", obj); });
    EXPECT_NE(msg.find("o.obj:4: "), std::string::npos) << line << msg;
    EXPECT_NE(msg.find("overflows float"), std::string::npos) << line << msg;
  }
  // FLT_MAX printed to 9 digits (3.40282347e+38, above FLT_MAX as a decimal) rounds to FLT_MAX:
  // accepted, so an OBJ slimrt writes reads back (fuzz_obj's round trip).
  const PolyMesh m = detail::read_obj(
      "max.obj", "v 0 0 0\nv 1 0 0\nv 0 3.40282347e+38 0\nv 0 -3.4028235e38 0\nf 1 2 3 4\n");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.positions[2].y, FLT_MAX);
  EXPECT_EQ(m.positions[3].y, -FLT_MAX);
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n"
      "property double z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  for (const char* big : {"1e300", "1e999"}) {
    const std::string ply = head + "0 0 0\n" + big + " 0 0\n0 1 0\n3 0 1 2\n";
    const std::string msg = error_of([&] { detail::read_ply("a.ply", ply); });
    EXPECT_NE(msg.find("a.ply:11: "), std::string::npos) << big << msg;
    EXPECT_NE(msg.find("overflows"), std::string::npos) << big << msg;
  }
  // Binary double 1e300.
  std::string bin =
      "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\n"
      "property double y\nproperty double z\nelement face 1\n"
      "property list uchar int vertex_indices\nend_header\n";
  const double coords[9] = {0, 0, 0, 1e300, 0, 0, 0, 1, 0};
  bin.append(reinterpret_cast<const char*>(coords), sizeof coords);
  const uint8_t n = 3;
  const int32_t idx[3] = {0, 1, 2};
  bin.append(reinterpret_cast<const char*>(&n), 1);
  bin.append(reinterpret_cast<const char*>(idx), sizeof idx);
  const std::string msg = error_of([&] { detail::read_ply("b.ply", bin); });
  EXPECT_NE(msg.find("b.ply: byte "), std::string::npos) << msg;
  EXPECT_NE(msg.find("overflows float"), std::string::npos) << msg;
}

TEST(RobustHostile, ObjExponentsBeyond400AreErrorsNamingTheLine) {
  for (const char* line :
       {"v 0e2147483649 0 0\n", "vn 0 0 1e-0000002147483649\n", "vt 1E+9999999 0\n",
        "vw 1 0e3805 1\n", "v 0 0e401 0\n", "t c 0/1/0 0e9999999\n"}) {
    const std::string obj = std::string("v 0 0 0\nv 1 0 0\nv 0 1 0\n") + line + "f 1 2 3\n";
    const std::string msg = error_of([&] { detail::read_obj("e.obj", obj); });
    EXPECT_NE(msg.find("e.obj:4: "), std::string::npos) << line << msg;
    EXPECT_NE(msg.find("has an exponent beyond 400"), std::string::npos) << line << msg;
  }
  // Only numbers have exponents: a tag named like one is not refused.
  EXPECT_EQ(error_of([&] {
              detail::read_obj("tag.obj",
                               "v 0 0 0\nv 1 0 0\nv 0 1 0\nt file1e999 0/0/1 x\nf 1 2 3\n");
            }),
            "");
  // Exponents up to 400 still parse (these values underflow to 0).
  EXPECT_EQ(error_of([&] {
              detail::read_obj("ok.obj", "v 0 0 0\nv 1 0 0\nv 0 1e-400 0e400\nf 1 2 3\n");
            }),
            "");
}

TEST(RobustHostile, GltfIntPropertiesBeyondIntAreErrorsNotWrapped) {
  const std::string head =
      "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":36,\"uri\":"
      "\"data:application/octet-stream;base64," +
      std::string(48, 'A') +
      "\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],\"accessors\":[{"
      "\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],"
      "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":";
  const std::string ok = head + "0}}]}],\"nodes\":[{\"mesh\":0,\"extras\":{\"mesh\":1e10}}]}";
  EXPECT_EQ(error_of([&] { detail::read_gltf("ok.gltf", ok, false, "."); }), "");
  for (const std::string& bad :
       {head + "0}}]}],\"nodes\":[{\"mesh\":4294967296}]}",
        head + "0}}]}],\"nodes\":[{\"mesh\":1e10}]}",
        head + "4294967296}}]}],\"nodes\":[{\"mesh\":0}]}",
        head + "0}}]}],\"nodes\":[{\"children\":[1,4294967297]},{\"mesh\":0}]}"}) {
    const std::string msg = error_of([&] { detail::read_gltf("w.gltf", bad, false, "."); });
    EXPECT_NE(msg.find("w.gltf:1: "), std::string::npos) << msg;
    EXPECT_NE(msg.find("expected an integer from 0 to 2147483647"), std::string::npos) << msg;
  }
}

// ---- 3. outputs complete or absent ----

TEST(RobustHostile, AtomicWriteReplacesWholeFilesAndLeavesNoTemporary) {
  TempDir d{"slim_hostile"};
  const std::string p = d.path("out.json");
  write_file_atomically(p, std::string(1000, 'a'));
  write_file_atomically(p, "short");
  EXPECT_EQ(fs::file_size(p), 5u);
  EXPECT_EQ(d.names(), std::vector<std::string>{"out.json"});
}

TEST(RobustHostile, FullDiskLeavesNothingBehindAndIsAnError) {
  TempDir d{"slim_hostile"};
  const Image img = noise_image(200, 200);  // about 120 KB as PNG, 480 KB as EXR
  for (const char* name : {"full.png", "full.exr", "full.json"}) {
    std::string msg;
    {
      FileSizeLimit limit(16 * 1024);
      msg = error_of([&] {
        if (std::string(name).ends_with(".json"))
          write_file_atomically(d.path(name), std::string(100000, 'x'));
        else
          write_image(img, d.path(name));
      });
    }
    EXPECT_NE(msg.find(name), std::string::npos) << msg;
    EXPECT_NE(msg.find("File too large"), std::string::npos) << msg;
    EXPECT_TRUE(d.names().empty()) << name << ": left " << d.names().size() << " files";
  }
}

TEST(RobustHostile, FullTmpfsLeavesNothingBehind) {
  if (::geteuid() != 0) GTEST_SKIP() << "mounting a 64 KiB tmpfs needs root";
  TempDir d{"slim_hostile"};
  const std::string mnt = d.path("tiny");
  fs::create_directories(mnt);
  if (::mount("tmpfs", mnt.c_str(), "tmpfs", 0, "size=64k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here: " << std::strerror(errno);
  const std::string msg = error_of([&] { write_image(noise_image(256, 256), mnt + "/full.png"); });
  const bool empty = fs::is_empty(mnt);
  ::umount(mnt.c_str());
  EXPECT_NE(msg.find("No space left on device"), std::string::npos) << msg;
  EXPECT_TRUE(empty);
}

TEST(RobustHostile, OutputPathsAreCheckedFirst) {
  TempDir d{"slim_hostile"};
  EXPECT_NE(
      error_of([&] { check_output_path(d.path("no/such/dir/x.png")); }).find("does not exist"),
      std::string::npos);
  EXPECT_NE(error_of([&] { check_output_path(d.path("")); }).find("expected a file name"),
            std::string::npos);
  const std::string file = d.write("plain", "x");
  EXPECT_NE(error_of([&] { check_output_path(file + "/x.png"); }).find("is not a folder"),
            std::string::npos);
  EXPECT_EQ(error_of([&] { check_output_path(d.path("fine.png")); }), "");
  EXPECT_EQ(d.names(), std::vector<std::string>{"plain"});  // the probe file is gone

  // The CLI refuses a bad -o before it even loads the (missing) scene.
  const Cli r = run_cli("render " + d.path("missing.obj") + " -o " + d.path("nodir/x.png"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("nodir' does not exist"), std::string::npos) << r.err;
  const Cli b = run_cli("bench terrain:8 --config bvh8-tri4v --json " + d.path("nodir/x.json"));
  EXPECT_EQ(b.exit_code, 1) << b.err;
  EXPECT_NE(b.err.find("nodir' does not exist"), std::string::npos) << b.err;
}

TEST(RobustHostile, CliOnAFullDiskExitsNonZeroAndLeavesNoFile) {
  TempDir d{"slim_hostile"};
  // ulimit -f 16: 8 or 16 KiB (512- or 1024-byte blocks); the noisy path-traced PNG is larger.
  const Cli r =
      run_cli("render terrain:64 --res 256x256 --spp 1 -o " + d.path("cut.png"), "ulimit -f 16;");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("File too large"), std::string::npos) << r.err;
  EXPECT_TRUE(d.names().empty()) << d.names().size() << " files left";
  // Results on stdout count too.
  const Cli s = run_cli("info terrain:8 > /dev/full");
  EXPECT_EQ(s.exit_code, 1) << s.err;
  EXPECT_NE(s.err.find("No space left on device"), std::string::npos) << s.err;
}

// ---- 4. memory bounded ----

TEST(RobustHostile, GltfInstancingBeyondTheMemoryBudgetIsRefusedBeforeCopying) {
  TempDir d{"slim_hostile"};
  const uint32_t nv = 99999;  // one mesh of 99999 vertices (1.2 MB buffer, 33333 triangles)
  std::vector<float> pos(size_t(nv) * 3);
  for (uint32_t i = 0; i < nv; ++i) pos[3 * i] = float(i % 3), pos[3 * i + 1] = float(i % 5);
  d.write("m.bin", std::string(reinterpret_cast<const char*>(pos.data()), pos.size() * 4));
  // Enough nodes on it for the flattened copy to pass the memory budget.
  const uint64_t per_instance = uint64_t(nv) * 12;  // the positions alone pass the budget
  const uint64_t nodes = memory_budget() / per_instance + 2;
  std::string json =
      "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"uri\":\"m.bin\","
      "\"byteLength\":" +
      std::to_string(pos.size() * 4) +
      "}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":" + std::to_string(pos.size() * 4) +
      "}],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":" + std::to_string(nv) +
      ",\"type\":\"VEC3\"}],\"meshes\":[{\"primitives\":[{\"attributes\":"
      "{\"POSITION\":0}}]}],\"nodes\":[";
  for (uint64_t i = 0; i < nodes; ++i) json += std::string(i ? "," : "") + "{\"mesh\":0}";
  json += "]}";
  const std::string file = d.write("inst.gltf", json);
  const std::string msg = error_of([&] { load(file); });
  EXPECT_NE(msg.find(std::to_string(nodes) + " mesh instances"), std::string::npos) << msg;
  EXPECT_NE(msg.find("half of this machine's memory"), std::string::npos) << msg;
}

std::string xz_compress(const std::string& plain) {
  std::string out(plain.size() / 2 + 4096, '\0');
  size_t pos = 0;
  EXPECT_EQ(lzma_easy_buffer_encode(6, LZMA_CHECK_CRC64, nullptr,
                                    reinterpret_cast<const uint8_t*>(plain.data()), plain.size(),
                                    reinterpret_cast<uint8_t*>(out.data()), &pos, out.size()),
            LZMA_OK);
  out.resize(pos);
  return out;
}

TEST(RobustHostile, DecompressionLimitCountsBytesHeld) {
  const std::string packed = xz_compress(std::string(size_t(4) << 20, 'z'));
  const std::string msg = error_of(
      [&] { detail::xz_decompress("bomb.xz", packed.data(), packed.size(), uint64_t(1) << 20); });
  EXPECT_NE(msg.find("decompresses to more than 1 MiB"), std::string::npos) << msg;
  EXPECT_EQ(detail::xz_decompress("ok.xz", packed.data(), packed.size(), uint64_t(4) << 20).size(),
            size_t(4) << 20);
  // The default limit is a share of this machine's memory.
  const uint64_t phys = uint64_t(sysconf(_SC_PHYS_PAGES)) * uint64_t(sysconf(_SC_PAGESIZE));
  EXPECT_LE(memory_budget(), std::max<uint64_t>(phys / 2, uint64_t(256) << 20));
  EXPECT_EQ(detail::max_file_bytes(), memory_budget());
}

TEST(RobustHostile, BufferSizingOptionsHaveLimits) {
  const Cli v = run_cli("verify sphere:1 --rays 1099511627776");
  EXPECT_EQ(v.exit_code, 1) << v.err;
  EXPECT_NE(v.err.find("--rays 1099511627776 needs about"), std::string::npos) << v.err;
  TempDir d{"slim_hostile"};
  const Cli r = run_cli("render terrain:8 --res 65536x65536 -o " + d.path("x.png"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--res 65536x65536: 4294967296 pixels need about"), std::string::npos)
      << r.err;
  EXPECT_TRUE(d.names().empty());
}

// ---- 6. std::bad_alloc never the whole message ----

TEST(RobustHostile, OutOfMemoryNamesTheStepAndTheScene) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "an address space limit breaks the sanitizers' shadow memory";
#endif
  TempDir d{"slim_hostile"};
  // 1.5 GB of address space: terrain:2048 loads, its build runs out.
  const Cli r = run_cli("render terrain:2048 --res 64x64 --threads 1 -o " + d.path("t.png"),
                        "ulimit -v 1500000;");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("out of memory while building terrain:2048 as bvh8-tri4v"),
            std::string::npos)
      << r.err;
  EXPECT_TRUE(d.names().empty());
}

TEST(RobustHostile, GnuplotFailureSaysWhatGnuplotSaid) {
  TempDir d{"slim_hostile"};
  // A stand-in gnuplot that answers --version and then fails like a bad script.
  d.write("gnuplot",
          "#!/bin/sh\n[ \"$1\" = --version ] && exit 0\ncat >/dev/null\n"
          "echo 'line 3: undefined variable: foo' >&2\nexit 3\n");
  fs::permissions(d.path("gnuplot"), fs::perms::owner_all);
  const std::string old_path = std::getenv("PATH") ? std::getenv("PATH") : "";
  setenv("PATH", (d.path("") + ":" + old_path).c_str(), 1);
  bench::BenchReport report;
  bench::BenchRow row;
  row.scene = "s";
  row.config = "bvh8-tri4v";
  row.bytes_per_triangle = 40.0;
  row.mrays_diffuse = bench::Spread{10.0, 10.0, 10.0};  // median, lo, hi over the rounds
  report.rows.push_back(row);
  std::string why;
  const bool ok = bench::write_plot(report, d.path("plot.png"), &why);
  setenv("PATH", old_path.c_str(), 1);
  EXPECT_FALSE(ok);
  EXPECT_NE(why.find("gnuplot exited with code 3, expected 0: line 3: undefined variable: foo"),
            std::string::npos)
      << why;
  EXPECT_EQ(why.find("256"), std::string::npos) << why;
  EXPECT_EQ(d.names(), std::vector<std::string>{"gnuplot"});  // no plot, no temporary file
}

// ---- 5. verify far from the origin ----

// A closed cube of half-size `radius` centred at (offset, offset, offset) as an OBJ file.
std::string offset_cube(double offset, double radius) {
  std::string s;
  for (int i = 0; i < 8; ++i) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "v %.9g %.9g %.9g\n", offset + (i & 1 ? radius : -radius),
                  offset + (i & 2 ? radius : -radius), offset + (i & 4 ? radius : -radius));
    s += buf;
  }
  s += "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n";
  return s;
}

TEST(RobustHostile, VerifyFindsNoLeaksFarFromTheOrigin) {
  TempDir d{"slim_hostile"};
  for (double radius : {1e3, 1e9}) {
    const std::string file = d.write("cube.obj", offset_cube(4e6, radius));
    const Cli r =
        run_cli("verify " + file +
                " --config bvh8-tri4v,qbvh8-tri4v,clbvh-tri4v,bvh8-pairs --rays 30000 --threads 2");
    EXPECT_EQ(r.exit_code, 0) << "radius " << radius << ": " << r.err;
  }
}

// ---- 7. degenerate stacks ----

// A million coincident triangles: every centroid is equal, so the builder splits at the object
// median by index (build.cpp) and the tree is balanced (depth about log2(n / leaf size)). A ray
// through the stack still tests every triangle (all boxes are equal and every hit has the same
// t), as with Embree; this guards the build, not the trace.
TEST(RobustHostile, CoincidentStackBuildsABalancedTree) {
  const uint32_t n = 1000000;
  for (float jitter : {0.0f, 1e-7f}) {
    std::vector<PrimRef> refs(n);
    for (uint32_t i = 0; i < n; ++i) {
      const float e = jitter * float(i % 7);  // near-coincident: a few distinct centroids
      refs[i].box = {Vec3f(e, 0, 0), Vec3f(1 + e, 1, 0)};
      refs[i].id = i;
    }
    Bvh2BuildConfig cfg;
    const Bvh2 b = build_bvh2(refs, cfg);
    EXPECT_LE(b.depth, 24) << "jitter " << jitter;
    EXPECT_LE(b.nodes.size(), size_t(n)) << "jitter " << jitter;
  }
}

// ---- 6. messages ----

TEST(RobustHostile, MessagesNameWhatWasExpectedAndFound) {
  // torus:N: one range, the one that holds.
  for (const char* spec : {"torus:5", "torus:7", "torus:20000"}) {
    const std::string msg = error_of([&] { load(spec); });
    EXPECT_NE(msg.find("even integer from 6 to 16384"), std::string::npos) << msg;
    EXPECT_EQ(msg.find("65534"), std::string::npos) << msg;
  }
  // byteStride: the 4..252 rule.
  const std::string stride =
      "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":4,\"uri\":"
      "\"data:application/octet-stream;base64,AAAAAA==\"}],\"bufferViews\":[{\"buffer\":0,"
      "\"byteLength\":4,\"byteStride\":256}]}";
  std::string msg = error_of([&] { detail::read_gltf("s.gltf", stride, false, "."); });
  EXPECT_NE(msg.find("byteStride 256; expected a multiple of 4 from 4 to 252"), std::string::npos)
      << msg;
  // A data URI shorter than byteLength: no base64 excerpt.
  const std::string shortdata =
      "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":"
      "4000,\"uri\":\"data:application/octet-stream;base64," +
      std::string(400, 'A') + "\"}]}";
  msg = error_of([&] { detail::read_gltf("u.gltf", shortdata, false, "."); });
  EXPECT_NE(msg.find("does not decode to its byteLength"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("AAAAAAAAAA"), std::string::npos) << msg;
  // A buffer file that exists but is refused (a folder) is not "File not found".
  TempDir d{"slim_hostile"};
  fs::create_directories(d.path("dir.bin"));
  const std::string ext =
      "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":4,"
      "\"uri\":\"dir.bin\"}]}";
  msg = error_of([&] { detail::read_gltf("e.gltf", ext, false, d.path("")); });
  EXPECT_NE(msg.find("not a regular file"), std::string::npos) << msg;
  EXPECT_EQ(msg.find("File not found"), std::string::npos) << msg;
}

}  // namespace
