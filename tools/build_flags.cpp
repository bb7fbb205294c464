// The command-line flags of BuildOptions (build_flags.h).
#include "build_flags.h"

#include <cstdlib>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "slimrt/error.h"

namespace slim::cli {

namespace {

// A flag whose value is one of `names`, each standing for an enum value: the parse fails with
// "--flag: VALUE not in {a,b,c}" for any other. `current` is the default shown.
template <class E>
void add_choice(CLI::App& app, const std::string& flag, E& field,
                const std::vector<std::pair<std::string, E>>& names, const std::string& help) {
  std::vector<std::string> keys;
  std::string current;
  for (const auto& [n, e] : names) {
    keys.push_back(n);
    if (e == field) current = n;
  }
  app.add_option_function<std::string>(
         flag,
         [&field, names](const std::string& v) {
           for (const auto& [n, e] : names)
             if (n == v) field = e;
         },
         help)
      ->check(CLI::IsMember(keys))
      ->default_str(current)
      ->group("Build options");
}

}  // namespace

void add_build_options(CLI::App& app, BuildOptions& tuning) {
  const char* group = "Build options";
  app.add_option("--threads", tuning.threads, "build (and trace) threads, 0 = all cores")
      ->check(CLI::Range(0, 4096))
      ->capture_default_str()
      ->group(group);
  add_choice(
      app, "--collapse", tuning.collapse,
      {{"auto", Collapse::Auto}, {"optimal", Collapse::Optimal}, {"slots", Collapse::Slots}},
      "how the binary BVH becomes 8-wide nodes: optimal (SAH-optimal descendants), slots "
      "(open the largest child until 8 slots are taken), auto (slots for the compressed-leaf "
      "BVH, optimal otherwise; for the clusters optimal counting a node's memory)");
  app.add_option("--grid-parts", tuning.grid_parts,
                 "grid formats under compressed-leaf nodes: multi-leaf children per sub-grid (1, 2 "
                 "or 4; 0 = 4 under compressed-leaf nodes, 1 otherwise)")
      ->check(CLI::IsMember({0, 1, 2, 4}))
      ->capture_default_str()
      ->group(group);
  add_choice(app, "--grid-leftovers", tuning.grid_leftovers,
             {{"auto", GridLeftovers::Auto},
              {"grids", GridLeftovers::Grids},
              {"triangles", GridLeftovers::Triangles}},
             "grid formats: where cells and triangles that form no grid go: grids (2x2 "
             "sub-grids), triangles (leaves of a second BVH), auto (whichever takes less memory)");
  app.add_option("--sah-bins", tuning.sah_bins, "binned SAH: bins per axis")
      ->check(CLI::Range(2, 64))
      ->capture_default_str()
      ->group(group);
  app.add_option("--max-leaf-size", tuning.max_leaf_size,
                 "triangles per leaf at most (pairs, grids and clusters use their own)")
      ->check(CLI::Range(1, 124))
      ->capture_default_str()
      ->group(group);
  app.add_option("--cluster-error", tuning.cluster_error,
                 "cluster: every vertex within this fraction of the box diagonal of its input "
                 "position (0 < E < 1)")
      ->check(CLI::Validator(
          [](const std::string& v) {
            const double e = std::strtod(v.c_str(), nullptr);
            return e > 0 && e < 1 ? std::string() : "Value " + v + " not in 0 < E < 1";
          },
          "0 < E < 1"))
      ->capture_default_str()
      ->group(group);
  // Flags: their default (on or off) is stated in the help text.
  PairingOptions& p = tuning.pairing_options;
  auto state = [](bool on) { return std::string(on ? " (default on)" : " (default off)"); };
  app.add_flag("--cluster-redivide", tuning.cluster_redivide,
               "clusters: divide two sibling clusters anew where that stores fewer vertices "
               "(smaller, builds longer)" +
                   state(tuning.cluster_redivide))
      ->group(group);
  app.add_flag("--pair-coordinate-keys", p.coordinate_keys,
               "pairs: key half-edges by edge midpoint and edge-box area instead of vertex "
               "indices (meshes whose vertices are not welded)" +
                   state(p.coordinate_keys))
      ->group(group);
  app.add_flag("--pair-weld", p.weld,
               "pairs: merge bit-identical vertex positions before pairing (geometry unchanged)" +
                   state(p.weld))
      ->group(group);
  app.add_flag("--pair-augment,!--no-pair-augment", p.augment,
               "pairs: re-pair along augmenting paths of length 3 after the greedy scan" +
                   state(p.augment))
      ->group(group);
  app.add_option("--pair-prescan", p.prescan_threshold,
                 "pairs: keep the input order when at least this fraction of the triangles pairs "
                 "in it (window 2); above 1 disables the pre-scan")
      ->check(CLI::Range(0.0, 2.0))
      ->capture_default_str()
      ->group(group);
}

BuildOptions build_options(const std::string& config, const BuildOptions& tuning) {
  BuildOptions o = BuildOptions::from_config(config, tuning);  // throws for an unknown name
  try {
    o.check();
  } catch (const Error& e) {
    throw Error("--config " + config + " with these build options: " + e.what());
  }
  return o;
}

}  // namespace slim::cli
