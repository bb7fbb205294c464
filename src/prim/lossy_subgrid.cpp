// Lossy compressed grid primitives (Benthin et al., Eurographics 2021): the unit vector table
// and the displacement encoders of section 4.1, the patch weights and the code unpacking tables
// of the section 4.3 decoder, and the sub-grid encoder of section 4 (Figure 2).
#include "prim/lossy_subgrid.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace slim {

// ---- unit vector table (section 4.1: "a set of predefined unit vectors in the first octant",
// 10 bits = 1024 entries) -----------------------------------------------------------------------

namespace {

constexpr double kHalfPi = 1.57079632679489661923;

int ring_size(int r) { return r == 0 ? 1 : (r % 4 == 0 ? r : r + 1); }

}  // namespace

UnitVectorTable::UnitVectorTable() {
  int n = 0;
  for (int r = 0; r < kRings; ++r) {
    ring_start[r] = uint16_t(n);
    const int size = ring_size(r);
    const double rho = double(r) / double(kRings - 1);
    // Inverse of the equal-area map: z = 1 - rho^2, sin(theta) = rho * sqrt(2 - rho^2).
    const double zz = 1.0 - rho * rho, s = rho * std::sqrt(2.0 - rho * rho);
    for (int l = 0; l < size; ++l) {
      const double phi = size == 1 ? 0.0 : kHalfPi * double(l) / double(size - 1);
      double v[3] = {s * std::cos(phi), s * std::sin(phi), zz};
      if (l == 0) v[1] = 0.0;  // exactly on the octant's borders
      if (l == size - 1 && size > 1) v[0] = 0.0;
      const double len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
      x[n] = float(v[0] / len);
      y[n] = float(v[1] / len);
      z[n] = float(v[2] / len);
      xyz[n][0] = x[n];
      xyz[n][1] = y[n];
      xyz[n][2] = z[n];
      xyz[n][3] = 0.0f;
      ++n;
    }
  }
  ring_start[kRings] = uint16_t(n);
}

int UnitVectorTable::candidates(const double d[3], uint32_t out[9]) const {
  const double len = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  const double zz = std::min(1.0, d[2] / len);
  const double rho = std::sqrt(std::max(0.0, 1.0 - zz));
  const double phi = std::atan2(d[1], d[0]);  // in [0, pi/2]
  const int r0 = int(std::lround(rho * (kRings - 1)));
  int n = 0;
  for (int r = std::max(0, r0 - 1); r <= std::min(kRings - 1, r0 + 1); ++r) {
    const int size = ring_size(r);
    const int l0 = size == 1 ? 0 : int(std::lround(phi / kHalfPi * (size - 1)));
    for (int l = std::max(0, l0 - 1); l <= std::min(size - 1, l0 + 1); ++l)
      out[n++] = uint32_t(ring_start[r] + l);
  }
  return n;
}

uint32_t UnitVectorTable::nearest(const double d[3]) const {
  uint32_t c[9];
  const int n = candidates(d, c);
  uint32_t best = c[0];
  double best_dot = -2.0;
  for (int i = 0; i < n; ++i) {
    const double dot = d[0] * x[c[i]] + d[1] * y[c[i]] + d[2] * z[c[i]];
    if (dot > best_dot) {
      best_dot = dot;
      best = c[i];
    }
  }
  return best;
}

const UnitVectorTable kUnitVectors;

// ---- patch weights and code unpacking ---------------------------------------------------------

PatchWeights::PatchWeights() {
  std::memset(this, 0, sizeof(*this));
  for (int n = 2; n <= 5; ++n) {
    for (int i = 0; i < 5; ++i) {
      const int ii = std::min(i, n - 1);
      // Both weights are quotients of small integers, so w0(i) = w1(n-1-i) bit for bit: a border
      // evaluated from either end gives the same point.
      w0[n][i] = float(n - 1 - ii) / float(n - 1);
      w1[n][i] = float(ii) / float(n - 1);
    }
    for (int k = 0; k < 25; ++k) {
      u0[n][k] = w0[n][k % 5];
      u1[n][k] = w1[n][k % 5];
      v0[n][k] = w0[n][k / 5];
      v1[n][k] = w1[n][k / 5];
    }
  }
}

