// Compressed triangle clusters (configurations `cluster`, `cluster-lossless`).
#pragma once

#include <cstdint>
#include <vector>

#include "slimrt/decoded.h"
#include "slimrt/math.h"
#include "slimrt/mesh.h"
#include "slimrt/scene.h"

namespace slim {

// The triangles a cluster configuration intersects, decoded exactly as its traversal decodes them
// (one per input fan triangle, in triangulation order), with the input face of each: to check the
// lossy format against a reference run on its own decoded geometry. max_error: the largest
// |decoded - input| over the vertices (0 for cluster-lossless). Throws slim::Error for other
// configurations.
struct ClusterTriangles : DecodedTriangles {
  double max_error = 0;
};
ClusterTriangles cluster_triangles(const std::vector<const PolyMesh*>& meshes,
                                   const BuildOptions& opt);

// The faces of `mesh` in the order a scene of configuration `opt` (`cluster` or
// `cluster-lossless`) stores them: order[i] is the input face that comes i-th (the clusters in the
// BVH's depth-first leaf order, each cluster's triangles in their strip order; the faces the build
// drops, degenerate or with a NaN/Inf vertex, last, in input order). Builds the scene once.
// A primID is the input face, so every cluster stores its triangles' faces: in a scan's or a
// modelling tool's face order those take up to log2(faces) bits a triangle, in this order a few.
// reorder_faces(mesh, order) (slimrt/mesh.h) gives the mesh whose faces come in this order; its
// cluster scenes are smaller, with nearly the same clusters (docs/results.md, "Faces in the
// clusters' order"). A user who keeps data per face permutes it the same way: the reordered
// mesh's face i is the input's face order[i]. Throws slim::Error for other configurations.
std::vector<uint32_t> cluster_face_order(const MeshView& mesh, const BuildOptions& opt);
std::vector<uint32_t> cluster_face_order(const PolyMesh& mesh, const BuildOptions& opt);

}  // namespace slim
