// SIMD wrapper extensions used by the grid primitives (prim/subgrid.h, prim/lossy_subgrid.h):
// integer bit operations on vint8, float/int reinterpretation, table row gathers, lane permutes,
// two-half loads and a byte shuffle for unpacking 3-byte codes; and a small rank sort of 64-bit
// keys (mesh/pairing.cpp). Same rules as core/simd.h: raw intrinsics live here only, and the
// scalar path gives bit-identical results.
//
// Names are chosen so that they cannot collide with operators core/simd.h may add later.
#pragma once

#include <cstdint>
#include <cstring>

#include "core/simd.h"

namespace slim::simd {

#if defined(SLIM_SIMD_AVX2)

// 8 floats from two unaligned 4-float halves: lanes 0-3 from lo, lanes 4-7 from hi.
SLIM_INLINE vfloat8 load2x4(const float* lo, const float* hi) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(lo)), _mm_loadu_ps(hi), 1);
}
// Swaps the two 4-lane halves.
SLIM_INLINE vfloat8 swap_halves(vfloat8 a) { return _mm256_permute2f128_ps(a.v, a.v, 1); }
// The upper half of a, then the lower half of b: 8-wide [a4..a7 | b0..b3], 4-wide [a2 a3 | b0 b1].
SLIM_INLINE vfloat8 mid_halves(vfloat8 a, vfloat8 b) {
  return _mm256_permute2f128_ps(a.v, b.v, 0x21);
}
SLIM_INLINE vfloat4 mid_halves(vfloat4 a, vfloat4 b) {
  return _mm_shuffle_ps(a.v, b.v, _MM_SHUFFLE(1, 0, 3, 2));
}
// Lanes 0-3 and lanes 4-7 as 4-wide vectors; two 4-wide vectors as lanes 0-3 and 4-7.
SLIM_INLINE vfloat4 lower4(vfloat8 a) { return _mm256_castps256_ps128(a.v); }
SLIM_INLINE vfloat4 upper4(vfloat8 a) { return _mm256_extractf128_ps(a.v, 1); }
SLIM_INLINE vfloat8 combine4(vfloat4 lo, vfloat4 hi) {
  return _mm256_insertf128_ps(_mm256_castps128_ps256(lo.v), hi.v, 1);
}
// 4-wide integer helpers and rounding up (the SAH sweep of bvh/build.cpp).
SLIM_INLINE vint4 load4i(const uint32_t* p) { return _mm_loadu_si128((const __m128i*)p); }
SLIM_INLINE vint4 add4i(vint4 a, vint4 b) { return _mm_add_epi32(a.v, b.v); }
SLIM_INLINE vfloat4 to_float4(vint4 a) { return _mm_cvtepi32_ps(a.v); }
SLIM_INLINE vfloat4 ceil4(vfloat4 a) {
  return _mm_round_ps(a.v, _MM_FROUND_TO_POS_INF | _MM_FROUND_NO_EXC);
}
// Lanes 0-2 of a, b, c as columns: x = (a0, b0, c0, -), y = (a1, b1, c1, -), z = (a2, b2, c2, -).
SLIM_INLINE void transpose3(vfloat4 a, vfloat4 b, vfloat4 c, vfloat4& x, vfloat4& y, vfloat4& z) {
  const __m128 ab_lo = _mm_unpacklo_ps(a.v, b.v);  // a0 b0 a1 b1
  const __m128 ab_hi = _mm_unpackhi_ps(a.v, b.v);  // a2 b2 a3 b3
  const __m128 cc_lo = _mm_unpacklo_ps(c.v, c.v);  // c0 c0 c1 c1
  const __m128 cc_hi = _mm_unpackhi_ps(c.v, c.v);  // c2 c2 c3 c3
  x = _mm_movelh_ps(ab_lo, cc_lo);
  y = _mm_movehl_ps(cc_lo, ab_lo);
  z = _mm_movelh_ps(ab_hi, cc_hi);
}