const PatchWeights kPatchWeights;

namespace detail {

// The last code a 16-byte window may start at: codes 16-20 are bytes 48-62, and byte 63 (res) is
// the last byte read. A block needs no readable bytes after it (the 68-byte shared layout is
// followed directly by the next block, or by the end of the arena).
constexpr int kLastWindowCode = 16;

CodeUnpack::CodeUnpack() {
  for (int g = 0; g < 3; ++g) {
    for (int half = 0; half < 2; ++half) {
      // The window starts at the first code of the 4 positions of this half, at most at code 16:
      // its 16 bytes then end at the block's res byte (63), whatever follows the block.
      int first = -1;
      for (int l = 0; l < 4 && first < 0; ++l) first = displ_position_slot(8 * g + 4 * half + l);
      const int base = 3 * std::min(first, kLastWindowCode);
      (half ? hi : lo)[g] = uint8_t(base);
      for (int l = 0; l < 4; ++l) {
        const int s = displ_position_slot(8 * g + 4 * half + l);
        if (s >= 0 && (3 * s < base || 3 * s + 2 > base + 15))
          throw std::logic_error("code unpack: a code outside its window");
        for (int b = 0; b < 4; ++b)
          ctrl[g][16 * half + 4 * l + b] = (s < 0 || b == 3) ? 0x80 : uint8_t(3 * s + b - base);
      }
    }
  }
}

const CodeUnpack kCodeUnpack;

}  // namespace detail

QuarterTables::QuarterTables() {
  std::memset(this, 0, sizeof(*this));
  for (int q = 0; q < 4; ++q) {
    const int qx = q & 1, qy = q >> 1;
    int next = 0;
    for (int b = 0; b < 3; ++b)
      for (int a = 0; a < 3; ++a) {
        const bool corner = a == 2 * qx && b == 2 * qy;
        const int l = corner ? 8 : next++;
        lane[q][b][a] = uint8_t(l);
        position[q][l] = uint8_t(5 * (2 * qy + b) + 2 * qx + a);
      }
    // Triangle t: cell (ci, cj) = (t & 1, (t >> 1) & 1), A for t < 4, B otherwise; corners as in
    // intersect_subgrid_rows (A: p00 p10 p11, flipped p01; B: p11 p01 p00, flipped p10).
    for (int t = 0; t < 8; ++t) {
      const int ci = t & 1, cj = (t >> 1) & 1;
      const int A[4][2] = {{ci, cj}, {ci + 1, cj}, {ci + 1, cj + 1}, {ci, cj + 1}};
      const int B[4][2] = {{ci + 1, cj + 1}, {ci, cj + 1}, {ci, cj}, {ci + 1, cj}};
      for (int k = 0; k < 4; ++k) {
        const int* v = t < 4 ? A[k] : B[k];
        const int l = lane[q][v[1]][v[0]];
        perm[q][k][t] = l == 8 ? 0 : l;
        if (l == 8) corner_mask[q][k] |= 1u << t;
      }
    }
  }
}

const QuarterTables kQuarterTables;

