// libFuzzer target: the PLY reader (src/io/ply.h: ascii, binary little and big endian) on
// arbitrary bytes. Contract: slim::Error or a mesh passing check_mesh(). Round trip: the mesh,
// written back as binary little-endian PLY and re-read, gives the same faces and the same
// position bits.
#include <cstdint>
#include <string_view>

#include "fuzz_common.h"
#include "io/ply.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace slim;
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  PolyMesh m;
  try {
    m = detail::read_ply("fuzz.ply", in);
  } catch (const Error&) {
    return 0;
  }
  fuzz::check_loaded(m);
  PolyMesh r;
  try {
    r = detail::read_ply("roundtrip.ply", fuzz::write_ply(m));
  } catch (const Error& e) {
    fuzz::fail("re-reading the PLY written from a loaded mesh failed:", e.what());
  }
  fuzz::check_same_geometry(m, r, "PLY round trip");
  return 0;
}
