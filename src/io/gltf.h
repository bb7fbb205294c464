// glTF 2.0 reader (.gltf and .glb) through tinygltf; geometry only.
#pragma once

#include <string>
#include <string_view>

#include "slimrt/mesh.h"

namespace slim::detail {

// Parses a glTF 2.0 asset held in memory (`binary`: GLB container, else JSON text). External
// buffers are looked up relative to `base_dir`. The default scene (else scene 0, else every root
// node, else every mesh) is flattened with its node transforms (matrix or TRS); each mesh primitive
// instance becomes one object. Triangles, strips and fans become triangles; points and lines are
// skipped. Normals (NORMAL) and uvs (TEXCOORD_0) are stored per vertex when any primitive has
// them. Errors: "<source>:<line>: ..." for JSON syntax, "<source>: byte N: ..." for the GLB
// container, "<source>: <json path>: ..." (e.g. accessors[3]) for bad references and ranges.
PolyMesh read_gltf(const std::string& source, std::string_view data, bool binary,
                   const std::string& base_dir);

}  // namespace slim::detail
