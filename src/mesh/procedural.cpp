// Procedural benchmark scenes (docs/benchmark.md), generated deterministically from (N, seed)
// so that anyone can reproduce a figure with one command and no download.
//
//  terrain:N  N x N quads over [0,1] x [0,1] in x,y, z up, (N+1)^2 vertices. Height = 8-octave fBm
//             of 2D gradient noise; heights span about 5% of the extent. Stands in for the papers'
//             "Ground" scene: a gentle heightfield, a near-perfect single vertex grid.
//  torus:N    N x N/2 quads (N around the major circle of radius 1, N/2 around the minor one of
//             radius 0.4), displaced along the normal by 7-octave 3D fBm sampled on the undisplaced
//             position. Closed 2-manifold: N * N/2 vertices welded at both seams, every edge shared
//             by exactly two quads. N even, >= 6. The papers' "Torus".
//  canyon:N   N x N quads over [0,1] x [0,1], z up, (N+1)^2 vertices: terraced mesas cut by a
//             network of steep-walled canyons that follow the crest lines of ridged multifractal
//             noise (Musgrave), with rocky detail; heights span about 20% of the extent, cliffs
//             and canyon walls make many rays graze. The papers' "Canyon".
//
// All faces are quads, counter-clockwise seen from above / outside, so the geometric normal points
// up / outward. Heightfield quad (i,j) has the corners (i,j), (i+1,j), (i+1,j+1), (i,j+1) with
// vertex index j*(N+1)+i; torus quad (i,j) the same with vertex index j*N+i, wrapped at the seams.
// Faces are listed row by row (j outer, i inner), face index j*N+i.
//
// Determinism: the noise is an integer hash plus IEEE float/double + - * / and floor only (no std::
// distributions, no libm trigonometry: the torus angles use a series sin/cos in double), and the
// build compiles with -ffp-contract=off, so every platform and thread count gives the same bits.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <unordered_map>
#include <vector>

#include "mesh/procedural.h"
#include "slimrt/error.h"
#include "slimrt/mesh.h"