namespace detail {

QuarterUnpack::QuarterUnpack() {
  std::memset(this, 0, sizeof(*this));
  const QuarterTables& qt = kQuarterTables;  // defined above in this file: constructed first
  for (int q = 0; q < 4; ++q) {
    for (int half = 0; half < 2; ++half) {
      int slot[4];
      for (int l = 0; l < 4; ++l) slot[l] = displ_position_slot(qt.position[q][4 * half + l]);
      // Two windows: the first from the first lane's code, the second from the first code it
      // misses. A window of 16 bytes at code s holds codes s .. s+4 and starts at most at code
      // 16 (kLastWindowCode: it ends at the res byte).
      bool done[4] = {false, false, false, false};
      for (int k = 0; k < 2; ++k) {
        int first = -1;
        for (int l = 0; l < 4 && first < 0; ++l)
          if (!done[l]) first = slot[l];
        const int start = first < 0 ? 0 : std::min(first, kLastWindowCode);
        (half ? hi : lo)[q][k] = uint8_t(3 * start);
        for (int l = 0; l < 4; ++l) {
          const bool take = !done[l] && slot[l] >= start && slot[l] <= start + 4;
          for (int b = 0; b < 4; ++b)
            ctrl[q][k][16 * half + 4 * l + b] =
                take && b < 3 ? uint8_t(3 * (slot[l] - start) + b) : 0x80;
          done[l] = done[l] || take;
        }
      }
      for (int l = 0; l < 4; ++l)
        if (!done[l]) throw std::logic_error("quarter code unpack: codes out of two windows");
    }
    for (int n = 2; n <= 5; ++n)
      for (int l = 0; l < 8; ++l) {
        const int k = qt.position[q][l];
        u0[n][q][l] = kPatchWeights.u0[n][k];
        u1[n][q][l] = kPatchWeights.u1[n][k];
        v0[n][q][l] = kPatchWeights.v0[n][k];
        v1[n][q][l] = kPatchWeights.v1[n][k];
      }
  }
}

const QuarterUnpack kQuarterUnpack;

}  // namespace detail

// ---- displacement encoders (section 4.1) ------------------------------------------------------

int displacement_bias(float diag) {
  int e = 0;
  std::frexp(std::isfinite(diag) && diag > 0 ? double(diag) : 1.0, &e);  // diag < 2^e
  // Exponent 62 then reaches 2^(e+1) for encoding 1 and 31/32 * 2^(e+1) for encoding 2.
  return std::clamp(e + 127 - 61 + 1, 5, 192);
}

namespace {

SLIM_INLINE double dist2(const Vec3f& a, const Vec3f& b) {
  const double dx = double(a.x) - b.x, dy = double(a.y) - b.y, dz = double(a.z) - b.z;
  return dx * dx + dy * dy + dz * dz;
}

}  // namespace

uint32_t encode_displacement1(const Vec3f& patch, const Vec3f& target, int bias) {
  const double d[3] = {double(target.x) - patch.x, double(target.y) - patch.y,
                       double(target.z) - patch.z};
  uint32_t best = 0;
  double best_err = dist2(patch, target);  // code 0: the patch point itself
  if (best_err == 0.0) return 0;
  const double ad[3] = {std::fabs(d[0]), std::fabs(d[1]), std::fabs(d[2])};
  const uint32_t octant = (d[0] < 0 ? 1u : 0u) | (d[1] < 0 ? 2u : 0u) | (d[2] < 0 ? 4u : 0u);
  uint32_t cand[9];
  const int nc = kUnitVectors.candidates(ad, cand);
  // The 3 directions closest to d (largest projections) are tried, each with both lengths.
  double dots[9];
  for (int c = 0; c < nc; ++c)
    dots[c] = ad[0] * kUnitVectors.x[cand[c]] + ad[1] * kUnitVectors.y[cand[c]] +
              ad[2] * kUnitVectors.z[cand[c]];
  for (int c = 0; c < nc && c < 3; ++c) {
    int best_c = c;
    for (int o = c + 1; o < nc; ++o)
      if (dots[o] > dots[best_c]) best_c = o;
    std::swap(dots[c], dots[best_c]);
    std::swap(cand[c], cand[best_c]);
  }
  for (int c = 0; c < std::min(nc, 3); ++c) {
    const uint32_t k = cand[c];
    const double proj = dots[c];
    if (!(proj > 0.0)) continue;
    // The two 6-bit exponent / 5-bit mantissa lengths around the projection ("clamp the 8 bit
    // exponent, round the mantissa to 5 bits": both roundings are tried).
    uint32_t bits;
    const float pf = float(proj);
    std::memcpy(&bits, &pf, 4);
    int e = int(bits >> 23) - bias;
    uint32_t m = (bits >> 18) & 31;
    for (int step = 0; step < 2; ++step) {
      int ee = e;
      uint32_t mm = m + uint32_t(step);
      if (mm == 32) {
        mm = 0;
        ee++;
      }
      if (ee < 1) {
        ee = 1;
        mm = 0;
      }
      if (ee > 62) {
        ee = 62;
        mm = 31;
      }
      const uint32_t code = octant | (k << 3) | (uint32_t(ee) << kDisplExpShift) | (mm << 19);
      const double err = dist2(decode_vertex<1>(patch, code, bias), target);
      if (err < best_err) {
        best_err = err;
        best = code;
      }
    }
  }
  return best;
}

