// PLY reader (ascii, binary_little_endian, binary_big_endian).
#pragma once

#include <string>
#include <string_view>

#include "slimrt/mesh.h"

namespace slim::detail {

// Parses a whole PLY file held in memory: element "vertex" (x, y, z of any scalar type; optional
// nx/ny/nz and s/t, u/v or texture_u/texture_v, stored per vertex) and element "face" (a list
// property vertex_indices or vertex_index of any integer types). Other properties and elements are
// skipped. A file without a face element gives a mesh with 0 faces. `source` names the file in
// errors: "<source>:<line>: ..." for the header and ascii bodies, "<source>: byte N: ..." for
// binary bodies. Every count is checked against the bytes left before anything is allocated.
PolyMesh read_ply(const std::string& source, std::string_view data);

}  // namespace slim::detail
