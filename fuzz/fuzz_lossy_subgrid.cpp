// libFuzzer target: the lossy 5x5 sub-grid displacement codes (src/prim/lossy_subgrid.h,
// Benthin et al., "Ray Tracing Lossy Compressed Grid Primitives", section 4.1), both encodings.
//
// Input bytes:
//   [0]      bit 0: encoding 1 or 2; bits 1-2: res_x - 2; bits 3-4: res_y - 2 (2..5 vertices,
//            the decoder's contract: the encoder never writes other resolutions)
//   [1]      the scene's exponent bias, 5 + byte % 188 (displacement_bias() returns 5..192)
//   [2..49]  4 float corners, any finite bits (NaN/Inf read as 0: scenes skip such vertices)
//   [50..112] 63 bytes of displacement codes, any bits (escape codes included)
//   [113..]  the round-trip sub-grid: scale exponent, exact-vertex mask, 25 int16 x 3 vertices
// Checks:
//   1. decoding any codes: the SIMD decoder (decode_subgrid) gives, bit for bit, what the scalar
//      decode_vertex() gives for every non-escape position, flags exactly the escape codes, and
//      puts the patch corners at their exact floats;
//   2. round trip: encode_subgrid() of a sub-grid of finite vertices (scaled by 2^-20..2^20),
//      then decoding, gives the corners and the exact (escaped) vertices bit for bit, and every
//      other vertex within the bound the format promises for its displacement d from the bilinear
//      patch (spec_error below: Benthin et al. section 4.1, the same derivation as
//      tests/test_lossy_accuracy.cpp); the encoder is deterministic.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "fuzz_common.h"
#include "prim/lossy_subgrid.h"

