// Scene loading of the Costa quantized n-gon mesh: V. Costa, J. M. Pereira, J. A. Jorge, "Fast
// Compression of Meshes for GPU Ray-Tracing", WSCG 2013, section 3.1 "Scene Loading".
//
//   - a polygon of 3 vertices stays a triangle,
//   - a polygon of 4 vertices becomes a 4-vertex triangle fan (the "quad" primitive: triangles
//     (v0,v1,v2), (v0,v2,v3), the same diagonal as slimrt's fan triangulation),
//   - a polygon of 5 or more vertices goes through the GLU tessellator, which splits it into
//     triangles, triangle fans and triangle strips.
//
// The result is the paper's regular data structure (Figure 2) in its prefix-summed form (Figure 6,
// Listing 1): NgonMesh. prim/quantized_mesh.h compresses it.
#pragma once

#include <cstdint>
#include <vector>

#include "mesh/mesh_list.h"
#include "prim/quantized_mesh.h"
#include "slimrt/mesh.h"

namespace slim {

// ---- the GLU tessellator ----------------------------------------------------------------------

// One group of GLU's output: GL_TRIANGLES (a list, 3 indices per triangle), GL_TRIANGLE_FAN or
// GL_TRIANGLE_STRIP. `first`/`count` select Tessellation::indices.
enum class TessMode : uint8_t { Triangles, Fan, Strip };
struct TessGroup {
  TessMode mode;
  uint32_t first, count;
};

struct Tessellation {
  std::vector<TessGroup> groups;
  std::vector<uint32_t> indices;  // corner positions in the input polygon (0 .. n-1)
  bool fallback = false;          // GLU's output was rejected; `groups` is one fan (see below)
};

struct TessStats {
  uint64_t polygons = 0;               // polygons given to the tessellator (5+ vertices)
  uint64_t glu = 0;                    // tessellated by GLU
  uint64_t fallback_intersecting = 0;  // projection self-intersects (GLU asked for a new vertex)
  uint64_t fallback_degenerate = 0;    // zero Newell normal, GLU error, or empty output
  uint64_t fallback_area = 0;          // GLU output did not cover the projection exactly once
  uint64_t fallbacks() const { return fallback_intersecting + fallback_degenerate + fallback_area; }
};

// Newell's normal of a polygon (twice its vector area): exact for planar polygons, a robust
// average plane for non-planar ones. Computed in double.
void newell_normal(const Vec3f* positions, const uint32_t* idx, uint32_t n, double normal[3]);

// Projected-area check of a triangulation of a polygon (the tessellator's acceptance test and the
// tests' coverage check). Every triangle is projected onto the plane perpendicular to `normal`;
// the triangulation covers the projected polygon exactly once iff every triangle has a
// non-negative projected area and the areas add up to the polygon's (|normal| / 2). Returns the
// relative error max(|sum |a_t| - A|, |sum a_t - A|) / A (0 for a perfect cover; 1 when A = 0).
double projected_cover_error(const Vec3f* positions, const uint32_t* poly, uint32_t n,
                             const uint32_t* tris, uint64_t tri_count, const double normal[3]);

// Splits polygons with GLU's tessellator (gluNewTess; no GL context needed). One instance per
// thread (it owns a GLUtesselator).
//
// Non-planar and concave polygons: the polygon is projected onto the plane perpendicular to its
// Newell normal (the projected 2D coordinates are given to GLU, with gluTessNormal(0,0,1), so GLU
// tessellates exactly that projection) and GLU's winding rule ODD covers its inside once.
// COMBINE: GLU asks for a new vertex where the projected boundary crosses itself (or where two
// vertices coincide in the projection). We never add vertices to the mesh (the compressed store
// keeps the input vertex array, paper section 3.2): a combine at a point that is one of the
// polygon's own vertices in 3D (coincident vertices) reuses that vertex; any other combine
// rejects GLU's output for this polygon and the polygon becomes a plain fan (v0, v1, ..., vk),
// which is exactly how every other slimrt format triangulates it. The same fallback applies to
// polygons with a zero Newell normal, to GLU errors, and to any output whose projected triangles
// do not cover the projected polygon exactly once (projected_cover_error > 1e-4).
class PolygonTessellator {
 public:
  PolygonTessellator();
  ~PolygonTessellator();
  PolygonTessellator(const PolygonTessellator&) = delete;
  PolygonTessellator& operator=(const PolygonTessellator&) = delete;

