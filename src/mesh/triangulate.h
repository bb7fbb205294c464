// Fan triangulation of input meshes into one shared triangle array (the input of the triangle,
// pair and BVH-over-triangle formats). Faces with a NaN/Inf vertex are skipped and counted.
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstdint>
#include <vector>

#include "core/large_array.h"
#include "mesh/mesh_list.h"
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
FaceChunks face_chunks(const MeshView& m);

// fn(chunk, f0, f1, corners) for each chunk of fc, in parallel (TBB): the chunk's faces are
// [f0, f1) and `corners` points at face f0's first corner in m.face_indices.
template <class Fn>
void for_each_face_chunk(const MeshView& m, const FaceChunks& fc, Fn&& fn) {
  tbb::parallel_for(size_t(0), fc.count(), [&](size_t ch) {
    const size_t f0 = ch * FaceChunks::kFaces;
    fn(ch, f0, std::min(m.face_sizes.size(), f0 + FaceChunks::kFaces),
       m.face_indices.data() + fc.corner[ch]);
  });
}

// Whether every corner idx[0 .. n) is a finite vertex (one byte per vertex, nonzero = finite).
inline bool face_finite(const uint8_t* finite, const uint32_t* idx, uint32_t n) {
  bool ok = true;
  for (uint32_t k = 0; k < n; ++k) ok = ok && finite[idx[k]];
  return ok;
}

// Face (v0, v1, ..., vk) becomes (v0, v1, v2), (v0, v2, v3), ... Throws slim::Error if the
// meshes hold more than 2^32 - 1 vertices or triangles in total. Runs in parallel (TBB), with the
// same output as a serial loop over the faces.
TriangleMesh triangulate_fan(const MeshList& meshes);

}  // namespace slim
