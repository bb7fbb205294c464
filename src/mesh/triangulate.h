// Fan triangulation of input meshes into one shared triangle array (the input of the triangle,
// pair and BVH-over-triangle formats). Faces with a NaN/Inf vertex are skipped and counted.
#pragma once

#include <cstdint>
#include <vector>

#include "core/large_array.h"
#include "slimrt/mesh.h"

namespace slim {

struct TriangleMesh {
  LargeVector<Vec3f> vertices;  // all meshes' positions, concatenated (mesh g at vertex_base[g])
  std::vector<uint32_t> vertex_base;
  LargeVector<uint32_t> tris;      // 3 indices into `vertices` per triangle
  LargeVector<uint32_t> geom_ids;  // input mesh per triangle
  LargeVector<uint32_t> prim_ids;  // input face per triangle
  uint64_t input_faces = 0;
  uint64_t skipped_faces = 0;    // faces with a non-finite vertex
  uint64_t input_triangles = 0;  // fan triangles of all input faces (skipped ones included)
  size_t tri_count() const { return geom_ids.size(); }
};

// The faces of a mesh in chunks of kFaces, with each chunk's first corner (for loops over the
// faces in parallel). A mesh checked by check_mesh (face sizes add up to the corners).
struct FaceChunks {
  static constexpr size_t kFaces = 16384;
  std::vector<uint64_t> corner;  // corner[k] = first corner of chunk k; one more at the end
  size_t count() const { return corner.empty() ? 0 : corner.size() - 1; }
};
FaceChunks face_chunks(const PolyMesh& m);

// Face (v0, v1, ..., vk) becomes (v0, v1, v2), (v0, v2, v3), ... Throws slim::Error if the
// meshes hold more than 2^32 - 1 vertices or triangles in total. Runs in parallel (TBB), with the
// same output as a serial loop over the faces.
TriangleMesh triangulate_fan(const std::vector<const PolyMesh*>& meshes);

}  // namespace slim
