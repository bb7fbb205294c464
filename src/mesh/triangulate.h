// Fan triangulation of input meshes into one shared triangle array (the input of the triangle,
// pair and BVH-over-triangle formats). Faces with a NaN/Inf vertex are skipped and counted.
#pragma once

#include <cstdint>
#include <vector>

#include "slimrt/mesh.h"

namespace slim {

struct TriangleMesh {
  std::vector<Vec3f> vertices;     // all meshes' positions, concatenated (mesh g at vertex_base[g])
  std::vector<uint32_t> vertex_base;
  std::vector<uint32_t> tris;      // 3 indices into `vertices` per triangle
  std::vector<uint32_t> geom_ids;  // input mesh per triangle
  std::vector<uint32_t> prim_ids;  // input face per triangle
  uint64_t input_faces = 0;
  uint64_t skipped_faces = 0;      // faces with a non-finite vertex
  uint64_t input_triangles = 0;    // fan triangles of all input faces (skipped ones included)
  size_t tri_count() const { return geom_ids.size(); }
};

// Face (v0, v1, ..., vk) becomes (v0, v1, v2), (v0, v2, v3), ... Throws slim::Error if the
// meshes hold more than 2^32 - 1 vertices or triangles in total.
TriangleMesh triangulate_fan(const std::vector<const PolyMesh*>& meshes);

}  // namespace slim
