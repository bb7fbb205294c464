// SIMD wrappers: vfloat4/vfloat8, vint8, vbool4/vbool8 (Embree's grammar of names).
// The instruction set is chosen here and only here, from the SLIM_ISA_* macro that CMake sets
// (option SLIM_ISA=avx2|avx512|scalar). Raw intrinsics appear in no other file.
// The scalar path implements every operation with plain loops (std::fma for the fused ops, so
// that both paths give bit-identical results where the watertight test depends on it).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "slimrt/math.h"

#if defined(SLIM_ISA_AVX2) && !defined(SLIM_ISA_SCALAR)
#define SLIM_SIMD_AVX2 1
#include <immintrin.h>
#else
#define SLIM_SIMD_SCALAR 1
#endif

namespace slim::simd {

// Name of the compiled SIMD path, for reports ("avx2", "avx512", "scalar").
inline const char* isa_name() {
#if defined(SLIM_ISA_AVX512)
  return "avx512";
#elif defined(SLIM_SIMD_AVX2)
  return "avx2";
#else
  return "scalar";
#endif
}

SLIM_INLINE int popcount(uint32_t x) { return __builtin_popcount(x); }
SLIM_INLINE int ctz(uint32_t x) { return __builtin_ctz(x); }
// Clears the lowest set bit and returns its index.
SLIM_INLINE int pop_lowest(uint32_t& m) {
  int i = __builtin_ctz(m);
  m &= m - 1;
  return i;
}

SLIM_INLINE void prefetch(const void* p) { __builtin_prefetch(p, 0, 3); }

// The index of the set bit of rank k (k = 0: the lowest) of x, which has more than k set bits.
// BMI2 (with the AVX2 path): one deposit of bit k into x's set bits; otherwise k of them cleared.
SLIM_INLINE uint32_t select_bit(uint64_t x, uint32_t k) {
#if defined(SLIM_SIMD_AVX2) && defined(__BMI2__)
  return uint32_t(__builtin_ctzll(_pdep_u64(uint64_t(1) << k, x)));
#else
  for (; k; --k) x &= x - 1;
  return uint32_t(__builtin_ctzll(x));
#endif
}

// Bit i (i < 8) set where the 64-bit word p[i] is zero.
SLIM_INLINE uint32_t zero_mask8(const uint64_t* p) {
#if defined(SLIM_SIMD_AVX2)
  const __m256i z = _mm256_setzero_si256();
  const __m256i lo = _mm256_cmpeq_epi64(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)), z);
  const __m256i hi =
      _mm256_cmpeq_epi64(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + 4)), z);
  return uint32_t(_mm256_movemask_pd(_mm256_castsi256_pd(lo))) |
         uint32_t(_mm256_movemask_pd(_mm256_castsi256_pd(hi))) << 4;
#else
  uint32_t m = 0;
  for (int i = 0; i < 8; ++i) m |= uint32_t(p[i] == 0) << i;
  return m;
#endif
}

// Bit i (i < 8) set where the 32-bit word p[i] is zero.
SLIM_INLINE uint32_t zero_mask8(const uint32_t* p) {
#if defined(SLIM_SIMD_AVX2)
  const __m256i z = _mm256_cmpeq_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)),
                                       _mm256_setzero_si256());
  return uint32_t(_mm256_movemask_ps(_mm256_castsi256_ps(z)));
#else
  uint32_t m = 0;
  for (int i = 0; i < 8; ++i) m |= uint32_t(p[i] == 0) << i;
  return m;
#endif
}

#if defined(SLIM_SIMD_AVX2)

// ------------------------------------------------------------------------------------------------
// AVX2 / SSE implementation
// ------------------------------------------------------------------------------------------------

struct vbool8 {
  __m256 m;
  SLIM_INLINE vbool8() = default;
  SLIM_INLINE vbool8(__m256 v) : m(v) {}
  SLIM_INLINE uint32_t mask() const { return uint32_t(_mm256_movemask_ps(m)); }
};
SLIM_INLINE vbool8 operator&(vbool8 a, vbool8 b) { return _mm256_and_ps(a.m, b.m); }
SLIM_INLINE vbool8 operator|(vbool8 a, vbool8 b) { return _mm256_or_ps(a.m, b.m); }
SLIM_INLINE vbool8 andnot(vbool8 a, vbool8 b) { return _mm256_andnot_ps(b.m, a.m); }  // a & !b