SLIM_INLINE vint8 iand(vint8 a, vint8 b) { return _mm256_and_si256(a.v, b.v); }
SLIM_INLINE vint8 ior(vint8 a, vint8 b) { return _mm256_or_si256(a.v, b.v); }
SLIM_INLINE vint8 isub(vint8 a, vint8 b) { return _mm256_sub_epi32(a.v, b.v); }
template <int N>
SLIM_INLINE vint8 shr(vint8 a) {
  return _mm256_srli_epi32(a.v, N);
}
template <int N>
SLIM_INLINE vint8 shl(vint8 a) {
  return _mm256_slli_epi32(a.v, N);
}
SLIM_INLINE vbool8 ieq(vint8 a, vint8 b) {
  return _mm256_castsi256_ps(_mm256_cmpeq_epi32(a.v, b.v));
}
SLIM_INLINE vfloat8 as_float(vint8 a) { return _mm256_castsi256_ps(a.v); }
SLIM_INLINE vint8 as_int(vfloat8 a) { return _mm256_castps_si256(a.v); }
// m ? a : 0
SLIM_INLINE vfloat8 mask_zero(vbool8 m, vfloat8 a) { return _mm256_and_ps(m.m, a.v); }
// Lane i is true iff bit i of m is set.
SLIM_INLINE vbool8 lanes_from_bits(uint32_t m) {
  const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  return _mm256_castsi256_ps(
      _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(m)), bit), bit));
}
// Lane i of the result is lane idx[i] (0..7) of a.
SLIM_INLINE vfloat8 permute(vfloat8 a, vint8 idx) { return _mm256_permutevar8x32_ps(a.v, idx.v); }
// Rows table[idx[i]] of a table of (x, y, z, -) rows, transposed: lane i of x, y, z. Eight
// 16-byte loads and a 4x4 transpose per 128-bit half instead of three gathers.
SLIM_INLINE void gather_xyz(const float (*table)[4], vint8 idx, vfloat8& x, vfloat8& y,
                            vfloat8& z) {
  alignas(32) int32_t k[8];
  _mm256_store_si256((__m256i*)k, idx.v);
  auto rows = [&](int a, int b) {
    return _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_load_ps(table[k[a]])),
                                _mm_load_ps(table[k[b]]), 1);
  };
  const __m256 r04 = rows(0, 4), r15 = rows(1, 5), r26 = rows(2, 6), r37 = rows(3, 7);
  const __m256 lo01 = _mm256_unpacklo_ps(r04, r15);  // x0 x1 y0 y1 | x4 x5 y4 y5
  const __m256 lo23 = _mm256_unpacklo_ps(r26, r37);  // x2 x3 y2 y3 | x6 x7 y6 y7
  const __m256 hi01 = _mm256_unpackhi_ps(r04, r15);  // z0 z1 - - | z4 z5 - -
  const __m256 hi23 = _mm256_unpackhi_ps(r26, r37);  // z2 z3 - - | z6 z7 - -
  x = _mm256_shuffle_ps(lo01, lo23, 0x44);
  y = _mm256_shuffle_ps(lo01, lo23, 0xee);
  z = _mm256_shuffle_ps(hi01, hi23, 0x44);
}
// Byte shuffle: lanes 0-3 built from the 16 bytes at lo, lanes 4-7 from the 16 bytes at hi; ctrl
// byte b of each half selects source byte b & 15 of that half, or zero if b & 0x80 (pshufb).
SLIM_INLINE vint8 load_shuffle_2x16(const uint8_t* lo, const uint8_t* hi, const uint8_t* ctrl) {
  __m256i src = _mm256_inserti128_si256(_mm256_castsi128_si256(_mm_loadu_si128((const __m128i*)lo)),
                                        _mm_loadu_si128((const __m128i*)hi), 1);
  return _mm256_shuffle_epi8(src, _mm256_loadu_si256((const __m256i*)ctrl));
}

// Five interleaved points p[0..15) = x0 y0 z0 ... x4 y4 z4 -> lanes 0-4 of x, y, z (lanes 5-7
// repeat lanes of the same axis). Reads exactly the 15 floats.
SLIM_INLINE void load_xyz5(const float* p, vfloat8& x, vfloat8& y, vfloat8& z) {
  const __m256 a = _mm256_loadu_ps(p);      // x0 y0 z0 x1 y1 z1 x2 y2
  const __m256 b = _mm256_loadu_ps(p + 7);  // y2 z2 x3 y3 z3 x4 y4 z4
  const __m256i ix_a = _mm256_setr_epi32(0, 3, 6, 6, 6, 6, 6, 6);
  const __m256i ix_b = _mm256_setr_epi32(2, 2, 2, 2, 5, 5, 5, 5);
  const __m256i iy_a = _mm256_setr_epi32(1, 4, 7, 7, 7, 7, 7, 7);
  const __m256i iy_b = _mm256_setr_epi32(3, 3, 3, 3, 6, 6, 6, 6);
  const __m256i iz_a = _mm256_setr_epi32(2, 5, 5, 5, 5, 5, 5, 5);
  const __m256i iz_b = _mm256_setr_epi32(1, 1, 1, 4, 7, 7, 7, 7);
  // lanes 3-4 from b for x and y (0x18), lanes 2-4 for z (0x1c); lanes 5-7 from b too.
  x = _mm256_blend_ps(_mm256_permutevar8x32_ps(a, ix_a), _mm256_permutevar8x32_ps(b, ix_b), 0xf8);
  y = _mm256_blend_ps(_mm256_permutevar8x32_ps(a, iy_a), _mm256_permutevar8x32_ps(b, iy_b), 0xf8);
  z = _mm256_blend_ps(_mm256_permutevar8x32_ps(a, iz_a), _mm256_permutevar8x32_ps(b, iz_b), 0xfc);
}