uint32_t encode_displacement2(const Vec3f& patch, const Vec3f& target, int bias) {
  const double d[3] = {double(target.x) - patch.x, double(target.y) - patch.y,
                       double(target.z) - patch.z};
  const double amax = std::max(std::fabs(d[0]), std::max(std::fabs(d[1]), std::fabs(d[2])));
  if (amax == 0.0) return 0;
  // Smallest shared exponent whose scale holds the largest component: 31.5 * scale >= amax,
  // scale = 2^(e + bias - 132).
  int ex = 0;
  std::frexp(amax / 31.5, &ex);  // amax / 31.5 < 2^ex
  int e = std::clamp(ex + 132 - bias, 1, 62);
  while (e > 1 && 31.5 * std::ldexp(1.0, e - 1 + bias - 132) >= amax) --e;
  const float scale = float_from_bits(uint32_t(e + bias - 5) << 23);
  uint32_t code = uint32_t(e) << kDisplExpShift;
  static constexpr int kShift[3] = {3, 8, 19};
  const float p[3] = {patch.x, patch.y, patch.z}, t[3] = {target.x, target.y, target.z};
  for (int a = 0; a < 3; ++a) {
    // Per axis the decoded coordinate is p + (+-m * scale): pick the best m of the two roundings.
    const double q = std::fabs(d[a]) / double(scale);
    int m0 = std::clamp(int(std::floor(q)), 0, 31);
    int best_m = 0;
    double best_err = kInf;
    for (int m = m0; m <= std::min(m0 + 1, 31); ++m) {
      float c = float(m) * scale;
      if (d[a] < 0) c = -c;
      const double err = std::fabs(double(p[a] + c) - double(t[a]));
      if (err < best_err) {
        best_err = err;
        best_m = m;
      }
    }
    code |= uint32_t(best_m) << kShift[a];
    if (d[a] < 0) code |= 1u << a;
  }
  // A code that rounds every component to 0 is the zero displacement.
  if (((code >> 3) & 31) == 0 && ((code >> 8) & 31) == 0 && (code >> 19) == 0) return 0;
  return code;
}

// ---- sub-grid encoder (section 4, Figure 2) ---------------------------------------------------

template <int kEnc>
void encode_subgrid(const SubGridInput& in, int bias, uint8_t displ[63]) {
  const uint32_t rx = in.res_x, ry = in.res_y;
  const Vec3f c[4] = {in.v[0], in.v[rx - 1], in.v[5 * (ry - 1)], in.v[5 * (ry - 1) + rx - 1]};
  for (int s = 0; s < 21; ++s) {
    const int k = displ_slot_position(s);
    const uint32_t i = uint32_t(k % 5), j = uint32_t(k / 5);
    uint32_t code = 0;
    const bool corner = (i == 0 || i == rx - 1) && (j == 0 || j == ry - 1);
    if (i < rx && j < ry && !corner) {
      if (in.exact[k] != kNotExact)
        code = escape_code(in.exact[k]);
      else
        code = encode_displacement<kEnc>(patch_point(c, i, j, rx, ry), in.v[k], bias);
    }
    store_code(displ + 3 * s, code);
  }
}

template void encode_subgrid<1>(const SubGridInput&, int, uint8_t*);
template void encode_subgrid<2>(const SubGridInput&, int, uint8_t*);

}  // namespace slim