struct vfloat8 {
  __m256 v;
  SLIM_INLINE vfloat8() = default;
  SLIM_INLINE vfloat8(__m256 x) : v(x) {}
  SLIM_INLINE explicit vfloat8(float s) : v(_mm256_set1_ps(s)) {}
  SLIM_INLINE static vfloat8 load(const float* p) { return _mm256_load_ps(p); }
  SLIM_INLINE static vfloat8 loadu(const float* p) { return _mm256_loadu_ps(p); }
  SLIM_INLINE void store(float* p) const { _mm256_store_ps(p, v); }
  SLIM_INLINE void storeu(float* p) const { _mm256_storeu_ps(p, v); }
  SLIM_INLINE float operator[](int i) const {
    alignas(32) float t[8];
    _mm256_store_ps(t, v);
    return t[i];
  }
};
SLIM_INLINE vfloat8 operator+(vfloat8 a, vfloat8 b) { return _mm256_add_ps(a.v, b.v); }
SLIM_INLINE vfloat8 operator-(vfloat8 a, vfloat8 b) { return _mm256_sub_ps(a.v, b.v); }
SLIM_INLINE vfloat8 operator*(vfloat8 a, vfloat8 b) { return _mm256_mul_ps(a.v, b.v); }
SLIM_INLINE vfloat8 operator/(vfloat8 a, vfloat8 b) { return _mm256_div_ps(a.v, b.v); }
SLIM_INLINE vfloat8 min(vfloat8 a, vfloat8 b) { return _mm256_min_ps(a.v, b.v); }
SLIM_INLINE vfloat8 max(vfloat8 a, vfloat8 b) { return _mm256_max_ps(a.v, b.v); }
// a*b + c, a*b - c, c - a*b, each with one rounding.
SLIM_INLINE vfloat8 fmadd(vfloat8 a, vfloat8 b, vfloat8 c) { return _mm256_fmadd_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat8 fmsub(vfloat8 a, vfloat8 b, vfloat8 c) { return _mm256_fmsub_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat8 fnmadd(vfloat8 a, vfloat8 b, vfloat8 c) { return _mm256_fnmadd_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat8 abs(vfloat8 a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a.v); }
SLIM_INLINE vfloat8 signmsk(vfloat8 a) { return _mm256_and_ps(a.v, _mm256_set1_ps(-0.0f)); }
SLIM_INLINE vfloat8 operator^(vfloat8 a, vfloat8 b) { return _mm256_xor_ps(a.v, b.v); }
SLIM_INLINE vbool8 operator<(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_LT_OQ); }
SLIM_INLINE vbool8 operator<=(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_LE_OQ); }
SLIM_INLINE vbool8 operator>(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_GT_OQ); }
SLIM_INLINE vbool8 operator>=(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_GE_OQ); }
SLIM_INLINE vbool8 operator==(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_EQ_OQ); }
SLIM_INLINE vbool8 operator!=(vfloat8 a, vfloat8 b) { return _mm256_cmp_ps(a.v, b.v, _CMP_NEQ_UQ); }
// m ? a : b
SLIM_INLINE vfloat8 select(vbool8 m, vfloat8 a, vfloat8 b) { return _mm256_blendv_ps(b.v, a.v, m.m); }
SLIM_INLINE vfloat8 rcp_exact(vfloat8 a) { return _mm256_div_ps(_mm256_set1_ps(1.0f), a.v); }
SLIM_INLINE float reduce_min(vfloat8 a) {
  __m128 m = _mm_min_ps(_mm256_castps256_ps128(a.v), _mm256_extractf128_ps(a.v, 1));
  m = _mm_min_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
  m = _mm_min_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm_cvtss_f32(m);
}