// Sorts k <= 16 distinct 64-bit keys in[0, k) ascending into out[0, k) (out holds 16 entries):
// each key goes to its rank, the number of keys below it, by compares of all keys at once, with
// no branch on the keys (mesh/pairing.cpp's twin buckets, where an insertion sort mispredicts
// about once per key). Reads in[0, k) only.
SLIM_INLINE void rank_sort16(const uint64_t* in, size_t k, uint64_t* out) {
  const __m256i sign = _mm256_set1_epi64x(int64_t(uint64_t(1) << 63));
  const __m256i lane = _mm256_setr_epi64x(0, 1, 2, 3);
  const int nv = k <= 8 ? 2 : 4;
  __m256i v[4];
  for (int j = 0; j < nv; ++j) {
    // Lanes >= k: all ones (ranked after every key), others the key; biased for signed compares.
    // The masked load touches no lane >= k (the address is formed as an integer: it may lie
    // past the end of the keys).
    const __m256i live = _mm256_cmpgt_epi64(_mm256_set1_epi64x(int64_t(k) - 4 * j), lane);
    const auto* p = reinterpret_cast<const long long*>(reinterpret_cast<uintptr_t>(in) + 32 * j);
    const __m256i x = _mm256_maskload_epi64(p, live);
    v[j] =
        _mm256_xor_si256(_mm256_or_si256(x, _mm256_xor_si256(live, _mm256_set1_epi64x(-1))), sign);
  }
  for (size_t i = 0; i < k; ++i) {
    const __m256i b = _mm256_set1_epi64x(int64_t(in[i] ^ (uint64_t(1) << 63)));
    uint32_t below = 0;
    for (int j = 0; j < nv; ++j)
      below |= uint32_t(_mm256_movemask_pd(_mm256_castsi256_pd(_mm256_cmpgt_epi64(b, v[j]))))
               << (4 * j);
    out[__builtin_popcount(below)] = in[i];
  }
}

#else

SLIM_INLINE vfloat8 load2x4(const float* lo, const float* hi) {
  vfloat8 r;
  std::memcpy(r.v, lo, 16);
  std::memcpy(r.v + 4, hi, 16);
  return r;
}
SLIM_INLINE vfloat8 swap_halves(vfloat8 a) {
  vfloat8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = a.v[i ^ 4];
  return r;
}
SLIM_INLINE vfloat8 mid_halves(vfloat8 a, vfloat8 b) {
  vfloat8 r;
  for (int i = 0; i < 4; ++i) r.v[i] = a.v[i + 4], r.v[i + 4] = b.v[i];
  return r;
}
SLIM_INLINE vfloat4 mid_halves(vfloat4 a, vfloat4 b) {
  vfloat4 r;
  for (int i = 0; i < 2; ++i) r.v[i] = a.v[i + 2], r.v[i + 2] = b.v[i];
  return r;
}
SLIM_INLINE vfloat4 lower4(vfloat8 a) { return vfloat4::loadu(a.v); }
SLIM_INLINE vfloat4 upper4(vfloat8 a) { return vfloat4::loadu(a.v + 4); }
SLIM_INLINE vfloat8 combine4(vfloat4 lo, vfloat4 hi) {
  vfloat8 r;
  std::memcpy(r.v, lo.v, 16);
  std::memcpy(r.v + 4, hi.v, 16);
  return r;
}
SLIM_INLINE vint4 load4i(const uint32_t* p) {
  vint4 r;
  std::memcpy(r.v, p, 16);
  return r;
}
SLIM_INLINE vint4 add4i(vint4 a, vint4 b) {
  vint4 r;
  for (int i = 0; i < 4; ++i) r.v[i] = int32_t(uint32_t(a.v[i]) + uint32_t(b.v[i]));
  return r;
}
SLIM_INLINE vfloat4 to_float4(vint4 a) {
  vfloat4 r;
  for (int i = 0; i < 4; ++i) r.v[i] = float(a.v[i]);
  return r;
}
SLIM_INLINE vfloat4 ceil4(vfloat4 a) {
  vfloat4 r;
  for (int i = 0; i < 4; ++i) r.v[i] = std::ceil(a.v[i]);
  return r;
}
SLIM_INLINE void transpose3(vfloat4 a, vfloat4 b, vfloat4 c, vfloat4& x, vfloat4& y, vfloat4& z) {
  x = vfloat4(0.0f);
  y = vfloat4(0.0f);
  z = vfloat4(0.0f);
  const vfloat4* in[3] = {&a, &b, &c};
  for (int i = 0; i < 3; ++i) {
    x.v[i] = in[i]->v[0];
    y.v[i] = in[i]->v[1];
    z.v[i] = in[i]->v[2];
  }
}
SLIM_INLINE void load_xyz5(const float* p, vfloat8& x, vfloat8& y, vfloat8& z) {
  for (int i = 0; i < 8; ++i) {
    const int k = i < 5 ? i : 4;
    x.v[i] = p[3 * k];
    y.v[i] = p[3 * k + 1];
    z.v[i] = p[3 * k + 2];
  }
}

