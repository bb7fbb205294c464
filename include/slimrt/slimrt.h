// slimrt: compact CPU ray tracing of huge triangle and quad meshes. The user's API:
//
//   slim::PolyMesh mesh = slim::load("statue.ply");                     // slimrt/mesh.h
//   slim::Scene scene = slim::Scene::build(mesh, slim::BuildOptions::from_config("clbvh-compact"));
//   slim::Hit hit = scene.intersect({org, 0.0f, dir, slim::kInf});      // slimrt/ray.h
//   slim::MemoryStats m = scene.memory();                                // slimrt/scene.h
//
// Errors are slim::Error (slimrt/error.h); build progress and cancellation are in
// slimrt/progress.h. Measurement hooks (each format's own build figures, grid and pairing
// statistics, Costa sizes, the benchmark's path tracer and PSNR, a traversal that counts its work)
// are in slimrt/analysis.h.
#pragma once

#include "slimrt/error.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"
#include "slimrt/progress.h"
#include "slimrt/ray.h"
#include "slimrt/scene.h"
