// libFuzzer target: the GLB container + glTF reader (src/io/gltf.h, binary = true) on arbitrary
// bytes.
#include "fuzz_gltf_common.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return slim::fuzz::fuzz_gltf(data, size, true);
}
