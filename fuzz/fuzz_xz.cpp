// libFuzzer target: the .xz layer (src/io/xz.h) on arbitrary bytes, then the reader the
// decompressed content looks like (PLY magic, GLB magic, JSON, else OBJ).
// Contract: slim::Error or a mesh passing check_mesh(). Round trip: the input bytes, compressed
// with liblzma (preset 0) and decompressed by slimrt, come back unchanged.
#include <cstdint>
#include <string>
#include <string_view>

#include <lzma.h>

#include "fuzz_common.h"
#include "io/gltf.h"
#include "io/obj.h"
#include "io/ply.h"
#include "io/xz.h"

namespace {

// xz preset 0 of `in` through one encoder kept for the whole run: liblzma reuses its buffers when
// a stream is re-initialised, which keeps the round trip cheap under ASan.
std::string compress(const std::string& in) {
  static lzma_stream strm = LZMA_STREAM_INIT;
  if (lzma_easy_encoder(&strm, 0, LZMA_CHECK_CRC64) != LZMA_OK) slim::fuzz::fail("lzma init");
  std::string out(lzma_stream_buffer_bound(in.size()), '\0');
  strm.next_in = reinterpret_cast<const uint8_t*>(in.data());
  strm.avail_in = in.size();
  strm.next_out = reinterpret_cast<uint8_t*>(out.data());
  strm.avail_out = out.size();
  if (lzma_code(&strm, LZMA_FINISH) != LZMA_STREAM_END) slim::fuzz::fail("lzma_code");
  out.resize(out.size() - strm.avail_out);
  return out;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace slim;
  const std::string raw(reinterpret_cast<const char*>(data), size);
  const std::string packed = compress(raw);
  std::string back;
  try {
    back = detail::xz_decompress("roundtrip.xz", packed.data(), packed.size());
  } catch (const Error& e) {
    fuzz::fail("decompressing liblzma's own output failed:", e.what());
  }
  SLIM_FUZZ_CHECK(back == raw, "xz round trip changed the bytes");

  std::string plain;
  try {
    plain = detail::xz_decompress("fuzz.xz", data, size);
  } catch (const Error&) {
    return 0;
  }
  const std::string_view p = plain;
  try {
    PolyMesh m;
    if (p.substr(0, 3) == "ply")
      m = detail::read_ply("fuzz.ply.xz", p);
    else if (p.substr(0, 4) == "glTF")
      m = detail::read_gltf("fuzz.glb.xz", p, true, "/nonexistent-slimrt-fuzz-dir");
    else if (p.find_first_not_of(" \t\r\n") != std::string_view::npos &&
             p[p.find_first_not_of(" \t\r\n")] == '{')
      m = detail::read_gltf("fuzz.gltf.xz", p, false, "/nonexistent-slimrt-fuzz-dir");
    else
      m = detail::read_obj("fuzz.obj.xz", p);
    fuzz::check_loaded(m);
  } catch (const Error&) {
  }
  return 0;
}