namespace {

using namespace slim;

using fuzz::Reader;

bool same_or_nan(float a, float b) {
  return fuzz::same_bits(a, b) || (std::isnan(a) && std::isnan(b));
}

template <int kEnc>
void check_decoder(const Vec3f corner[4], const uint8_t* codes63, uint32_t rx, uint32_t ry,
                   int bias) {
  uint8_t displ[63 + 8] = {};  // 7 readable bytes must follow the codes
  std::memcpy(displ, codes63, 63);
  SubGridVerts w;
  alignas(32) uint32_t esc_codes[32] = {};
  const uint32_t esc = decode_subgrid<kEnc>(corner, displ, rx, ry, bias, w, esc_codes);
  for (uint32_t j = 0; j < ry; ++j)
    for (uint32_t i = 0; i < rx; ++i) {
      const int k = int(5 * j + i);
      const int slot = displ_position_slot(k);
      const uint32_t code = slot < 0 ? 0 : load_code(displ + 3 * slot);
      const bool is_escape = displ_exponent(code) == kDisplEscape;
      SLIM_FUZZ_CHECK(bool(esc >> k & 1) == is_escape,
                      "escape flag at position " + std::to_string(k));
      if (is_escape) {
        SLIM_FUZZ_CHECK(esc_codes[k] == code, "escape code");
        continue;
      }
      const Vec3f want = decode_vertex<kEnc>(patch_point(corner, i, j, rx, ry), code, bias);
      for (int a = 0; a < 3; ++a)
        SLIM_FUZZ_CHECK(same_or_nan(w.p[a][k], want[a]),
                        "SIMD and scalar decoders differ at position " + std::to_string(k) +
                            " axis " + std::to_string(a) + ": " + std::to_string(w.p[a][k]) +
                            " vs " + std::to_string(want[a]));
    }
  // The patch corners decode to themselves (lerp weights 0 and 1 are exact, code 0 adds +0).
  const int corner_pos[4] = {0, int(rx - 1), int(5 * (ry - 1)), int(5 * (ry - 1) + rx - 1)};
  for (int c = 0; c < 4; ++c) {
    const int k = corner_pos[c];
    const int slot = displ_position_slot(k);
    if (slot >= 0 && load_code(displ + 3 * slot) != 0) continue;  // an inner slot used as corner
    for (int a = 0; a < 3; ++a)
      SLIM_FUZZ_CHECK(same_or_nan(w.p[a][k], corner[c][a] + 0.0f), "corner " + std::to_string(c));
  }
}

// The error the format promises for a displacement d (computed here from the format's definition,
// not from the encoder), with the scene's exponent bias: lengths and scales are 2^(e + bias - 127)
// (encoding 2: 2^(e + bias - 132)) for the 6-bit exponent e = 1..62 (0: zero, 63: escape).
//   Encoding 1: a direction from 1024 first-octant unit vectors on 45 rings of an equal-area map
//     (at most 0.041 rad to the nearest entry) times a length with a 5-bit mantissa (relative
//     error <= 1/64): error <= 0.057 |d| < 0.06 |d|; below the smallest length 2^(1 + bias - 127)
//     the length may round to 0 or to it: plus that length.
//   Encoding 2: 5-bit magnitudes (0..31) of the smallest power-of-two scale s >= 2^(1 + bias - 132)
//     with 31.5 s >= the largest |d_a|, rounded to nearest: per component <= s / 2, so
//     <= sqrt(3) s / 2 in all (the encoder keeps the code nearest in distance, never farther).
template <int kEnc>
double spec_error(const Vec3f& target, const Vec3f& patch, int bias) {
  const double d[3] = {double(target.x) - patch.x, double(target.y) - patch.y,
                       double(target.z) - patch.z};
  const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if constexpr (kEnc == 1) {
    return 0.06 * len + std::ldexp(1.0, 1 + bias - 127);
  } else {
    const double dmax = std::max({std::fabs(d[0]), std::fabs(d[1]), std::fabs(d[2])});
    double s = std::ldexp(1.0, 1 + bias - 132);
    while (31.5 * s < dmax) s *= 2;
    return std::sqrt(3.0) * s / 2;
  }
}

template <int kEnc>
void check_round_trip(Reader& in, uint32_t rx, uint32_t ry) {
  SubGridInput s;
  s.res_x = rx;
  s.res_y = ry;
  const int exp = int(in.byte() % 41) - 20;
  uint32_t exact_mask = 0;
  in.bytes(&exact_mask, 4);
  Box3f box;
  for (int k = 0; k < 25; ++k) {
    int16_t q[3];
    in.bytes(q, sizeof q);
    s.v[k] = Vec3f(std::ldexp(float(q[0]), exp), std::ldexp(float(q[1]), exp),
                   std::ldexp(float(q[2]), exp));
    s.exact[k] = exact_mask >> k & 1 ? uint32_t(k) : kNotExact;
    if (uint32_t(k % 5) < rx && uint32_t(k / 5) < ry) box.extend(s.v[k]);
  }
  const int bias = displacement_bias(length(box.size()));
  uint8_t displ[63 + 8] = {}, again[63 + 8] = {};
  encode_subgrid<kEnc>(s, bias, displ);
  encode_subgrid<kEnc>(s, bias, again);
  SLIM_FUZZ_CHECK(std::memcmp(displ, again, 63) == 0, "the encoder is not deterministic");

  const Vec3f corner[4] = {s.v[0], s.v[rx - 1], s.v[5 * (ry - 1)], s.v[5 * (ry - 1) + rx - 1]};
  SubGridVerts w;
  alignas(32) uint32_t esc_codes[32] = {};
  const uint32_t esc = decode_subgrid<kEnc>(corner, displ, rx, ry, bias, w, esc_codes);
  apply_escapes(esc, esc_codes, s.v, w);  // exact-vertex array: vertex k at index k
  for (uint32_t j = 0; j < ry; ++j)
    for (uint32_t i = 0; i < rx; ++i) {
      const int k = int(5 * j + i);
      const Vec3f got(w.p[0][k], w.p[1][k], w.p[2][k]);
      const bool is_corner = (i == 0 || i == rx - 1) && (j == 0 || j == ry - 1);
      const std::string where = "position " + std::to_string(k) + " (encoding " +
                                std::to_string(kEnc) + ", 2^" + std::to_string(exp) + ")";
      if (is_corner || s.exact[k] != kNotExact) {
        SLIM_FUZZ_CHECK(got == s.v[k], "corner or exact vertex not kept at " + where);
        continue;
      }
      const Vec3f patch = patch_point(corner, i, j, rx, ry);
      const double d = length(s.v[k] - patch), err = length(got - s.v[k]);
      // Rounding of the patch and of the final add: a few ulps of the coordinates.
      const double slack = 4e-7 * (reduce_max(abs(s.v[k])) + reduce_max(abs(patch)));
      const double bound = spec_error<kEnc>(s.v[k], patch, bias);
      SLIM_FUZZ_CHECK(err <= bound + slack,
                      where + ": error " + std::to_string(err) + " above the format's bound " +
                          std::to_string(bound) + " for a displacement of " + std::to_string(d));
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader in{data, size};
  const uint8_t mode = in.byte();
  const int enc = mode & 1 ? 2 : 1;
  const uint32_t rx = 2 + (mode >> 1 & 3), ry = 2 + (mode >> 3 & 3);
  const int bias = 5 + in.byte() % 188;
  Vec3f corner[4];
  in.bytes(corner, sizeof corner);
  // Corners are finite in every scene (faces with a NaN/Inf vertex are skipped at build); the
  // decoder short-cuts position 24 to the corner, which only equals the patch for finite ones.
  for (Vec3f& c : corner)
    for (int a = 0; a < 3; ++a)
      if (!std::isfinite(c[a])) c[a] = 0.0f;
  uint8_t codes[63];
  in.bytes(codes, sizeof codes);
  if (enc == 1) {
    check_decoder<1>(corner, codes, rx, ry, bias);
    check_round_trip<1>(in, rx, ry);
  } else {
    check_decoder<2>(corner, codes, rx, ry, bias);
    check_round_trip<2>(in, rx, ry);
  }
  return 0;
}
