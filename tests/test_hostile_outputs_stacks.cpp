// Hostile inputs, continued: non-finite coordinates after glTF node transforms, outputs onto
// symlinks, devices and FIFOs, the CLI's report of discarded input, and stacks of coincident
// triangles.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "bench_plot.h"
#include "io/gltf.h"
#include "slimrt/analysis.h"
#include "slimrt/output.h"
#include "slimrt/slimrt.h"
#include "temp_dir.h"
#include "test_util.h"

namespace fs = std::filesystem;
using slim::test::error_of;
using slim::test::TempDir;

namespace {

using namespace slim;

// One triangle (0,0,0) (1,0,0) (0,1,0) as a glTF with `nodes` (a JSON array, or "" for none).
std::string triangle_gltf(
    const std::string& nodes,
    const std::string& base64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA") {
  return "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":36,\"uri\":"
         "\"data:application/octet-stream;base64," +
         base64 +
         "\"}],\"bufferViews\":[{\"buffer\":0,\"byteLength\":36}],\"accessors\":[{"
         "\"bufferView\":0,\"componentType\":5126,\"count\":3,\"type\":\"VEC3\"}],"
         "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}]" +
         (nodes.empty() ? "" : ",\"nodes\":" + nodes) + "}";
}

// ---- non-finite coordinates after node transforms ----

TEST(HostileOutputsStacks, GltfTransformThatOverflowsFloatIsAnError) {
  // In range after the transform: loads.
  const PolyMesh m = detail::read_gltf(
      "ok.gltf", triangle_gltf("[{\"mesh\":0,\"scale\":[1e30,1,1]}]"), false, ".");
  ASSERT_EQ(m.positions.size(), 3u);
  EXPECT_EQ(m.positions[1].x, 1e30f);
  struct Case {
    std::string nodes, expect;
  };
  for (const Case& c : std::vector<Case>{
           {"[{\"mesh\":0,\"scale\":[1e39,1,1]}]",
            "vertex 1 coordinate x is 1e+39 after the world transform of nodes[0]"},
           {"[{\"mesh\":0,\"translation\":[0,-1e300,0]}]",
            "vertex 0 coordinate y is -1e+300 after the world transform of nodes[0]"},
           // Each scale is finite as a float; their product is not.
           {"[{\"children\":[1],\"scale\":[1,1e20,1]},{\"mesh\":0,\"scale\":[1,1e20,1]}]",
            "vertex 2 coordinate y is 1e+40 after the world transform of nodes[1]"},
           {"[{\"mesh\":0,\"matrix\":[1e200,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1]}]",
            "vertex 1 coordinate x is 1e+200 after the world transform of nodes[0]"}}) {
    const std::string msg =
        error_of([&] { detail::read_gltf("big.gltf", triangle_gltf(c.nodes), false, "."); });
    EXPECT_NE(msg.find("big.gltf: meshes[0].primitives[0].POSITION: "), std::string::npos)
        << c.nodes << "\n"
        << msg;
    EXPECT_NE(msg.find(c.expect), std::string::npos) << c.nodes << "\n" << msg;
    EXPECT_NE(msg.find("expected a finite number"), std::string::npos) << msg;
  }
  // A NaN in the accessor itself, with and without nodes.
  const std::string nan_b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAwH8AAAAA";
  for (const std::string& nodes : {std::string(), std::string("[{\"mesh\":0}]")}) {
    const std::string msg =
        error_of([&] { detail::read_gltf("nan.gltf", triangle_gltf(nodes, nan_b64), false, "."); });
    EXPECT_NE(msg.find("nan.gltf: meshes[0].primitives[0].POSITION: vertex 2 coordinate y is nan "
                       "in the accessor"),
              std::string::npos)
        << msg;
  }
}

// ---- outputs onto links, devices and pipes ----

std::string contents(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The link stays a link; its target (relative, in another folder, or not yet existing) gets the
// bytes, and no temporary file is left in either folder.
TEST(HostileOutputsStacks, OutputThroughASymlinkWritesItsTarget) {
  TempDir d{"slim_outputs"};
  fs::create_directories(d.path("real"));
  fs::create_directories(d.path("links"));
  write_file_atomically(d.path("real/a.bin"), "old contents");
  fs::create_symlink("../real/a.bin", d.path("links/a.bin"));
  fs::create_symlink("../real/b.bin", d.path("links/b.bin"));  // dangling: created on write
  fs::create_symlink("a.bin", d.path("links/chain.bin"));      // a link to a link
  write_file_atomically(d.path("links/a.bin"), "new");
  write_file_atomically(d.path("links/b.bin"), "bee");
  EXPECT_TRUE(fs::is_symlink(d.path("links/a.bin")));
  EXPECT_TRUE(fs::is_symlink(d.path("links/b.bin")));
  EXPECT_EQ(contents(d.path("real/a.bin")), "new");
  EXPECT_EQ(contents(d.path("real/b.bin")), "bee");
  check_output_path(d.path("links/chain.bin"));
  write_file_atomically(d.path("links/chain.bin"), "chained");
  EXPECT_TRUE(fs::is_symlink(d.path("links/chain.bin")));
  EXPECT_EQ(contents(d.path("real/a.bin")), "chained");
  size_t real_files = 0, links = 0;
  for (const auto& e : fs::directory_iterator(d.path("real"))) real_files += e.exists();
  for (const auto& e : fs::directory_iterator(d.path("links"))) links += e.is_symlink();
  EXPECT_EQ(real_files, 2u);  // a.bin, b.bin: no temporary left
  EXPECT_EQ(links, 3u);
  // A link into a missing folder names that folder.
  fs::create_symlink("../nowhere/c.bin", d.path("links/c.bin"));
  EXPECT_NE(error_of([&] { check_output_path(d.path("links/c.bin")); }).find("does not exist"),
            std::string::npos);
  // A loop of links is an error, not a hang.
  fs::create_symlink("loop2", d.path("links/loop1"));
  fs::create_symlink("loop1", d.path("links/loop2"));
  EXPECT_NE(error_of([&] {
              write_file_atomically(d.path("links/loop1"), "x");
            }).find("levels of symbolic links"),
            std::string::npos);
}

// A character device is written in place, not replaced by a regular file.
TEST(HostileOutputsStacks, OutputOntoACharacterDeviceWritesIt) {
  TempDir d{"slim_outputs"};
  // As root: a null device node of our own (major 1, minor 3), so a failure replaces it and not
  // /dev/null. Otherwise /dev/null itself (no temporary file can be created in /dev then).
  std::string dev = "/dev/null";
  if (::geteuid() == 0 && ::mknod(d.path("null").c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0)
    dev = d.path("null");
  EXPECT_EQ(error_of([&] { check_output_path(dev); }), "");
  EXPECT_EQ(error_of([&] { write_file_atomically(dev, std::string(100000, 'x')); }), "");
  struct stat st {};
  ASSERT_EQ(::stat(dev.c_str(), &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode)) << dev << " is no longer a character device";
  if (dev != "/dev/null") {
    EXPECT_EQ(d.entries(), 1u);
  }
}

// A named pipe with a reader gets the bytes; without one the write is an error at once.
TEST(HostileOutputsStacks, OutputOntoANamedPipe) {
  TempDir d{"slim_outputs"};
  const std::string fifo = d.path("pipe");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0666), 0);
  EXPECT_EQ(error_of([&] { check_output_path(fifo); }), "");  // the reader may start later
  const auto t0 = std::chrono::steady_clock::now();
  const std::string msg = error_of([&] { write_file_atomically(fifo, "hello"); });
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  EXPECT_NE(msg.find("pipe: named pipe has no reader"), std::string::npos) << msg;
  struct stat st {};
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_EQ(d.entries(), 1u);
  // With a reader (non-blocking, so that opening it does not wait for the writer).
  const int reader = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK);
  ASSERT_GE(reader, 0);
  EXPECT_EQ(error_of([&] { write_file_atomically(fifo, "hello"); }), "");
  char buf[16] = {};
  EXPECT_EQ(::read(reader, buf, sizeof buf), 5);
  EXPECT_EQ(std::string(buf), "hello");
  ::close(reader);
  ASSERT_EQ(::stat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_EQ(d.entries(), 1u);
}

// The CLI's image goes to the link's target and the link stays.
TEST(HostileOutputsStacks, CliRendersThroughASymlink) {
  TempDir d{"slim_outputs"};
  fs::create_directories(d.path("real"));
  fs::create_symlink(d.path("real/img.png"), d.path("img.png"));
  const std::string cmd = std::string(SLIM_CLI_PATH) + " render terrain:8 --res 16x16 --spp 1 -o " +
                          d.path("img.png") + " >/dev/null 2>&1";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  EXPECT_TRUE(fs::is_symlink(d.path("img.png")));
  EXPECT_TRUE(fs::is_regular_file(d.path("real/img.png")));
  EXPECT_GT(fs::file_size(d.path("real/img.png")), 0u);
}

// An output name that is a link to the process's stdout (/dev/stdout -> /proc/self/fd/1 ->
// "pipe:[N]", no path) writes into the pipe; a reader that stops early gives a write error
// (exit 1, EPIPE), not a death by SIGPIPE.
TEST(HostileOutputsStacks, CliWritesIntoAPipeThroughDevStdout) {
  TempDir d{"slim_outputs"};
  fs::create_symlink("/dev/stdout", d.path("so.png"));
  const std::string render = std::string(SLIM_CLI_PATH) + " render terrain:64 --spp 1 -q -o " +
                             d.path("so.png") + " --res ";
  const std::string got = d.path("got.png");
  int status =
      std::system(("bash -c 'set -o pipefail; " + render + "16x16 | cat >" + got + "'").c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0);
  const std::string png = contents(got);
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  const std::string err = d.path("err.txt");
  status = std::system(("bash -c '" + render + "1024x1024 2>" + err +
                        " | head -c 10 >/dev/null; exit ${PIPESTATUS[0]}'")
                           .c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_NE(contents(err).find("Broken pipe"), std::string::npos) << contents(err);
}

// slimrt build onto a link to a character device: the device is written, the link stays, and
// the summary does not fail on the device's size.
TEST(HostileOutputsStacks, CliBuildsOntoALinkToADevice) {
  TempDir d{"slim_outputs"};
  std::string dev = "/dev/null";
  if (::geteuid() == 0 && ::mknod(d.path("null").c_str(), S_IFCHR | 0666, makedev(1, 3)) == 0)
    dev = d.path("null");
  fs::create_symlink(dev, d.path("out.slim"));
  const std::string line = d.path("stdout.txt");
  const std::string cmd = std::string(SLIM_CLI_PATH) + " build terrain:8 -o " + d.path("out.slim") +
                          " >" + line + " 2>&1";
  const int status = std::system(cmd.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << contents(line);
  EXPECT_NE(contents(line).find("not a regular file"), std::string::npos) << contents(line);
  EXPECT_TRUE(fs::is_symlink(d.path("out.slim")));
  struct stat st {};
  ASSERT_EQ(::stat(dev.c_str(), &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
}

// ---- bench --plot onto devices and pipes ----

bench::BenchReport plot_report() {
  bench::BenchReport r;
  r.machine.cpu = "test cpu";
  r.machine.threads = 1;
  for (const char* config : {"embree-tri", "bvh8-tri4v"}) {
    bench::BenchRow row;
    row.scene = "terrain:8";
    row.config = config;
    row.embree = std::string(config) == "embree-tri";
    row.bytes_per_triangle = row.embree ? 60.0 : 40.0;
    row.mrays_diffuse = bench::Spread{5.0, 4.0, 6.0};
    r.rows.push_back(row);
  }
  return r;
}

// The plot is written in place onto a character device and into a pipe reached through
// /dev/stdout, as the other outputs are: gnuplot's messages go to the temporary folder, since the
// output's folder (/dev) may take no file. In a child process, as user nobody when the test runs
// as root (root may create files in /dev).
TEST(HostileOutputsStacks, BenchPlotOntoADeviceAndThroughDevStdout) {
  if (std::system("gnuplot --version >/dev/null 2>&1") != 0) GTEST_SKIP() << "no gnuplot";
  const bench::BenchReport report = plot_report();
  std::fflush(stdout);
  std::fflush(stderr);
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    if (::geteuid() == 0 && (::setgid(65534) != 0 || ::setuid(65534) != 0)) ::_exit(10);
    ::prctl(PR_SET_DUMPABLE, 1);    // /proc/self/fd (behind /dev/stdout) stays ours after setuid
    std::signal(SIGPIPE, SIG_IGN);  // as the CLI: a gnuplot that stops early is an error
    std::string why;
    if (!bench::write_plot(report, "/dev/null", &why)) {
      std::fprintf(stderr, "/dev/null: %s\n", why.c_str());
      ::_exit(1);
    }
    // Standard output as a pipe that a thread drains.
    int fds[2];
    if (::pipe(fds) != 0) ::_exit(11);
    std::string png;
    std::thread reader([&] {
      char buf[65536];
      ssize_t n;
      while ((n = ::read(fds[0], buf, sizeof buf)) > 0) png.append(buf, size_t(n));
    });
    const int saved = ::dup(1);
    ::dup2(fds[1], 1);
    ::close(fds[1]);
    const bool written = bench::write_plot(report, "/dev/stdout", &why);
    ::dup2(saved, 1);  // the pipe's last writer closes: the reader sees its end
    reader.join();
    if (!written) {
      std::fprintf(stderr, "/dev/stdout: %s\n", why.c_str());
      ::_exit(2);
    }
    if (png.size() < 8 || png.substr(1, 3) != "PNG") {
      std::fprintf(stderr, "/dev/stdout: %zu bytes, no PNG\n", png.size());
      ::_exit(3);
    }
    ::_exit(0);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: /dev/null failed, 2: /dev/stdout failed, 3: no PNG";
}

// ---- stacks of coincident triangles ----

// `n` triangles on (0,0,0) (1,0,0) (0,1,0): the same vertices in the three rotations, and the
// same positions through another vertex index; `mirrored` adds one facing the other way.
PolyMesh coincident_stack(uint32_t n, bool mirrored) {
  PolyMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 1, 0}};
  const uint32_t faces[4][3] = {{0, 1, 2}, {1, 2, 0}, {2, 0, 1}, {0, 1, 3}};
  for (uint32_t i = 0; i < n; ++i) {
    m.face_sizes.push_back(3);
    m.face_indices.insert(m.face_indices.end(), faces[i % 4], faces[i % 4] + 3);
  }
  if (mirrored) {
    m.face_sizes.push_back(3);
    m.face_indices.insert(m.face_indices.end(), {0, 2, 1});
  }
  return m;
}

// The build left out `dropped` duplicate triangles and its structure is valid.
void expect_dropped_and_valid(const Scene& s, double dropped) {
  EXPECT_EQ(stat_detail(s, "duplicate_triangles").value_or(-1), dropped);
  std::string why;
  EXPECT_TRUE(s.validate(&why)) << why;
}

// A ray straight down (-z) from (x, y, 1), counted.
Hit down_from(const Scene& s, float x, float y, TraversalCounters& counters) {
  Ray ray;
  ray.org = {x, y, 1.0f};
  ray.dir = {0, 0, -1};
  return intersect_counted(s, ray, counters);
}

// The triangle formats keep one triangle of each group of exact duplicates (the one of the
// lowest face index), so a ray through a stack of 10^5 tests a few triangles instead of all,
// and its hit is the first face of the stack at the same t. A triangle facing the other way is
// no duplicate.
TEST(HostileOutputsStacks, CoincidentTrianglesAreTracedInBoundedTime) {
  const uint32_t n = 100000;
  const PolyMesh stack = coincident_stack(n, false), mirrored = coincident_stack(n, true);
  for (const char* config : {"bvh8-tri4v", "bvh8-tri4i", "qbvh8-tri4v", "clbvh-compact", "grid"}) {
    SCOPED_TRACE(config);
    const BuildOptions opt = BuildOptions::from_config(config);
    const Scene s = Scene::build(stack, opt);
    EXPECT_EQ(stat_detail(s, "duplicate_triangles").value_or(-1), double(n - 1));
    std::string why;
    EXPECT_TRUE(s.validate(&why)) << why;
    TraversalCounters c;
    Ray ray;
    ray.org = {0.25f, 0.25f, 1.0f};
    ray.dir = {0, 0, -1};
    const Hit h = intersect_counted(s, ray, c);
    ASSERT_TRUE(h.valid());
    EXPECT_EQ(h.t, 1.0f);
    EXPECT_EQ(h.primID, 0u);
    EXPECT_LE(c.prim_tests, 8u);
    const Scene sm = Scene::build(mirrored, opt);
    EXPECT_EQ(stat_detail(sm, "duplicate_triangles").value_or(-1), double(n - 1));
    EXPECT_TRUE(sm.validate(&why)) << why;
  }
}

// Every configuration of the registry (pairs, clusters, costa and grids included), and the grid
// formats with their leftovers as 2x2 sub-grids: a ray through a stack of 10^4 coincident
// triangles, or through its box beside the triangle, tests a bounded number of triangles, and a
// hit is the lowest face of the stack. With a mirrored triangle added (another surface, kept)
// the hit is the lowest face of one of the two surfaces.
TEST(HostileOutputsStacks, EveryConfigurationTracesAStackInBoundedTime) {
  const uint32_t n = 10000;
  const PolyMesh stack = coincident_stack(n, false), mirrored = coincident_stack(n, true);
  std::vector<std::pair<std::string, BuildOptions>> cases;
  for (const ConfigInfo& c : configs()) {
    cases.emplace_back(c.name, BuildOptions::from_config(c.name));
    const Leaf leaf = c.options.leaf;
    if (leaf == Leaf::Grids || leaf == Leaf::LossyGrids || leaf == Leaf::SharedLossyGrids) {
      cases.emplace_back(c.name + " --grid-leftovers grids", c.options);
      cases.back().second.grid_leftovers = GridLeftovers::Grids;
    }
  }
  for (const auto& [name, opt] : cases) {
    for (const bool mirror : {false, true}) {
      SCOPED_TRACE(name + (mirror ? " with a mirrored triangle" : ""));
      const Scene s = Scene::build(mirror ? mirrored : stack, opt);
      expect_dropped_and_valid(s, double(n - 1));
      TraversalCounters hit_counters;
      const Hit h = down_from(s, 0.25f, 0.25f, hit_counters);
      ASSERT_TRUE(h.valid());
      EXPECT_FLOAT_EQ(h.t, 1.0f);
      if (mirror)
        EXPECT_TRUE(h.primID == 0u || h.primID == n) << h.primID;
      else
        EXPECT_EQ(h.primID, 0u);
      EXPECT_LE(hit_counters.prim_tests, 16u);
      // Inside the stack's box, beside the triangle: a miss after the same leaves.
      TraversalCounters miss_counters;
      EXPECT_FALSE(down_from(s, 0.75f, 0.75f, miss_counters).valid());
      EXPECT_LE(miss_counters.prim_tests, 16u);
    }
  }
}

// `n` quads on the unit square (the same vertices, and every other one through another vertex
// with the same position), plus one quad below it at z = -1 that is no duplicate.
PolyMesh coincident_quads(uint32_t n) {
  PolyMesh m;
  m.positions = {{0, 0, 0},  {1, 0, 0},  {1, 1, 0},  {0, 1, 0}, {0, 1, 0},
                 {0, 0, -1}, {1, 0, -1}, {1, 1, -1}, {0, 1, -1}};
  const uint32_t faces[2][4] = {{0, 1, 2, 3}, {0, 1, 2, 4}};
  for (uint32_t i = 0; i < n; ++i) {
    m.face_sizes.push_back(4);
    m.face_indices.insert(m.face_indices.end(), faces[i % 2], faces[i % 2] + 4);
  }
  m.face_sizes.push_back(4);
  m.face_indices.insert(m.face_indices.end(), {5, 6, 7, 8});
  return m;
}

// The grid formats on a stack of coincident quads: with the leftovers as 2x2 sub-grids, the
// 1-cell grids with the same corners are one sub-grid (the lowest face kept), as the leftover
// triangles are; as triangles, the triangle formats' rule drops them. The quad below stays.
TEST(HostileOutputsStacks, GridFormatsTraceAQuadStackInBoundedTime) {
  const uint32_t n = 10000;
  const PolyMesh stack = coincident_quads(n);
  for (const ConfigInfo& c : configs()) {
    const Leaf leaf = c.options.leaf;
    if (leaf != Leaf::Grids && leaf != Leaf::LossyGrids && leaf != Leaf::SharedLossyGrids) continue;
    for (const GridLeftovers lo : {GridLeftovers::Auto, GridLeftovers::Grids}) {
      SCOPED_TRACE(c.name + (lo == GridLeftovers::Grids ? " --grid-leftovers grids" : ""));
      BuildOptions opt = c.options;
      opt.grid_leftovers = lo;
      const Scene s = Scene::build(stack, opt);
      expect_dropped_and_valid(s, double(2 * (n - 1)));
      TraversalCounters counters;
      const Hit h = down_from(s, 0.25f, 0.75f, counters);
      ASSERT_TRUE(h.valid());
      EXPECT_FLOAT_EQ(h.t, 1.0f);
      EXPECT_EQ(h.primID, 0u);
      EXPECT_LE(counters.prim_tests, 64u);
      Ray ray;  // below the stack: the quad at z = -1
      ray.org = {0.25f, 0.75f, -0.5f};
      ray.dir = {0, 0, -1};
      const Hit below = s.intersect(ray);
      ASSERT_TRUE(below.valid());
      EXPECT_EQ(below.primID, n);
    }
  }
}

// The CLI's summary line says that input was left out.
TEST(HostileOutputsStacks, CliSummaryShowsDroppedDuplicates) {
  TempDir d{"slim_outputs"};
  std::string obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 4 5 6\n";
  for (int i = 0; i < 1000; ++i) obj += "f 1 2 3\n";
  const std::string path = d.write("stack.obj", obj);
  for (const char* cmd : {"render", "build"}) {
    const std::string out = d.path(std::string(cmd) == "render" ? "s.png" : "s.slim");
    const std::string line = d.path("stdout.txt");
    const std::string run = std::string(SLIM_CLI_PATH) + " " + cmd + " " + path +
                            " --config bvh8-tri4v -o " + out + " >" + line + " 2>&1";
    const int status = std::system(run.c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0) << cmd;
    const std::string text = contents(line);
    EXPECT_NE(text.find("1001 triangles | left out: 999 duplicate triangles"), std::string::npos)
        << cmd << ": " << text;
  }
}

}  // namespace