#define SLIM_EXT_IBINOP(name, op)                                                       \
  SLIM_INLINE vint8 name(vint8 a, vint8 b) {                                            \
    vint8 r;                                                                            \
    for (int i = 0; i < 8; ++i) r.v[i] = int32_t(uint32_t(a.v[i]) op uint32_t(b.v[i])); \
    return r;                                                                           \
  }
SLIM_EXT_IBINOP(iand, &)
SLIM_EXT_IBINOP(ior, |)
SLIM_EXT_IBINOP(isub, -)
#undef SLIM_EXT_IBINOP

template <int N>
SLIM_INLINE vint8 shr(vint8 a) {
  vint8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = int32_t(uint32_t(a.v[i]) >> N);
  return r;
}
template <int N>
SLIM_INLINE vint8 shl(vint8 a) {
  vint8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = int32_t(uint32_t(a.v[i]) << N);
  return r;
}
SLIM_INLINE vbool8 ieq(vint8 a, vint8 b) {
  vbool8 r;
  for (int i = 0; i < 8; ++i) r.bits |= uint32_t(a.v[i] == b.v[i]) << i;
  return r;
}
SLIM_INLINE vfloat8 as_float(vint8 a) {
  vfloat8 r;
  std::memcpy(r.v, a.v, 32);
  return r;
}
SLIM_INLINE vint8 as_int(vfloat8 a) {
  vint8 r;
  std::memcpy(r.v, a.v, 32);
  return r;
}
SLIM_INLINE vfloat8 mask_zero(vbool8 m, vfloat8 a) {
  vfloat8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = (m.bits >> i) & 1 ? a.v[i] : 0.0f;
  return r;
}
SLIM_INLINE vbool8 lanes_from_bits(uint32_t m) { return {m & 0xffu}; }
SLIM_INLINE vfloat8 permute(vfloat8 a, vint8 idx) {
  vfloat8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = a.v[idx.v[i] & 7];
  return r;
}
SLIM_INLINE void gather_xyz(const float (*table)[4], vint8 idx, vfloat8& x, vfloat8& y,
                            vfloat8& z) {
  for (int i = 0; i < 8; ++i) {
    x.v[i] = table[idx.v[i]][0];
    y.v[i] = table[idx.v[i]][1];
    z.v[i] = table[idx.v[i]][2];
  }
}
SLIM_INLINE vint8 load_shuffle_2x16(const uint8_t* lo, const uint8_t* hi, const uint8_t* ctrl) {
  uint8_t src[32], out[32];
  std::memcpy(src, lo, 16);
  std::memcpy(src + 16, hi, 16);
  for (int i = 0; i < 32; ++i) {
    const uint8_t c = ctrl[i];
    out[i] = (c & 0x80) ? 0 : src[(i & 16) + (c & 15)];
  }
  vint8 r;
  std::memcpy(r.v, out, 32);
  return r;
}

SLIM_INLINE void rank_sort16(const uint64_t* in, size_t k, uint64_t* out) {
  for (size_t i = 0; i < k; ++i) {
    uint32_t r = 0;
    for (size_t j = 0; j < k; ++j) r += in[j] < in[i];
    out[r] = in[i];
  }
}

#endif

}  // namespace slim::simd
