// The triangles a format intersects, decoded exactly as its leaves decode them, each with the
// input face it stands for: the reference geometry for formats with their own geometry
// (ConfigInfo::own_geometry in slimrt/scene.h; decoded_triangles() in slimrt/analysis.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "slimrt/math.h"

namespace slim {

struct DecodedTriangles {
  std::vector<Vec3f> vertices;  // 3 per triangle
  std::vector<uint32_t> geom;   // input mesh of each triangle
  std::vector<uint32_t> face;   // input face of each triangle
  size_t size() const { return face.size(); }
};

}  // namespace slim
