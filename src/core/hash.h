// 64-bit keys of primitives for validate()'s "every primitive exactly once" fingerprint, taken
// for every primitive of every build.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

namespace slim {

// NH hashing (the UMAC family, Black et al. 1999): 32-bit words in pairs, each plus its own
// 32-bit key, multiplied into 64 bits and summed (almost-universal), then MurmurHash3's 64-bit
// finaliser; never 0. The multiplies are independent: a chain of one multiply-mix per word, as
// before, cost ~60 cycles of latency per triangle and ~400 per 128-byte sub-grid block in every
// build. The tail is zero-padded and the length is hashed too.
inline uint64_t nh_key(const void* data, size_t bytes) {
  const auto* p = static_cast<const uint8_t*>(data);
  auto key = [](size_t i) { return uint32_t(0x9E3779B9u * uint32_t(i + 1) ^ 0x7F4A7C15u); };
  uint64_t h = bytes;
  auto pair = [&](size_t i, const uint32_t(&w)[2]) {
    h += uint64_t(uint32_t(w[0] + key(i / 4))) * uint64_t(uint32_t(w[1] + key(i / 4 + 1)));
  };
  size_t i = 0;
  for (; i + 8 <= bytes; i += 8) {  // whole pairs: loads of a constant size
    uint32_t w[2];
    std::memcpy(w, p + i, 8);
    pair(i, w);
  }
  if (i < bytes) {
    uint32_t w[2] = {0, 0};
    std::memcpy(w, p + i, bytes - i);
    pair(i, w);
  }
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDULL;
  h ^= h >> 33;
  h *= 0xC4CEB9FE1A85EC53ULL;
  h ^= h >> 33;
  return h | 1;
}

}  // namespace slim