namespace slim {

bool is_procedural(const std::string& name) {
  auto c = name.find(':');
  if (c == std::string::npos) return false;
  std::string k = name.substr(0, c);
  return k == "terrain" || k == "torus" || k == "canyon";
}

namespace {

// ---- integer hash noise ----

// "lowbias32" integer finalizer (C. Wellons, hash-prospector): full avalanche, 5 cheap ops.
SLIM_INLINE uint32_t mix32(uint32_t h) {
  h ^= h >> 16;
  h *= 0x7feb352du;
  h ^= h >> 15;
  h *= 0x846ca68bu;
  h ^= h >> 16;
  return h;
}

SLIM_INLINE uint32_t hash2(int32_t x, int32_t y, uint32_t seed) {
  return mix32(uint32_t(x) * 0x9E3779B1u + mix32(uint32_t(y) * 0x85EBCA77u + seed));
}

SLIM_INLINE uint32_t hash3(int32_t x, int32_t y, int32_t z, uint32_t seed) {
  return mix32(uint32_t(x) * 0x9E3779B1u +
               mix32(uint32_t(y) * 0x85EBCA77u + mix32(uint32_t(z) * 0xC2B2AE3Du + seed)));
}

// Per-octave seed: octaves must not be copies of one another.
SLIM_INLINE uint32_t octave_seed(uint32_t seed, int octave) {
  return mix32(seed * 0x27D4EB2Fu + uint32_t(octave) * 0x165667B1u + 0x3C6EF372u);
}

SLIM_INLINE float fade(float t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }
SLIM_INLINE float lerp(float a, float b, float t) { return a + (b - a) * t; }
SLIM_INLINE float smoothstep(float a, float b, float x) {
  float t = std::min(std::max((x - a) / (b - a), 0.0f), 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

// 2D gradient (Perlin) noise with 8 unit gradients; range about [-0.71, 0.71].
SLIM_INLINE float grad2(uint32_t h, float x, float y) {
  constexpr float kD = 0.70710678f;
  constexpr float kGx[8] = {1, -1, 0, 0, kD, -kD, kD, -kD};
  constexpr float kGy[8] = {0, 0, 1, -1, kD, kD, -kD, -kD};
  uint32_t i = h >> 29;  // top bits: the best mixed ones
  return kGx[i] * x + kGy[i] * y;
}

float noise2(float x, float y, uint32_t seed) {
  float fx = std::floor(x), fy = std::floor(y);
  int32_t ix = int32_t(fx), iy = int32_t(fy);
  float dx = x - fx, dy = y - fy;
  float n00 = grad2(hash2(ix, iy, seed), dx, dy);
  float n10 = grad2(hash2(ix + 1, iy, seed), dx - 1.0f, dy);
  float n01 = grad2(hash2(ix, iy + 1, seed), dx, dy - 1.0f);
  float n11 = grad2(hash2(ix + 1, iy + 1, seed), dx - 1.0f, dy - 1.0f);
  float u = fade(dx), v = fade(dy);
  return lerp(lerp(n00, n10, u), lerp(n01, n11, u), v);
}

// 3D gradient noise with Perlin's 12 edge gradients (improved noise, 2002); range about [-1, 1].
SLIM_INLINE float grad3(uint32_t hash, float x, float y, float z) {
  uint32_t h = hash >> 28;
  float u = h < 8 ? x : y;
  float v = h < 4 ? y : (h == 12 || h == 14 ? x : z);
  return ((h & 1) ? -u : u) + ((h & 2) ? -v : v);
}

float noise3(float x, float y, float z, uint32_t seed) {
  float fx = std::floor(x), fy = std::floor(y), fz = std::floor(z);
  int32_t ix = int32_t(fx), iy = int32_t(fy), iz = int32_t(fz);
  float dx = x - fx, dy = y - fy, dz = z - fz;
  float u = fade(dx), v = fade(dy), w = fade(dz);
  float n[2][2][2];
  for (int c = 0; c < 2; ++c)
    for (int b = 0; b < 2; ++b)
      for (int a = 0; a < 2; ++a)
        n[c][b][a] =
            grad3(hash3(ix + a, iy + b, iz + c, seed), dx - float(a), dy - float(b), dz - float(c));
  float y0 = lerp(lerp(n[0][0][0], n[0][0][1], u), lerp(n[0][1][0], n[0][1][1], u), v);
  float y1 = lerp(lerp(n[1][0][0], n[1][0][1], u), lerp(n[1][1][0], n[1][1][1], u), v);
  return lerp(y0, y1, w);
}

// Between octaves the 2D domain is rotated by ~37 degrees and scaled by 2 (the matrix
// [1.6 1.2; -1.2 1.6]), which hides the axis-aligned lattice of the noise.
SLIM_INLINE void next_octave(float& x, float& y) {
  float nx = 1.6f * x + 1.2f * y;
  float ny = -1.2f * x + 1.6f * y;
  x = nx;
  y = ny;
}

// fBm: sum of `octaves` octaves, gain 0.5; about [-0.5, 0.5] in practice.
float fbm2(float x, float y, uint32_t seed, int octaves) {
  float sum = 0.0f, amp = 0.5f;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * noise2(x, y, octave_seed(seed, o));
    next_octave(x, y);
    amp *= 0.5f;
  }
  return sum;
}

float fbm3(float x, float y, float z, uint32_t seed, int octaves) {
  float sum = 0.0f, amp = 0.5f;
  for (int o = 0; o < octaves; ++o) {
    sum += amp * noise3(x, y, z, octave_seed(seed, o));
    x *= 2.0f;
    y *= 2.0f;
    z *= 2.0f;
    amp *= 0.5f;
  }
  return sum;
}

// Ridged multifractal (Musgrave, "Texturing & Modeling", ch. 16), offset 1, gain 2, H = 1:
// each octave is (1 - |noise|)^2, weighted by the previous octave so detail gathers on the ridges.
// Result in [0, 1): ridges near 1, broad valleys near 0.
float ridged2(float x, float y, uint32_t seed, int octaves) {
  float sum = 0.0f, amp = 1.0f, norm = 0.0f, weight = 1.0f;
  for (int o = 0; o < octaves; ++o) {
    float n = noise2(x, y, octave_seed(seed, o)) * 1.41421356f;
    float s = 1.0f - std::fabs(n);
    s = s * s * weight;
    weight = std::min(std::max(s * 2.0f, 0.0f), 1.0f);
    sum += s * amp;
    norm += amp;
    amp *= 0.5f;
    next_octave(x, y);
  }
  return sum / norm;
}

// ---- deterministic sin/cos of 2*pi*k/n (no libm: results are identical on every platform) ----

// Taylor series on [0, pi/4]: the 10th term is below 1e-19, so the double result is accurate to
// about 1 ulp; only + * / are used.
void sincos_small(double a, double& s, double& c) {
  double a2 = a * a;
  double ts = a, tc = 1.0;
  s = a;
  c = 1.0;
  for (int k = 1; k <= 10; ++k) {
    ts *= -a2 / double((2 * k) * (2 * k + 1));
    tc *= -a2 / double((2 * k - 1) * (2 * k));
    s += ts;
    c += tc;
  }
}

void sincos_turn(int64_t k, int64_t n, double& s, double& c) {
  constexpr double kHalfPi = 1.57079632679489661923;
  k %= n;
  if (k < 0) k += n;
  int64_t q = (4 * k) / n;    // quadrant
  int64_t r = 4 * k - q * n;  // angle within the quadrant = (pi/2) * r / n
  double ss, cc;
  if (2 * r <= n) {
    sincos_small(kHalfPi * (double(r) / double(n)), ss, cc);
  } else {  // reflect to [0, pi/4]: sin(a) = cos(pi/2 - a)
    sincos_small(kHalfPi * (double(n - r) / double(n)), cc, ss);
  }
  switch (q) {
    case 0:
      s = ss, c = cc;
      break;
    case 1:
      s = cc, c = -ss;
      break;
    case 2:
      s = -ss, c = -cc;
      break;
    default:
      s = -cc, c = ss;
      break;
  }
}

// ---- mesh assembly ----

void check_n(const char* kind, int n, int64_t max_n) {
  if (n < 1 || n > max_n)
    throw Error(std::string(kind) + ":" + std::to_string(n) + ": N must be in [1, " +
                std::to_string(max_n) + "]");
}

// Quads of an nx x ny grid of cells over a vertex grid `stride` vertices wide; wrap_x / wrap_y
// weld the last column / row to the first one (torus).
void grid_faces(PolyMesh& m, int nx, int ny, int64_t stride, bool wrap_x, bool wrap_y) {
  size_t faces = size_t(nx) * size_t(ny);
  m.face_sizes.assign(faces, 4u);
  m.face_indices.resize(faces * 4);
  uint32_t* out = m.face_indices.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, ny), [&](const tbb::blocked_range<int>& rows) {
    for (int j = rows.begin(); j != rows.end(); ++j) {
      int64_t j1 = (wrap_y && j + 1 == ny) ? 0 : j + 1;
      uint32_t* f = out + size_t(j) * size_t(nx) * 4;
      for (int i = 0; i < nx; ++i, f += 4) {
        int64_t i1 = (wrap_x && i + 1 == nx) ? 0 : i + 1;
        f[0] = uint32_t(j * stride + i);
        f[1] = uint32_t(j * stride + i1);
        f[2] = uint32_t(j1 * stride + i1);
        f[3] = uint32_t(j1 * stride + i);
      }
    }
  });
}

// Terrain height at (x, y) in [0,1]^2. Base frequency 3 cells across the extent; 8 octaves reach
// 3 * 2^7 = 384 cells, finer than a quad at N = 256 and about 2.7 quads per cell at N = 1024.
// fbm2 spans about [-0.5, 0.5], so kAmp gives a height range of about 5% of the unit extent.
float terrain_height(float x, float y, uint32_t s) {
  constexpr float kFreq = 3.0f, kAmp = 0.07f;
  return kAmp * fbm2(x * kFreq + 17.25f, y * kFreq + 3.5f, s, 8);
}

// Mesas cut by canyons: a low-frequency fBm plateau, terraced into flat steps with sharp risers
// (cliffs), carved down along the crest lines of a ridged multifractal (the network of
// zero-crossings of the noise: ridged2 > ~0.7 there) into steep-walled canyons, plus rocky
// high-frequency detail. Heights span about 20% of the extent; about 40% of the faces at N=1024
// are steeper than 45 degrees, so many rays graze.
float canyon_height(float x, float y, uint32_t s) {
  constexpr float kFreq = 2.0f, kAmp = 0.25f, kDetail = 0.015f;
  constexpr int kSteps = 4;  // terraces
  float px = x * kFreq + 5.75f, py = y * kFreq + 11.5f;
  float carve = smoothstep(0.62f, 0.8f, ridged2(px, py, s, 6));
  float base = 0.5f + 1.6f * fbm2(px * 0.7f, py * 0.7f, s ^ 0x5bd1e995u, 4);
  float t = std::min(std::max(base, 0.0f), 1.0f) * float(kSteps);
  float step = std::floor(t);
  float terrace = (step + smoothstep(0.75f, 1.0f, t - step)) * (1.0f / float(kSteps));
  float detail = fbm2(px * 6.0f, py * 6.0f, s ^ 0x1b873593u, 5);
  return kAmp * ((0.35f + 0.65f * terrace) * (1.0f - 0.85f * carve)) + kDetail * detail;
}

constexpr double kTorusMajor = 1.0, kTorusMinor = 0.4;
constexpr float kTorusFreq = 2.5f, kTorusAmp = 0.12f;  // displacement spans about +-0.05

// A mesh with the grid's vertices (all rows, in parallel) and quads.
PolyMesh grid_mesh(const detail::ProceduralGrid& g, const std::string& name) {
  PolyMesh m;
  m.name = name;
  m.positions.resize(size_t(g.verts_x) * size_t(g.verts_y));
  Vec3f* pos = m.positions.data();
  tbb::parallel_for(tbb::blocked_range<int>(0, g.verts_y), [&](const tbb::blocked_range<int>& r) {
    for (int j = r.begin(); j != r.end(); ++j) g.vertex_row(j, pos + size_t(j) * size_t(g.verts_x));
  });
  grid_faces(m, g.cells_x, g.cells_y, g.verts_x, g.wrap, g.wrap);
  return m;
}

}  // namespace