struct vint8 {
  __m256i v;
  SLIM_INLINE vint8() = default;
  SLIM_INLINE vint8(__m256i x) : v(x) {}
  SLIM_INLINE explicit vint8(int s) : v(_mm256_set1_epi32(s)) {}
  SLIM_INLINE static vint8 loadu(const int32_t* p) { return _mm256_loadu_si256((const __m256i*)p); }
  SLIM_INLINE void storeu(int32_t* p) const { _mm256_storeu_si256((__m256i*)p, v); }
  // 8 unsigned bytes widened to 8 ints.
  SLIM_INLINE static vint8 load_u8(const uint8_t* p) {
    return _mm256_cvtepu8_epi32(_mm_loadl_epi64((const __m128i*)p));
  }
  SLIM_INLINE int operator[](int i) const {
    alignas(32) int32_t t[8];
    _mm256_store_si256((__m256i*)t, v);
    return t[i];
  }
};
SLIM_INLINE vfloat8 to_float(vint8 a) { return _mm256_cvtepi32_ps(a.v); }
SLIM_INLINE vint8 operator+(vint8 a, vint8 b) { return _mm256_add_epi32(a.v, b.v); }

struct vbool4 {
  __m128 m;
  SLIM_INLINE vbool4() = default;
  SLIM_INLINE vbool4(__m128 v) : m(v) {}
  SLIM_INLINE uint32_t mask() const { return uint32_t(_mm_movemask_ps(m)); }
};
SLIM_INLINE vbool4 operator&(vbool4 a, vbool4 b) { return _mm_and_ps(a.m, b.m); }
SLIM_INLINE vbool4 operator|(vbool4 a, vbool4 b) { return _mm_or_ps(a.m, b.m); }

