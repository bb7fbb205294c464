// Shared pieces of the libFuzzer targets (fuzz/*.cpp, built by cmake/fuzz.cmake, run by
// ./fuzz.sh): what a loaded mesh must satisfy, and re-encoders for the round-trip checks.
//
// The contract every loader target checks (README.md: untrusted input gets an error, never a
// crash): on any bytes the reader either throws slim::Error or returns a mesh that passes
// check_mesh(). Any other exception escapes LLVMFuzzerTestOneInput, and libFuzzer reports it as a
// crash; so do memory errors and undefined behaviour (the targets are built with ASan + UBSan),
// hangs (-timeout) and runaway allocations (-rss_limit_mb).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <string_view>

#include "seed_files.h"
#include "slimrt/error.h"
#include "slimrt/mesh.h"

namespace slim::fuzz {

// Stops the run with a message: libFuzzer saves the input as a crash artifact.
[[noreturn]] inline void fail(const char* what, const std::string& detail = "") {
  std::fprintf(stderr, "slimrt fuzz check failed: %s %s\n", what, detail.c_str());
  std::abort();
}
#define SLIM_FUZZ_CHECK(cond, detail)               \
  do {                                              \
    if (!(cond)) ::slim::fuzz::fail(#cond, detail); \
  } while (0)

// The fuzz input read byte by byte (the decoder and algorithm targets); zeros past its end.
struct Reader {
  const uint8_t* p;
  size_t n;
  uint8_t byte() { return n ? (--n, *p++) : 0; }
  void bytes(void* out, size_t k) {
    auto* o = static_cast<uint8_t*>(out);
    for (size_t i = 0; i < k; ++i) o[i] = byte();
  }
};

// A mesh a loader returned must pass check_mesh(); load() relies on it. The loaders document
// that every result does, so a slim::Error here is a failure too.
inline void check_loaded(const PolyMesh& m) {
  try {
    check_mesh(m);
  } catch (const Error& e) {
    fail("loader returned a mesh that fails check_mesh:", e.what());
  }
  SLIM_FUZZ_CHECK(m.face_object.empty() || m.face_object.size() == m.face_count(), "");
  uint64_t corners = 0;
  for (uint32_t n : m.face_sizes) corners += n;
  SLIM_FUZZ_CHECK(corners == m.face_indices.size(), "");
}

inline bool same_bits(float a, float b) { return std::memcmp(&a, &b, 4) == 0; }
inline bool all_finite(const PolyMesh& m) {
  for (const Vec3f& p : m.positions)
    if (!is_finite(p)) return false;
  return true;
}

// The same faces and positions: bit for bit (NaNs of any payload count as equal), or, with
// `ulps` > 0, within that many units in the last place (for text formats whose number parser is
// not correctly rounded), or, with `ulps` < 0, equal as values (-0 == +0).
inline bool close_floats(float x, float y, int ulps) {
  if (std::isnan(x) || std::isnan(y)) return std::isnan(x) && std::isnan(y);
  if (ulps < 0) return x == y;
  if (same_bits(x, y)) return true;
  if (ulps == 0 || std::signbit(x) != std::signbit(y)) return x == y;
  int32_t a, b;
  std::memcpy(&a, &x, 4);
  std::memcpy(&b, &y, 4);
  return std::abs(int64_t(a) - int64_t(b)) <= ulps;
}
inline void check_same_geometry(const PolyMesh& a, const PolyMesh& b, const char* what,
                                int ulps = 0) {
  SLIM_FUZZ_CHECK(a.positions.size() == b.positions.size(), what);
  SLIM_FUZZ_CHECK(a.face_sizes == b.face_sizes, what);
  SLIM_FUZZ_CHECK(a.face_indices == b.face_indices, what);
  for (size_t i = 0; i < a.positions.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const float x = a.positions[i][k], y = b.positions[i][k];
      SLIM_FUZZ_CHECK(close_floats(x, y, ulps), std::string(what) + ": vertex " +
                                                    std::to_string(i) + ": " + std::to_string(x) +
                                                    " vs " + std::to_string(y));
    }
}

// Binary little-endian PLY of the mesh's positions and faces (uint face sizes and indices):
// re-reading it must give back the same geometry (a lossless re-encode of what was parsed).
inline std::string write_ply(const PolyMesh& m) {
  std::string h =
      "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(m.positions.size()) +
      "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
      std::to_string(m.face_count()) + "\nproperty list uint uint vertex_indices\nend_header\n";
  seeds::ByteWriter w;
  for (const Vec3f& p : m.positions) w.put(p.x), w.put(p.y), w.put(p.z);
  size_t c = 0;
  for (uint32_t n : m.face_sizes) {
    w.put(n);
    for (uint32_t k = 0; k < n; ++k) w.put(m.face_indices[c++]);
  }
  return h + w.bytes;
}

// OBJ text of the mesh's positions and faces (positions printed with 9 significant digits, which
// identify a float). Only for finite positions: OBJ has no NaN/Inf literal that the reader takes.
inline std::string write_obj(const PolyMesh& m) {
  std::string s;
  char buf[96];
  for (const Vec3f& p : m.positions) {
    std::snprintf(buf, sizeof buf, "v %.9g %.9g %.9g\n", p.x, p.y, p.z);
    s += buf;
  }
  size_t c = 0;
  for (uint32_t n : m.face_sizes) {
    s += 'f';
    for (uint32_t k = 0; k < n; ++k) s += ' ' + std::to_string(m.face_indices[c++] + 1);
    s += '\n';
  }
  return s;
}

// GLB of a triangle mesh (every face size 3): one node, one primitive, float3 positions and
// uint32 indices in the BIN chunk.
inline std::string write_glb(const PolyMesh& m) {
  seeds::ByteWriter w;
  for (const Vec3f& p : m.positions) w.put(p.x), w.put(p.y), w.put(p.z);
  const size_t pos_bytes = w.bytes.size();
  for (uint32_t i : m.face_indices) w.put(i);
  const size_t idx_bytes = w.bytes.size() - pos_bytes;
  const std::string nv = std::to_string(m.positions.size()),
                    ni = std::to_string(m.face_indices.size());
  std::string prim = R"({"attributes": {"POSITION": 0})" +
                     std::string(m.face_indices.empty() ? "" : R"(, "indices": 1)") + "}";
  std::string json =
      R"({"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "scene": 0,
    "nodes": [{"mesh": 0}], "meshes": [{"primitives": [)" +
      prim + R"(]}],
    "accessors": [{"bufferView": 0, "componentType": 5126, "count": )" +
      nv + R"(, "type": "VEC3"}, {"bufferView": 1, "componentType": 5125, "count": )" + ni +
      R"(, "type": "SCALAR"}],
    "bufferViews": [{"buffer": 0, "byteLength": )" +
      std::to_string(pos_bytes) + R"(}, {"buffer": 0, "byteOffset": )" + std::to_string(pos_bytes) +
      R"(, "byteLength": )" + std::to_string(idx_bytes) + R"(}],
    "buffers": [{"byteLength": )" +
      std::to_string(w.bytes.size()) + "}]}";
  return seeds::glb_container(json, w.bytes);
}

}  // namespace slim::fuzz
