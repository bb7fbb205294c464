// Seed inputs of the fuzz targets that read a byte format of their own (scene, pairing,
// quantized_mesh, lossy_subgrid; the layouts are in each target's header comment): small valid
// meshes and sub-grids, so that libFuzzer starts from inputs that reach the build, the pairing and
// the encoders instead of from empty ones. make_seeds writes them to OUT_DIR/<target>/.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

namespace slim::seeds {

struct BinarySeed {
  std::string target, name, bytes;
};

namespace detail {

inline void put8(std::string& s, int v) { s.push_back(char(uint8_t(int8_t(v)))); }
inline void put16(std::string& s, int v) {
  const uint16_t u = uint16_t(int16_t(v));
  s.push_back(char(u & 0xff));
  s.push_back(char(u >> 8));
}
inline void put_float(std::string& s, float f) {
  char b[4];
  std::memcpy(b, &f, 4);
  s.append(b, 4);
}

// An n x n vertex lattice (heights z(i, j)) as faces: quads (size byte 1 -> 4 corners) or two
// triangles per cell (size byte 0 -> 3 corners). Indices are bytes: n * n <= 256.
inline void lattice_faces(std::string& s, int n, bool quads) {
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i, b = a + 1, c = a + n + 1, d = a + n;
      if (quads) {
        s += {char(1), char(a), char(b), char(c), char(d)};
      } else {
        s += {char(0), char(a), char(b), char(c)};
        s += {char(0), char(a), char(c), char(d)};
      }
    }
}

inline int height(int i, int j) { return (i * 7 + j * 13) % 5 - 2; }

}  // namespace detail

inline std::vector<BinarySeed> binary_seeds() {
  using namespace detail;
  std::vector<BinarySeed> out;
  // scene: lattice mode, scale 2^0 (bits 1-5 = 16), a 6x6 heightfield and rays down onto it.
  for (bool quads : {true, false}) {
    std::string s;
    const int n = 6, rays = 12;
    put8(s, 16 << 1);
    put8(s, n * n - 1);
    put8(s, rays);
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) put8(s, 10 * i), put8(s, 10 * j), put8(s, height(i, j));
    for (int r = 0; r < rays; ++r) {  // origin (lattice * 2), direction (lattice * 1)
      put8(s, 3 + 4 * r), put8(s, 2 + 3 * r), put8(s, 40);
      put8(s, r % 3 - 1), put8(s, r % 2), put8(s, -10);
    }
    lattice_faces(s, n, quads);
    out.push_back({"scene", quads ? "heightfield_quads" : "heightfield_tris", s});
  }
  // pairing: int8 lattice; triangles of a grid (all pairable), then with groups.
  for (int flags : {0, 2}) {
    std::string s;
    const int n = 8;
    put8(s, flags);
    put8(s, n * n - 1);
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) put8(s, 4 * i), put8(s, 4 * j), put8(s, height(i, j));
    lattice_faces(s, n, false);
    out.push_back({"pairing", flags ? "grid_tris_grouped" : "grid_tris", s});
  }
  // quantized_mesh: the BitArray prefix (width, count, 6 seed bytes), then mode (lattice, scale
  // 2^-4: bits 2-7 = 28), a quad grid, and a pentagon and a hexagon (size bytes 2, 3).
  for (int mode : {28 << 2, (28 << 2) | 1}) {
    std::string s;
    s += {char(13), char(40), char(1), char(2), char(3), char(4), char(5), char(6)};
    const int n = 6;
    put8(s, mode);
    put8(s, n * n - 1);
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) put16(s, 100 * i), put16(s, 100 * j), put16(s, 30 * height(i, j));
    lattice_faces(s, n, true);
    s += {char(2), char(0), char(1), char(2), char(8), char(7)};
    s += {char(3), char(0), char(1), char(2), char(3), char(9), char(8)};
    out.push_back({"quantized_mesh", mode & 1 ? "grid_ngons_T" : "grid_ngons", s});
  }
  // lossy_subgrid: 5x5 sub-grids, both encodings: corners of a unit square, zero codes, then a
  // round-trip sub-grid (scale exponent byte 20 -> 2^0, no exact vertex, a bumpy 5x5 patch).
  for (int enc : {0, 1}) {
    std::string s;
    put8(s, enc | 3 << 1 | 3 << 3);
    put8(s, 100);
    const float corner[4][3] = {{0, 0, 0}, {4, 0, 0}, {0, 4, 1}, {4, 4, 0}};
    for (const auto& c : corner)
      for (float x : c) put_float(s, x);
    s.append(63, '\0');
    put8(s, 20);
    s.append(4, '\0');
    for (int j = 0; j < 5; ++j)
      for (int i = 0; i < 5; ++i) put16(s, 64 * i), put16(s, 64 * j), put16(s, 9 * height(i, j));
    out.push_back({"lossy_subgrid", enc ? "bumpy_e2" : "bumpy_e1", s});
  }
  return out;
}

}  // namespace slim::seeds
