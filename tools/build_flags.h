// The command-line flags of BuildOptions, shared by `slimrt render`, `bench`, `verify`, `build`
// and `info`: one flag per tuning field (the fields a configuration name does not fix), each with
// its default in --help.
//
//   BuildOptions tuning;
//   add_build_options(app, tuning);                  // --threads, --collapse, --sah-bins, ...
//   app.parse(argc, argv);
//   BuildOptions opt = build_options(config, tuning);  // the row's format with that tuning
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "slimrt/scene.h"

namespace slim::cli {

// Adds to `app`, writing into `tuning` while it parses:
//   --threads N            threads (0 = all cores)
//   --collapse auto|optimal|slots
//   --grid-parts 0|1|2|4
//   --grid-leftovers auto|grids|triangles
//   --sah-bins 2..64
//   --max-leaf-size 1..124
//   --cluster-error E      (0 < E < 1)
//   --pair-coordinate-keys, --pair-weld, --no-pair-augment, --pair-prescan F (0..2)
// A value out of range or not among the choices makes the parse fail with a message naming the
// flag. The defaults shown are those of `tuning` when called (BuildOptions' own for a default
// BuildOptions).
void add_build_options(CLI::App& app, BuildOptions& tuning);

// BuildOptions::from_config(config, tuning), checked (BuildOptions::check): throws slim::Error
// naming the configuration for an unknown name or a tuning the configuration cannot take (e.g.
// --grid-parts 2 with nodes that have no multi-leaves).
BuildOptions build_options(const std::string& config, const BuildOptions& tuning);

}  // namespace slim::cli
