// The body of the glTF (JSON) and GLB targets (fuzz_gltf.cpp, fuzz_glb.cpp).
#pragma once

#include <cstdint>
#include <string_view>

#include "fuzz_common.h"
#include "io/gltf.h"

namespace slim::fuzz {

// External buffers (uri "x.bin" or "../../etc/passwd") resolve under a directory that does not
// exist, so a fuzzed file never reads a real file.
inline const char* kNoBaseDir = "/nonexistent-slimrt-fuzz-dir";

// Contract: slim::Error or a mesh passing check_mesh(). Round trip: a triangle mesh with finite
// positions, written as a one-node GLB (float3 positions, uint32 indices) and re-read, gives the
// same faces and the same position values.
inline int fuzz_gltf(const uint8_t* data, size_t size, bool binary) {
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  PolyMesh m;
  try {
    m = detail::read_gltf(binary ? "fuzz.glb" : "fuzz.gltf", in, binary, kNoBaseDir);
  } catch (const Error&) {
    return 0;
  }
  check_loaded(m);
  bool triangles = m.face_count() > 0;
  for (uint32_t n : m.face_sizes) triangles = triangles && n == 3;
  if (triangles && all_finite(m)) {
    PolyMesh r;
    try {
      r = detail::read_gltf("roundtrip.glb", write_glb(m), true, kNoBaseDir);
    } catch (const Error& e) {
      fail("re-reading the GLB written from a loaded mesh failed:", e.what());
    }
    check_same_geometry(m, r, "GLB round trip", -1);
  }
  return 0;
}

}  // namespace slim::fuzz
