// libFuzzer target: Scene::open of arbitrary bytes as a scene file (src/api/scene_file.cpp), then
// a few rays traced through what opened.
//
// Each input is written to a file of its own process and opened three times: with the section
// checksums (the default: damaged bytes must give slim::Error); without them and with the
// structure check (OpenOptions::check_structure); and the same after the header checksum (always
// verified) was recomputed over the input, so that the fuzzer gets past both checksums to the
// header fields, the section table, the records and the node and leaf data. Checks (README.md
// "Scene files"):
//   - open either succeeds or throws slim::Error naming the file;
//   - an opened scene traces rays through its bounds without memory errors, undefined behaviour
//     or hangs, and every hit has tnear <= t <= tfar.
// The seeds (fuzz/make_seeds.cpp) are small scene files of every configuration of the registry
// (the structure check covers them all) and of joined scenes.
#include <unistd.h>
#include <xxhash.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "slimrt/error.h"
#include "slimrt/scene.h"

namespace {

using namespace slim;

const std::string& path() {
  static const std::string p =
      "/tmp/slimrt_fuzz_scene_file_" + std::to_string(::getpid()) + ".slim";
  return p;
}

void trace(const Scene& s) {
  const Box3f b = s.bounds();
  Vec3f c(0, 0, 0), e(1, 1, 1);
  if (!b.empty() && std::isfinite(b.lo.x + b.lo.y + b.lo.z + b.hi.x + b.hi.y + b.hi.z)) {
    c = (b.lo + b.hi) * 0.5f;
    e = b.hi - b.lo;
  }
  for (int i = 0; i < 16; ++i) {
    Ray r;
    const float a = float(i) * 0.7f;
    r.org = c + Vec3f(e.x * std::cos(a), e.y * std::sin(a), e.z * (0.5f + 0.1f * float(i)));
    r.dir = c - r.org + Vec3f(0.01f * float(i), -0.02f * float(i), 0.003f);
    const Hit h = s.intersect(r);
    if (h.valid()) SLIM_FUZZ_CHECK(h.t >= r.tnear && h.t <= r.tfar, "hit outside [tnear, tfar]");
    (void)s.occluded(r);
  }
}

// The input with its header checksum recomputed (scene_file.cpp: header_bytes at 24, the
// checksum at 32 over [0, header_bytes) with itself zeroed), when the header fits.
std::vector<uint8_t> with_header_checksum(const uint8_t* data, size_t size) {
  std::vector<uint8_t> b(data, data + size);
  if (size < 512) return b;
  uint64_t hb;
  std::memcpy(&hb, b.data() + 24, 8);
  if (hb < 512 || hb > size) return b;
  std::memset(b.data() + 32, 0, 8);
  const uint64_t sum = XXH3_64bits(b.data(), hb);
  std::memcpy(b.data() + 32, &sum, 8);
  return b;
}

void write(const uint8_t* data, size_t size) {
  FILE* f = std::fopen(path().c_str(), "wb");
  if (!f) return;
  if (size) std::fwrite(data, 1, size, f);
  std::fclose(f);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  for (int mode = 0; mode < 3; ++mode) {
    if (mode == 0) write(data, size);
    if (mode == 2) {
      const std::vector<uint8_t> b = with_header_checksum(data, size);
      write(b.data(), b.size());
    }
    OpenOptions o;
    o.verify_checksums = mode == 0;
    o.check_structure = mode >= 1;
    try {
      const Scene s = Scene::open(path(), o);
      trace(s);
    } catch (const Error& e) {
      SLIM_FUZZ_CHECK(std::string(e.what()).find(path()) != std::string::npos,
                      std::string("error without the file name: ") + e.what());
    }
  }
  std::remove(path().c_str());  // none left in /tmp when the fuzzer stops between inputs
  return 0;
}
