// The command-line flags of BuildOptions (tools/build_flags.h): each flag reaches its field, a
// value out of range is refused with a message naming the flag, a configuration name plus the
// tuning gives the options, and every command that builds offers the flags.
#include <gtest/gtest.h>

#include <array>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "build_flags.h"
#include "slimrt/clusters.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"
#include "temp_dir.h"

using namespace slim;

namespace {

// Parses `args` (after the program name) into a fresh BuildOptions.
BuildOptions parse(std::vector<std::string> args) {
  CLI::App app{"test"};
  BuildOptions tuning;
  cli::add_build_options(app, tuning);
  std::vector<const char*> argv = {"test"};
  for (const std::string& a : args) argv.push_back(a.c_str());
  app.parse(int(argv.size()), argv.data());
  return tuning;
}

// The message of the parse error of `args`, or "" when they parse.
std::string parse_error(std::vector<std::string> args) {
  try {
    parse(std::move(args));
  } catch (const CLI::ParseError& e) {
    return e.what();
  }
  return "";
}

// Standard output and error of a shell command.
std::string run(const std::string& cmd) {
  std::string out;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return out;
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), p)) out.append(buf.data(), n);
  pclose(p);
  return out;
}

}  // namespace

TEST(BuildFlags, EachFlagReachesItsField) {
  const BuildOptions d;
  const BuildOptions none = parse({});
  EXPECT_EQ(none.threads, d.threads);
  EXPECT_EQ(none.collapse, d.collapse);
  EXPECT_EQ(none.grid_parts, d.grid_parts);
  EXPECT_EQ(none.grid_leftovers, d.grid_leftovers);
  EXPECT_EQ(none.sah_bins, d.sah_bins);
  EXPECT_EQ(none.max_leaf_size, d.max_leaf_size);
  EXPECT_EQ(none.cluster_error, d.cluster_error);
  EXPECT_EQ(none.pairing_options.coordinate_keys, d.pairing_options.coordinate_keys);
  EXPECT_EQ(none.pairing_options.weld, d.pairing_options.weld);
  EXPECT_EQ(none.pairing_options.augment, d.pairing_options.augment);
  EXPECT_EQ(none.pairing_options.prescan_threshold, d.pairing_options.prescan_threshold);

  const BuildOptions o = parse(
      {"--threads", "3", "--collapse", "slots", "--grid-parts", "2", "--grid-leftovers",
       "triangles", "--sah-bins", "16", "--max-leaf-size", "7", "--cluster-error", "0.001",
       "--pair-coordinate-keys", "--pair-weld", "--no-pair-augment", "--pair-prescan", "1.5"});
  EXPECT_EQ(o.threads, 3);
  EXPECT_EQ(o.collapse, Collapse::Slots);
  EXPECT_EQ(o.grid_parts, 2);
  EXPECT_EQ(o.grid_leftovers, GridLeftovers::Triangles);
  EXPECT_EQ(o.sah_bins, 16);
  EXPECT_EQ(o.max_leaf_size, 7);
  EXPECT_EQ(o.cluster_error, 0.001);
  EXPECT_TRUE(o.pairing_options.coordinate_keys);
  EXPECT_TRUE(o.pairing_options.weld);
  EXPECT_FALSE(o.pairing_options.augment);
  EXPECT_EQ(o.pairing_options.prescan_threshold, 1.5);
  // The format fields are the configuration's, never a flag's.
  EXPECT_EQ(o.nodes, d.nodes);
  EXPECT_EQ(o.leaf, d.leaf);

  EXPECT_EQ(parse({"--collapse", "optimal"}).collapse, Collapse::Optimal);
  EXPECT_EQ(parse({"--collapse", "auto"}).collapse, Collapse::Auto);
  EXPECT_EQ(parse({"--grid-leftovers", "grids"}).grid_leftovers, GridLeftovers::Grids);
  EXPECT_TRUE(parse({"--pair-augment"}).pairing_options.augment);
}