  // Tessellates the polygon positions[idx[0..n)] (n >= 3). Indices in `out` are corner positions
  // 0..n-1 of the polygon. Updates stats.
  void tessellate(const Vec3f* positions, const uint32_t* idx, uint32_t n, Tessellation& out,
                  TessStats& stats);

  struct Impl;

 private:
  Impl* impl_;
};

// ---- the regular data structure (paper Figures 2 and 6) -----------------------------------------

// Primitive i has vertices faces[prim_offsets[i] .. prim_offsets[i+1]). For a primitive of 5+
// vertices, its first face entry is (vertex << 1) | flag, flag 0 = fan, 1 = strip (paper section
// 3.2: "shifted to the left one bit to accommodate a flag"); all other entries are plain vertex
// indices. Primitives of all input meshes are concatenated; their vertex indices point into
// `vertices` (the meshes' position arrays, concatenated, as loaded).
struct NgonMesh {
  std::vector<Vec3f> vertices;
  std::vector<uint32_t> prim_offsets;  // prim_count() + 1 prefix sums (Listing 1)
  std::vector<uint32_t> faces;
  std::vector<uint32_t> prim_face;  // input face of each primitive, as a global face id
  std::vector<uint32_t> face_base;  // global id of mesh g's first face; mesh_count() + 1 entries

  // Statistics of the loading (paper Table 1).
  uint64_t input_faces = 0;
  uint64_t skipped_faces = 0;    // faces with a non-finite vertex (not stored)
  uint64_t input_triangles = 0;  // fan triangles of all input faces (skipped included)
  uint64_t triangles = 0, quads = 0, fans = 0, strips = 0;  // primitives by kind
  TessStats tess;

  size_t prim_count() const { return prim_offsets.empty() ? 0 : prim_offsets.size() - 1; }
  size_t mesh_count() const { return face_base.empty() ? 0 : face_base.size() - 1; }
  uint32_t prim_size(size_t i) const { return prim_offsets[i + 1] - prim_offsets[i]; }
  // Triangles the primitives hold (a primitive of k vertices holds k - 2).
  uint64_t triangle_count() const { return faces.size() - 2 * uint64_t(prim_count()); }
  // The arrays the Costa store encodes (prim/quantized_mesh.h).
  operator NgonArrays() const { return {vertices, prim_offsets, faces}; }
};

// Loads the meshes as the paper's section 3.1 does (see the top of this file). Faces with a
// non-finite vertex are skipped and counted. Throws slim::Error if the scene exceeds 2^31 - 1
// vertices or face entries (the face array stores vertex << 1 | flag in 32 bits).
NgonMesh load_ngon_mesh(const MeshList& meshes);

// Option T of the paper: every primitive becomes its triangles (fans (c, v_j, v_j+1); strips
// keep their orientation: odd triangles are (v_t+1, v_t, v_t+2)), one triangle primitive each.
NgonMesh triangulate_ngon_mesh(const NgonMesh& mesh);

// Renumbers the vertices (a permutation: every vertex is kept, positions unchanged) so that the
// vertices stored shifted left by the fan/strip flag (first entries of 5+-vertex primitives) get
// the lowest numbers, and all others follow in order of first use in the face array (unused
// vertices last). PACKFACES (Listing 3) then needs one bit for the flag only when a flagged vertex
// number does not fit in the width of the plain ones; the order of first use also keeps the
// vertices of neighbouring primitives near in memory.
void renumber_vertices(NgonMesh& mesh);

// Appends the triangles of primitive i (3 vertex indices each, in the order the leaf tests them)
// to `tris`. The triangulation rules of all primitive kinds, in one place.
void primitive_triangles(const NgonMesh& mesh, size_t i, std::vector<uint32_t>& tris);

}  // namespace slim
