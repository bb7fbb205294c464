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

}  // namespace slim
