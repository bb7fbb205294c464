// The tiling of a rectangle of an image across threads (render.cpp shade_rect).
#pragma once

#include <cstdint>

namespace slim::render_tiling {

constexpr int kTileSize = 32;       // tiles of a large rectangle (a whole image)
constexpr int kMinTileSize = 4;     // the smallest, for a rectangle of few 32x32 tiles
constexpr int kTilesPerThread = 4;  // tasks per thread, so that uneven tiles balance

// Square tiles of `tile` pixels over a w x h rectangle (the last row and column may be smaller).
inline int64_t tile_count(int w, int h, int tile) {
  return int64_t((w + tile - 1) / tile) * int64_t((h + tile - 1) / tile);
}

// The tile edge for a w x h rectangle shaded by `threads` threads: kTileSize, halved while the
// rectangle holds fewer than kTilesPerThread tiles per thread (down to kMinTileSize), so that a
// small rectangle (one 64x64 tile of `slimrt render` under mpirun) still keeps every thread busy.
inline int tile_size(int w, int h, int threads) {
  int t = kTileSize;
  while (t > kMinTileSize && tile_count(w, h, t) < int64_t(kTilesPerThread) * threads) t /= 2;
  return t;
}

}  // namespace slim::render_tiling
