// libFuzzer target: the OBJ reader (src/io/obj.h) on arbitrary bytes.
// Contract: slim::Error or a mesh passing check_mesh(). Round trip: a mesh with finite positions,
// written back as OBJ text (9 significant digits) and re-read, gives the same faces and the same
// positions within 1 ulp (tinyobjloader's number parser is not correctly rounded).
#include <cstdint>
#include <string_view>

#include "fuzz_common.h"
#include "io/obj.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace slim;
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  PolyMesh m;
  try {
    m = detail::read_obj("fuzz.obj", in);
  } catch (const Error&) {
    return 0;
  }
  fuzz::check_loaded(m);
  if (fuzz::all_finite(m)) {
    PolyMesh r;
    try {
      r = detail::read_obj("roundtrip.obj", fuzz::write_obj(m));
    } catch (const Error& e) {
      fuzz::fail("re-reading the OBJ written from a loaded mesh failed:", e.what());
    }
    fuzz::check_same_geometry(m, r, "OBJ round trip", 1);
  }
  return 0;
}