TEST(BuildFlags, InvalidValuesAreRefusedNamingTheFlag) {
  const std::vector<std::vector<std::string>> bad = {
      {"--threads", "-1"},        {"--collapse", "best"},     {"--grid-parts", "3"},
      {"--grid-leftovers", "no"}, {"--sah-bins", "1"},        {"--sah-bins", "65"},
      {"--sah-bins", "many"},     {"--max-leaf-size", "0"},   {"--cluster-error", "0"},
      {"--cluster-error", "1.5"}, {"--pair-prescan", "-0.1"}, {"--max-leaf-size", "1000"},
  };
  for (const auto& args : bad) {
    const std::string what = parse_error(args);
    EXPECT_NE(what.find(args[0]), std::string::npos) << args[0] << " " << args[1] << ": " << what;
  }
}

TEST(BuildFlags, HelpShowsEachDefault) {
  CLI::App app{"test"};
  BuildOptions tuning;
  cli::add_build_options(app, tuning);
  const BuildOptions d;
  EXPECT_EQ(app.get_option("--collapse")->get_default_str(), "auto");
  EXPECT_EQ(app.get_option("--grid-leftovers")->get_default_str(), "auto");
  EXPECT_EQ(app.get_option("--sah-bins")->get_default_str(), std::to_string(d.sah_bins));
  EXPECT_EQ(app.get_option("--max-leaf-size")->get_default_str(), std::to_string(d.max_leaf_size));
  EXPECT_EQ(app.get_option("--grid-parts")->get_default_str(), std::to_string(d.grid_parts));
  EXPECT_EQ(app.get_option("--threads")->get_default_str(), std::to_string(d.threads));
  for (const char* f : {"--cluster-error", "--pair-prescan"})
    EXPECT_FALSE(app.get_option(f)->get_default_str().empty()) << f;
  // The flags state theirs in their help text.
  EXPECT_NE(app.get_option("--pair-weld")->get_description().find("(default off)"),
            std::string::npos);
  EXPECT_NE(app.get_option("--pair-coordinate-keys")->get_description().find("(default off)"),
            std::string::npos);
  EXPECT_NE(app.get_option("--pair-augment")->get_description().find("(default on)"),
            std::string::npos);
  const std::string help = app.help();
  for (const char* f : {"--threads", "--collapse", "--grid-parts", "--grid-leftovers", "--sah-bins",
                        "--max-leaf-size", "--cluster-error", "--pair-coordinate-keys",
                        "--pair-weld", "--pair-augment", "--pair-prescan"})
    EXPECT_NE(help.find(f), std::string::npos) << f;
}

TEST(BuildFlags, ConfigNamePlusTuningGivesTheOptions) {
  BuildOptions tuning = parse({"--sah-bins", "8", "--collapse", "optimal", "--threads", "2"});
  tuning.leaf = Leaf::Costa;  // format fields of the tuning are ignored
  tuning.grid_encoding = GridEncoding::SharedExponent;
  for (const ConfigInfo& c : configs()) {
    SCOPED_TRACE(c.name);
    const BuildOptions o = BuildOptions::from_config(c.name, tuning);
    EXPECT_EQ(o.config_name(), c.name);
    EXPECT_EQ(o.nodes, c.options.nodes);
    EXPECT_EQ(o.leaf, c.options.leaf);
    EXPECT_EQ(o.grid_encoding, c.options.grid_encoding);
    EXPECT_EQ(o.costa, c.options.costa);
    EXPECT_EQ(o.pairing, c.options.pairing);
    EXPECT_EQ(o.sah_bins, 8);
    EXPECT_EQ(o.collapse, Collapse::Optimal);
    EXPECT_EQ(o.threads, 2);
  }
  EXPECT_THROW(BuildOptions::from_config("no-such-config", tuning), Error);
  // A tuning the configuration cannot take: refused, naming the configuration.
  tuning.grid_parts = 2;
  EXPECT_NO_THROW(cli::build_options("lossy-grid", tuning));
  try {
    cli::build_options("bvh8-tri4v", tuning);
    ADD_FAILURE() << "grid parts above 1 need compressed-leaf nodes";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bvh8-tri4v"), std::string::npos) << e.what();
  }
}