namespace detail {

ProceduralSpec parse_procedural(const std::string& spec, int max_n) {
  const size_t colon = spec.find(':');
  const std::string kind = spec.substr(0, colon),
                    digits = colon == std::string::npos ? "" : spec.substr(colon + 1);
  if (kind != "terrain" && kind != "torus" && kind != "canyon")
    throw Error(spec + ": expected a procedural scene terrain:N, torus:N or canyon:N");
  // Strict: decimal digits only, no sign, blanks or leading zeros.
  bool ok = !digits.empty() && digits.size() <= 6 && digits[0] != '0' &&
            std::all_of(digits.begin(), digits.end(), [](char c) { return c >= '0' && c <= '9'; });
  const int n = ok ? std::stoi(digits) : 0;
  // A torus needs N even and N/2 >= 3 (make_torus): one range stated, the one that holds.
  if (kind == "torus" && (!ok || n > max_n || n < 6 || n % 2 != 0))
    throw Error(spec + ": expected torus:N with N an even integer from 6 to " +
                std::to_string(max_n));
  if (!ok || n > max_n)
    throw Error(spec + ": expected " + kind + ":N with N an integer from 1 to " +
                std::to_string(max_n));
  return {kind, n};
}

ProceduralGrid::ProceduralGrid(const ProceduralSpec& spec, uint32_t seed) : n_(spec.n) {
  const int n = spec.n;
  if (spec.kind == "torus") {
    // N = 4 would give a 2-gon minor circle: both rows of quads share the same vertical edges,
    // so the mesh would not be a 2-manifold. N/2 >= 3 is the smallest closed torus.
    if (n < 6 || n % 2 != 0 || n > 65534)
      throw Error("torus:" + std::to_string(n) + ": N must be even and in [6, 65534]");
    kind_ = Kind::Torus;
    s_ = mix32(seed ^ 0x70A05u);
    cells_x = verts_x = n;      // around the major circle
    cells_y = verts_y = n / 2;  // around the minor one
    wrap = true;
    // Angle tables: N + N/2 series evaluations instead of one per vertex.
    su_.resize(verts_x), cu_.resize(verts_x), sv_.resize(verts_y), cv_.resize(verts_y);
    for (int i = 0; i < verts_x; ++i) sincos_turn(i, verts_x, su_[i], cu_[i]);
    for (int j = 0; j < verts_y; ++j) sincos_turn(j, verts_y, sv_[j], cv_[j]);
    return;
  }
  const bool terrain = spec.kind == "terrain";
  if (!terrain && spec.kind != "canyon") throw Error(spec.kind + ": not a procedural scene");
  check_n(terrain ? "terrain" : "canyon", n, 65534);  // (n+1)^2 indices must fit in 32 bits
  kind_ = terrain ? Kind::Terrain : Kind::Canyon;
  s_ = mix32(seed ^ (terrain ? 0x7E44A1Du : 0xCA7107u));
  cells_x = cells_y = n;
  verts_x = verts_y = n + 1;
}

void ProceduralGrid::vertex_span(int j, int i0, int i1, Vec3f* out) const {
  if (kind_ == Kind::Torus) {
    for (int i = i0; i < i1; ++i) {
      // Outward normal and undisplaced point of the torus at (theta_i, phi_j).
      double nx = cv_[j] * cu_[i], ny = cv_[j] * su_[i], nz = sv_[j];
      double ring = kTorusMajor + kTorusMinor * cv_[j];
      double px = ring * cu_[i], py = ring * su_[i], pz = kTorusMinor * sv_[j];
      // Noise sampled on the 3D position: periodic by construction, and seam vertices are
      // shared anyway, so the surface closes.
      double d = kTorusAmp * fbm3(float(px) * kTorusFreq, float(py) * kTorusFreq,
                                  float(pz) * kTorusFreq, s_, 7);
      out[i - i0] = Vec3f(float(px + nx * d), float(py + ny * d), float(pz + nz * d));
    }
    return;
  }
  // (n+1)^2 heightfield vertices over [0,1]^2: x = i/n, y = j/n, the last ones exactly 1.
  const float inv_n = 1.0f / float(n_);
  const float y = j == n_ ? 1.0f : float(j) * inv_n;
  for (int i = i0; i < i1; ++i) {
    const float x = i == n_ ? 1.0f : float(i) * inv_n;
    out[i - i0] =
        Vec3f(x, y, kind_ == Kind::Terrain ? terrain_height(x, y, s_) : canyon_height(x, y, s_));
  }
}

void ProceduralGrid::tile(int i0, int i1, int j0, int j1, std::vector<uint32_t>& sizes,
                          std::vector<uint64_t>& face_ids, std::vector<Vec3f>& corners) const {
  if (i0 < 0 || i1 > cells_x || j0 < 0 || j1 > cells_y || i0 >= i1 || j0 >= j1) return;
  // Vertex rows j0..j1 (row j1 wraps to 0 on a torus), columns i0..i1 of them used.
  const int rows = j1 - j0 + 1;
  std::vector<Vec3f> v(size_t(rows) * size_t(verts_x));
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& r) {
    for (int k = r.begin(); k != r.end(); ++k) {
      const int j = (wrap && j0 + k == verts_y) ? 0 : j0 + k;
      vertex_row(j, v.data() + size_t(k) * size_t(verts_x));
    }
  });
  const size_t quads = size_t(i1 - i0) * size_t(j1 - j0);
  sizes.insert(sizes.end(), quads, 4u);
  const size_t c0 = corners.size();
  corners.resize(c0 + 4 * quads);
  Vec3f* c = corners.data() + c0;
  for (int j = j0; j < j1; ++j) {
    const Vec3f* r0 = v.data() + size_t(j - j0) * size_t(verts_x);
    const Vec3f* r1 = r0 + verts_x;
    for (int i = i0; i < i1; ++i, c += 4) {
      const int ii = (wrap && i + 1 == cells_x) ? 0 : i + 1;
      c[0] = r0[i];
      c[1] = r0[ii];
      c[2] = r1[ii];
      c[3] = r1[i];
      face_ids.push_back(uint64_t(j) * uint64_t(cells_x) + uint64_t(i));
    }
  }
}

}  // namespace detail

