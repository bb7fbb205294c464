// slimrt triangle pairing statistics (A. Aman, S. Fenney, "Fast Triangle Pairing for Ray
// Tracing", Imagination Technologies).
//
//   slim::PairingStats s = slim::pairing_stats(mesh);   // pairs the fan triangles of the mesh
//   printf("%.1f%% paired (window-2: %.1f%%) in %.3f s\n", 100 * s.paired_fraction,
//          100 * s.window2_paired_fraction, s.pairing_s);
//
// The pairing itself runs inside Scene::build for the `bvh8-pairs` / `clbvh-pairs` configurations
// (with BuildOptions::pairing_options); this header reports what it does.
#pragma once

#include <cstdint>
#include <vector>

#include "slimrt/mesh.h"
#include "slimrt/scene.h"  // PairingOptions

namespace slim {

struct PairingStats {
  uint64_t triangles = 0;      // fan triangles that were paired over (faces with NaN/Inf skipped)
  uint64_t pairs = 0;          // pairs formed (2 triangles each)
  uint64_t unpaired = 0;       // triangles left alone (triangles - 2 * pairs)
  double paired_fraction = 0;  // 2 * pairs / triangles, of the result used
  // The paper's "old" figure: in-order window N = 2. pair_triangles() leaves it NaN when its
  // pre-scan stopped early (once the threshold was out of reach: the heuristic runs);
  // pairing_stats() always measures it (outside pairing_s).
  double window2_paired_fraction = 0;
  double heuristic_paired_fraction = 0;  // the paper's greedy scan alone (also when skipped)
  bool prescan_skipped = false;          // input order already well paired: kept, heuristic not run
  double pairing_s = 0;  // wall time of the pairing used by Scene::build (one thread):
                         // weld (if any) + pre-scan + (unless skipped) table, sort, scan
  double weld_s = 0, prescan_s = 0, table_s = 0, sort_s = 0, scan_s = 0;  // its parts
  uint64_t half_edges = 0;         // half-edge records sorted (0 if the pre-scan skipped it)
  uint64_t nonmanifold_edges = 0;  // key runs of 3+ half-edges (edges of 3+ triangles)
  uint64_t welded_vertices = 0;    // vertices merged away by the weld step
  uint64_t augmented_pairs = 0;    // pairs gained by the augmenting-path pass
  double augment_s = 0;            // its time (part of pairing_s)
};

// Pairs the fan triangles of the mesh as Scene::build does (throws slim::Error on a malformed
// mesh, see check_mesh) and returns the figures. The heuristic is always run once for
// heuristic_paired_fraction; pairing_s times the path Scene::build takes.
PairingStats pairing_stats(const PolyMesh& mesh, const PairingOptions& opt = {});

// One triangle pair of the pairing as a quad, for renderers with quad primitives or dual-triangle
// units. The corners are in the order of Embree's RTC_GEOMETRY_TYPE_QUAD: triangle 0 is
// (v[0], v[1], v[3]) and triangle 1 is (v[2], v[3], v[1]), sharing the diagonal v[1]-v[3];
// triangle 0 keeps its input winding, triangle 1 keeps it when the mesh is consistently oriented.
// With weld or coordinate keys, v[1] and v[3] are the first triangle's vertex indices and the
// second triangle's shared corners map to them by position. A triangle left unpaired is (v[0],
// v[1], v[2], v[2]) (triangle 1 degenerate, face[1] = kInvalidID). face[h] is the input face of
// triangle h and fan[h] its fan triangle in that face (input corners 0, fan + 1, fan + 2);
// corner[h][k] is the quad corner (0..3) holding that fan triangle's corner k, so that a hit's
// weights can be returned for the input corners.
struct PairedQuad {
  uint32_t v[4];
  uint32_t face[2];
  uint32_t fan[2];
  uint8_t corner[2][3];
};

// The pairs and unpaired triangles Scene::build uses for bvh8-pairs (the fan triangles of the
// mesh paired with `opt`) as quads, pairs first (ascending by their first triangle), then the
// unpaired triangles. Vertex indices are the mesh's; faces with a NaN/Inf vertex are skipped.
// Throws slim::Error on a malformed mesh (check_mesh).
std::vector<PairedQuad> pair_quads(const PolyMesh& mesh, const PairingOptions& opt = {});

}  // namespace slim
