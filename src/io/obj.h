// Wavefront OBJ reader (tinyobjloader, polygons kept).
#pragma once

#include <string>
#include <string_view>

#include "slimrt/mesh.h"

namespace slim::detail {

// Parses a whole OBJ file held in memory: v, vn, vt and f lines (v, v/t, v//n, v/t/n, negative
// relative indices), polygons kept as authored. 'o'/'g' groups become objects (face_object +
// object_names; faces before the first group belong to object "default"). Corners without a normal
// or uv in a file that has them elsewhere point to an extra zero normal / zero uv. Materials are
// not read. A file without faces gives a mesh with 0 faces. Errors: "<source>:<line>: ...".
PolyMesh read_obj(const std::string& source, std::string_view data);

}  // namespace slim::detail
