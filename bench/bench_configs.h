// What `slimrt bench` needs to know about a configuration name: the default list, whether the
// name exists, whether the format is lossy, and the geometry it intersects when it has its own
// (validated against Embree run on that geometry). Each property is one small function here,
// answered by the library's registry (find_config) and the built scene (decoded_triangles).
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "slimrt/analysis.h"

namespace slim::bench {

// Every Embree anchor, then every slimrt configuration (slim::all_config_names()).
std::vector<std::string> default_configs();
// Throws slim::Error naming the configuration if it is neither an Embree anchor nor a slimrt name.
void check_config_name(const std::string& name);
// The registry's lossy flag (lossy-grid*, costa-* with V); false for the Embree anchors.
bool is_lossy_config(const std::string& name);

// Formats that intersect other triangles than the input's fan triangulation: lossy grids, costa
// with V (quantized), costa's GLU tessellation of n-gons, the grid cells' diagonals. They are
// validated against Embree run on their own decoded geometry (the same triangles, so agreement
// measures the traversal, not the encoding), with hits mapped back to the input faces.
struct OwnGeometry {
  PolyMesh mesh;                     // one triangle per face
  std::vector<uint32_t> geom, face;  // per triangle: the input mesh and face it decodes
};
// The decoded triangles of a built scene of such a format (decoded_triangles(scene, meshes):
// from the built scene where it decodes its leaves); nullopt for every other configuration.
std::optional<OwnGeometry> own_geometry(const Scene& scene,
                                        const std::vector<const PolyMesh*>& meshes);

}  // namespace slim::bench