// Every command that builds a scene offers the flags and refuses a bad value naming the flag.
TEST(BuildFlags, EveryCommandTakesThem) {
  const std::string cli = SLIM_CLI_PATH;
  const std::vector<std::pair<std::string, std::string>> commands = {
      {"render", " -o never.png"}, {"bench", ""}, {"verify", ""},
      {"build", " -o never.slim"}, {"info", ""},  {"reorder", " never.obj"}};
  for (const auto& [cmd, out] : commands) {
    SCOPED_TRACE(cmd);
    const std::string help = run(cli + " " + cmd + " --help");
    for (const char* f :
         {"--threads", "--collapse", "--grid-parts", "--grid-leftovers", "--sah-bins",
          "--max-leaf-size", "--cluster-error", "--pair-weld", "--pair-prescan"})
      EXPECT_NE(help.find(f), std::string::npos) << f;
    const std::string bad = run(cli + " " + cmd + " terrain:4 --sah-bins 99" + out);
    EXPECT_NE(bad.find("--sah-bins"), std::string::npos) << bad;
  }
}

// `slimrt reorder`: the mesh with its faces in the clusters' order and the order file, whose line
// i is the input face that became face i; the input is never the output.
TEST(ReorderCli, WritesTheMeshAndTheOrder) {
  const std::string cli = SLIM_CLI_PATH;
  slim::test::TempDir d{"slimrt_reorder"};
  const std::string obj = d.dir() + "/t.obj", order = d.dir() + "/t.order";
  const std::string out = run(cli + " reorder torus:16 " + obj + " --order " + order);
  EXPECT_NE(out.find("128 faces"), std::string::npos) << out;
  const slim::PolyMesh in = slim::load("torus:16"), r = slim::load(obj);
  ASSERT_EQ(r.face_count(), in.face_count());
  EXPECT_EQ(r.positions, in.positions);
  std::vector<uint32_t> o;
  FILE* f = std::fopen(order.c_str(), "r");
  ASSERT_TRUE(f);
  for (unsigned x; std::fscanf(f, "%u", &x) == 1;) o.push_back(x);
  std::fclose(f);
  EXPECT_EQ(o, slim::cluster_face_order(in, slim::BuildOptions::from_config("cluster")));
  ASSERT_EQ(o.size(), in.face_count());
  const std::vector<uint64_t> ri = r.face_offsets(), ii = in.face_offsets();
  for (size_t i = 0; i < o.size(); ++i) {
    ASSERT_LT(o[i], in.face_count());
    ASSERT_EQ(r.face_sizes[i], in.face_sizes[o[i]]);
    for (uint32_t k = 0; k < r.face_sizes[i]; ++k)
      ASSERT_EQ(r.face_indices[ri[i] + k], in.face_indices[ii[o[i]] + k]) << i;
  }
  // The input as the output, the order as the output, another format, another configuration.
  const std::string before = run("cat " + obj);
  EXPECT_NE(run(cli + " reorder " + obj + " " + obj).find("is the input"), std::string::npos);
  EXPECT_EQ(run("cat " + obj), before);
  EXPECT_NE(run(cli + " reorder torus:16 " + obj + " --order " + obj).find("is the output"),
            std::string::npos);
  const std::string fresh = d.dir() + "/fresh.obj";
  EXPECT_NE(run(cli + " reorder torus:16 " + fresh + " --order " + d.dir() + "/./fresh.obj")
                .find("is the output"),
            std::string::npos);
  EXPECT_NE(run(cli + " reorder torus:16 " + d.dir() + "/t.ply").find("FILE.obj"),
            std::string::npos);
  EXPECT_NE(run(cli + " reorder torus:16 " + obj + " --config bvh8-tri4v")
                .find("reorder takes cluster or cluster-lossless"),
            std::string::npos);
}
