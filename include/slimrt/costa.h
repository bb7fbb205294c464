// Sizes of the Costa quantized n-gon mesh ("Fast Compression of Meshes for GPU Ray-Tracing",
// V. Costa, J. M. Pereira, J. A. Jorge; Tables 1 and 3) for `slimrt info --costa` and the
// benchmark. Scenes use the format through BuildOptions (geometry Quantized, costa letters).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "slimrt/decoded.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim {

struct CostaSizes {
  // The paper's regular data structure (Figures 2 and 6): prefix-summed primitive array
  // ((primitives + 1) x 4 B), face array (4 B per entry), float vertices (12 B each).
  uint64_t regular_bytes = 0;
  uint64_t triangulated_bytes = 0;       // the same after T (every primitive a triangle)
  uint64_t gzip_bytes = 0;               // gzip -9 (zlib, gzip wrapper) of the regular arrays
  uint64_t gzip_triangulated_bytes = 0;  // gzip -9 of the triangulated arrays
  // Store bytes of every combination of the letters T, P, F, V ("" = none, ..., "TPFV"), laid
  // out as a scene keeps them: primitives in BVH leaf order, the leaves ordered so that the
  // running primitive size stays near the linear prediction of P (Listing 2), vertices renumbered
  // so that the fan/strip flag of F costs no extra bit when the flagged vertices fit (see
  // src/api/scene_costa.cpp). A V scene's BVH is built over quantized positions and can order a
  // few primitives differently; stat_details(scene) lists the scene's own store bytes.
  // gzip_bytes compresses the regular arrays in the same order.
  std::map<std::string, uint64_t> combos;
  // The same with the primitives and vertices in input order, as the paper's Table 3 has them.
  std::map<std::string, uint64_t> input_order_combos;

  // Paper Table 1: the scene after loading (section 3.1) and after T.
  uint64_t vertices = 0, input_faces = 0, skipped_faces = 0;
  uint64_t primitives = 0, triangles = 0, quads = 0, fans = 0, strips = 0;
  uint64_t triangulated_primitives = 0;
  // Widths chosen by the packing (Listings 2 and 3).
  uint32_t prim_residual_bits = 0, prim_residual_bits_triangulated = 0;
  uint32_t face_bits = 0, face_bits_triangulated = 0;
  // Polygons of 5+ vertices: tessellated by GLU, or fanned (see src/mesh/tessellate.h).
  uint64_t tess_polygons = 0, tess_glu = 0, tess_fallbacks = 0;
};

// The 16 combinations in the paper's Table 3 order: "", "V", "F", "FV", "P", "PV", "PF", "PFV",
// then the same with a leading "T".
std::vector<std::string> costa_combinations();

// Loads the meshes as the paper does (triangles, quads as 4-vertex fans, GLU tessellation of
// larger polygons), then measures every combination. Throws slim::Error on malformed meshes.
CostaSizes costa_sizes(const std::vector<const PolyMesh*>& meshes);
CostaSizes costa_sizes(const PolyMesh& mesh);

// The triangles a costa configuration (BuildOptions with geometry Quantized, any letters, any
// Bvh) intersects, decoded from its store exactly as its leaves decode them, with the input face
// of each: to check the format against a reference run on its own geometry. Polygons of 5+ vertices
// are split by GLU's tessellator, not fanned, so even the lossless letters (no V) differ from a
// fan-triangulated reference on non-planar or concave n-gons. Throws slim::Error for other
// configurations and malformed meshes.
using CostaTriangles = DecodedTriangles;
CostaTriangles costa_triangles(const std::vector<const PolyMesh*>& meshes, const BuildOptions& opt);

}  // namespace slim