PolyMesh make_terrain(int n, uint32_t seed) {
  check_n("terrain", n, 65534);
  return grid_mesh(detail::ProceduralGrid({"terrain", n}, seed), "terrain:" + std::to_string(n));
}

PolyMesh make_canyon(int n, uint32_t seed) {
  check_n("canyon", n, 65534);
  return grid_mesh(detail::ProceduralGrid({"canyon", n}, seed), "canyon:" + std::to_string(n));
}

PolyMesh make_torus(int n, uint32_t seed) {
  return grid_mesh(detail::ProceduralGrid({"torus", n}, seed), "torus:" + std::to_string(n));
}

PolyMesh make_sphere(int levels, float jitter, uint32_t seed) {
  if (levels < 0 || levels > 10)
    throw Error("sphere: " + std::to_string(levels) + " subdivision levels, expected 0 to 10");
  // The icosahedron, its 20 faces wound outward.
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  std::vector<Vec3f> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                          {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                          {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<uint32_t> f = {0, 11, 5,  0, 5,  1, 0, 1, 7, 0, 7,  10, 0, 10, 11, 1, 5, 9, 5, 11,
                             4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3,  9,  4, 3,  4,  2, 3, 2, 6, 3,
                             6, 8,  3,  8, 9,  4, 9, 5, 2, 4, 11, 6,  2, 10, 8,  6, 7, 9, 8, 1};
  // Each level splits every triangle into 4 at its edge midpoints, shared by both neighbours.
  for (int l = 0; l < levels; ++l) {
    std::unordered_map<uint64_t, uint32_t> mid;
    auto midpoint = [&](uint32_t a, uint32_t b) {
      const uint64_t key = uint64_t(std::min(a, b)) << 32 | std::max(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]) * 0.5f);
      return mid[key] = uint32_t(v.size() - 1);
    };
    std::vector<uint32_t> nf;
    nf.reserve(f.size() * 4);
    for (size_t i = 0; i < f.size(); i += 3) {
      const uint32_t a = f[i], b = f[i + 1], c = f[i + 2];
      const uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      nf.insert(nf.end(), {a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca});
    }
    f.swap(nf);
  }
  PolyMesh m;
  m.name = "sphere:" + std::to_string(levels);
  m.positions.resize(v.size());
  for (size_t i = 0; i < v.size(); ++i) {
    // Radial jitter in [-jitter, +jitter) from the vertex index (deterministic).
    const float r = float(mix32(uint32_t(i) * 0x9E3779B9u ^ seed) >> 8) * (1.0f / 16777216.0f);
    m.positions[i] = normalize(v[i]) * (1.0f + jitter * (2.0f * r - 1.0f));
  }
  m.face_indices = std::move(f);
  m.face_sizes.assign(m.face_indices.size() / 3, 3);
  return m;
}

}  // namespace slim