struct vfloat4 {
  __m128 v;
  SLIM_INLINE vfloat4() = default;
  SLIM_INLINE vfloat4(__m128 x) : v(x) {}
  SLIM_INLINE explicit vfloat4(float s) : v(_mm_set1_ps(s)) {}
  SLIM_INLINE static vfloat4 loadu(const float* p) { return _mm_loadu_ps(p); }
  SLIM_INLINE void storeu(float* p) const { _mm_storeu_ps(p, v); }
  SLIM_INLINE float operator[](int i) const {
    alignas(16) float t[4];
    _mm_store_ps(t, v);
    return t[i];
  }
};
SLIM_INLINE vfloat4 operator+(vfloat4 a, vfloat4 b) { return _mm_add_ps(a.v, b.v); }
SLIM_INLINE vfloat4 operator-(vfloat4 a, vfloat4 b) { return _mm_sub_ps(a.v, b.v); }
SLIM_INLINE vfloat4 operator*(vfloat4 a, vfloat4 b) { return _mm_mul_ps(a.v, b.v); }
SLIM_INLINE vfloat4 operator/(vfloat4 a, vfloat4 b) { return _mm_div_ps(a.v, b.v); }
SLIM_INLINE vfloat4 min(vfloat4 a, vfloat4 b) { return _mm_min_ps(a.v, b.v); }
SLIM_INLINE vfloat4 max(vfloat4 a, vfloat4 b) { return _mm_max_ps(a.v, b.v); }
SLIM_INLINE vfloat4 fmadd(vfloat4 a, vfloat4 b, vfloat4 c) { return _mm_fmadd_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat4 fmsub(vfloat4 a, vfloat4 b, vfloat4 c) { return _mm_fmsub_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat4 fnmadd(vfloat4 a, vfloat4 b, vfloat4 c) { return _mm_fnmadd_ps(a.v, b.v, c.v); }
SLIM_INLINE vfloat4 abs(vfloat4 a) { return _mm_andnot_ps(_mm_set1_ps(-0.0f), a.v); }
SLIM_INLINE vfloat4 signmsk(vfloat4 a) { return _mm_and_ps(a.v, _mm_set1_ps(-0.0f)); }
SLIM_INLINE vfloat4 operator^(vfloat4 a, vfloat4 b) { return _mm_xor_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator<(vfloat4 a, vfloat4 b) { return _mm_cmplt_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator<=(vfloat4 a, vfloat4 b) { return _mm_cmple_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator>(vfloat4 a, vfloat4 b) { return _mm_cmpgt_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator>=(vfloat4 a, vfloat4 b) { return _mm_cmpge_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator==(vfloat4 a, vfloat4 b) { return _mm_cmpeq_ps(a.v, b.v); }
SLIM_INLINE vbool4 operator!=(vfloat4 a, vfloat4 b) { return _mm_cmpneq_ps(a.v, b.v); }
SLIM_INLINE vfloat4 select(vbool4 m, vfloat4 a, vfloat4 b) { return _mm_blendv_ps(b.v, a.v, m.m); }
SLIM_INLINE vfloat4 rcp_exact(vfloat4 a) { return _mm_div_ps(_mm_set1_ps(1.0f), a.v); }

struct vint4 {
  __m128i v;
  SLIM_INLINE vint4() = default;
  SLIM_INLINE vint4(__m128i x) : v(x) {}
  SLIM_INLINE explicit vint4(int s) : v(_mm_set1_epi32(s)) {}
  SLIM_INLINE void storeu(int32_t* p) const { _mm_storeu_si128((__m128i*)p, v); }
  SLIM_INLINE int operator[](int i) const {
    alignas(16) int32_t t[4];
    _mm_store_si128((__m128i*)t, v);
    return t[i];
  }
};
// Truncating conversion (as a C cast) and clamping.
SLIM_INLINE vint4 to_int_trunc(vfloat4 a) { return _mm_cvttps_epi32(a.v); }
SLIM_INLINE vint4 clamp(vint4 a, vint4 lo, vint4 hi) {
  return _mm_min_epi32(_mm_max_epi32(a.v, lo.v), hi.v);
}

#else

// ------------------------------------------------------------------------------------------------
// Scalar implementation (compiles everywhere)
// ------------------------------------------------------------------------------------------------

template <int N>
struct vboolN {
  uint32_t bits = 0;
  SLIM_INLINE uint32_t mask() const { return bits; }
};
template <int N>
SLIM_INLINE vboolN<N> operator&(vboolN<N> a, vboolN<N> b) { return {a.bits & b.bits}; }
template <int N>
SLIM_INLINE vboolN<N> operator|(vboolN<N> a, vboolN<N> b) { return {a.bits | b.bits}; }
template <int N>
SLIM_INLINE vboolN<N> andnot(vboolN<N> a, vboolN<N> b) { return {a.bits & ~b.bits}; }

template <int N>
struct vfloatN {
  float v[N];
  SLIM_INLINE vfloatN() = default;
  SLIM_INLINE explicit vfloatN(float s) {
    for (int i = 0; i < N; ++i) v[i] = s;
  }
  SLIM_INLINE static vfloatN load(const float* p) { return loadu(p); }
  SLIM_INLINE static vfloatN loadu(const float* p) {
    vfloatN r;
    std::memcpy(r.v, p, sizeof(r.v));
    return r;
  }
  SLIM_INLINE void store(float* p) const { std::memcpy(p, v, sizeof(v)); }
  SLIM_INLINE void storeu(float* p) const { std::memcpy(p, v, sizeof(v)); }
  SLIM_INLINE float operator[](int i) const { return v[i]; }
};

#define SLIM_SCALAR_BINOP(op)                                                 \
  template <int N>                                                            \
  SLIM_INLINE vfloatN<N> operator op(vfloatN<N> a, vfloatN<N> b) {            \
    vfloatN<N> r;                                                             \
    for (int i = 0; i < N; ++i) r.v[i] = a.v[i] op b.v[i];                    \
    return r;                                                                 \
  }
SLIM_SCALAR_BINOP(+)
SLIM_SCALAR_BINOP(-)
SLIM_SCALAR_BINOP(*)
SLIM_SCALAR_BINOP(/)
#undef SLIM_SCALAR_BINOP

#define SLIM_SCALAR_CMP(op)                                                   \
  template <int N>                                                            \
  SLIM_INLINE vboolN<N> operator op(vfloatN<N> a, vfloatN<N> b) {             \
    vboolN<N> r;                                                              \
    for (int i = 0; i < N; ++i) r.bits |= uint32_t(a.v[i] op b.v[i]) << i;    \
    return r;                                                                 \
  }
SLIM_SCALAR_CMP(<)
SLIM_SCALAR_CMP(<=)
SLIM_SCALAR_CMP(>)
SLIM_SCALAR_CMP(>=)
SLIM_SCALAR_CMP(==)
SLIM_SCALAR_CMP(!=)
#undef SLIM_SCALAR_CMP

template <int N>
SLIM_INLINE vfloatN<N> min(vfloatN<N> a, vfloatN<N> b) {
  // Same NaN behaviour as minps: returns b if either is NaN.
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = a.v[i] < b.v[i] ? a.v[i] : b.v[i];
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> max(vfloatN<N> a, vfloatN<N> b) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = a.v[i] > b.v[i] ? a.v[i] : b.v[i];
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> fmadd(vfloatN<N> a, vfloatN<N> b, vfloatN<N> c) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = std::fma(a.v[i], b.v[i], c.v[i]);
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> fmsub(vfloatN<N> a, vfloatN<N> b, vfloatN<N> c) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = std::fma(a.v[i], b.v[i], -c.v[i]);
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> fnmadd(vfloatN<N> a, vfloatN<N> b, vfloatN<N> c) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = std::fma(-a.v[i], b.v[i], c.v[i]);
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> abs(vfloatN<N> a) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = std::fabs(a.v[i]);
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> signmsk(vfloatN<N> a) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = std::signbit(a.v[i]) ? -0.0f : 0.0f;
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> operator^(vfloatN<N> a, vfloatN<N> b) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) {
    uint32_t x, y;
    std::memcpy(&x, &a.v[i], 4);
    std::memcpy(&y, &b.v[i], 4);
    x ^= y;
    std::memcpy(&r.v[i], &x, 4);
  }
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> select(vboolN<N> m, vfloatN<N> a, vfloatN<N> b) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = (m.bits >> i) & 1 ? a.v[i] : b.v[i];
  return r;
}
template <int N>
SLIM_INLINE vfloatN<N> rcp_exact(vfloatN<N> a) {
  vfloatN<N> r;
  for (int i = 0; i < N; ++i) r.v[i] = 1.0f / a.v[i];
  return r;
}
template <int N>
SLIM_INLINE float reduce_min(vfloatN<N> a) {
  float m = a.v[0];
  for (int i = 1; i < N; ++i) m = a.v[i] < m ? a.v[i] : m;
  return m;
}

using vfloat8 = vfloatN<8>;
using vfloat4 = vfloatN<4>;
using vbool8 = vboolN<8>;
using vbool4 = vboolN<4>;

struct vint8 {
  int32_t v[8];
  SLIM_INLINE vint8() = default;
  SLIM_INLINE explicit vint8(int s) {
    for (int i = 0; i < 8; ++i) v[i] = s;
  }
  SLIM_INLINE static vint8 loadu(const int32_t* p) {
    vint8 r;
    std::memcpy(r.v, p, sizeof(r.v));
    return r;
  }
  SLIM_INLINE void storeu(int32_t* p) const { std::memcpy(p, v, sizeof(v)); }
  SLIM_INLINE static vint8 load_u8(const uint8_t* p) {
    vint8 r;
    for (int i = 0; i < 8; ++i) r.v[i] = p[i];
    return r;
  }
  SLIM_INLINE int operator[](int i) const { return v[i]; }
};
struct vint4 {
  int32_t v[4];
  SLIM_INLINE vint4() = default;
  SLIM_INLINE explicit vint4(int s) {
    for (int i = 0; i < 4; ++i) v[i] = s;
  }
  SLIM_INLINE void storeu(int32_t* p) const { std::memcpy(p, v, sizeof(v)); }
  SLIM_INLINE int operator[](int i) const { return v[i]; }
};
SLIM_INLINE vint4 to_int_trunc(vfloat4 a) {
  vint4 r;
  for (int i = 0; i < 4; ++i) {
    float x = a.v[i];
    r.v[i] = x != x || x <= -2147483648.0f || x >= 2147483648.0f ? int32_t(0x80000000u) : int32_t(x);
  }
  return r;
}
SLIM_INLINE vint4 clamp(vint4 a, vint4 lo, vint4 hi) {
  vint4 r;
  for (int i = 0; i < 4; ++i) r.v[i] = a.v[i] < lo.v[i] ? lo.v[i] : (a.v[i] > hi.v[i] ? hi.v[i] : a.v[i]);
  return r;
}

SLIM_INLINE vfloat8 to_float(vint8 a) {
  vfloat8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = float(a.v[i]);
  return r;
}
SLIM_INLINE vint8 operator+(vint8 a, vint8 b) {
  vint8 r;
  for (int i = 0; i < 8; ++i) r.v[i] = a.v[i] + b.v[i];
  return r;
}

#endif

}  // namespace slim::simd
