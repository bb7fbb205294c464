// core/large_array.h: the huge-page buffers of the builds (alignment, sizes, overflow refusal).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>
#endif

#include "core/large_array.h"

namespace slim {
namespace {

TEST(LargeArray, AlignmentAndSizes) {
  for (bool kept : {false, true})
    for (size_t bytes : {size_t(1), size_t(100), size_t(4096), size_t(2) << 20,
                         (size_t(2) << 20) + 1, size_t(5) << 20}) {
      SCOPED_TRACE(std::to_string(bytes) + (kept ? " kept" : ""));
      void* p = large_alloc(bytes, 64, kept);
      ASSERT_NE(p, nullptr);
      EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % 64, 0u);
      // Huge-page candidates (2 MB and more, kept or not) are 2 MB aligned.
      if (bytes >= (size_t(2) << 20)) {
        EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % (size_t(2) << 20), 0u);
      }
      static_cast<char*>(p)[bytes - 1] = 1;  // the whole range is usable
      std::free(p);
    }
  EXPECT_EQ(large_alloc(0), nullptr);
}

// A kept buffer whose rounding to whole huge pages would add more than 1/32 is advised as huge
// pages only over its whole 2 MB pages: once it is touched throughout, no page past its end is
// resident (the memory figures count its bytes). 5 MB: rounding to 6 MB would add 20%.
TEST(LargeArray, KeptBufferIsNeverBackedPastItsEnd) {
#if defined(__linux__)
  const size_t page = size_t(sysconf(_SC_PAGESIZE));
  for (size_t bytes : {(size_t(5) << 20) + 100, (size_t(9) << 20) + 4096 * 3}) {
    SCOPED_TRACE(bytes);
    auto* p = static_cast<unsigned char*>(large_alloc(bytes, 64, /*kept=*/true));
    ASSERT_NE(p, nullptr);
    for (size_t i = 0; i < bytes; i += 512) p[i] = 1;
    p[bytes - 1] = 1;
    // From the first page boundary past the last byte to the end of its huge page, within the
    // mapping that holds the last byte (the next mapping, a library say, has pages of its own).
    const uintptr_t last = reinterpret_cast<uintptr_t>(p) + bytes - 1;
    const size_t end = (last + page) / page * page;
    size_t huge_end = (end + (size_t(2) << 20) - 1) / (size_t(2) << 20) * (size_t(2) << 20);
    std::ifstream maps("/proc/self/maps");
    std::string line;
    bool found = false;
    while (std::getline(maps, line)) {
      unsigned long lo = 0, hi = 0;
      if (std::sscanf(line.c_str(), "%lx-%lx", &lo, &hi) == 2 && lo <= last && last < hi) {
        huge_end = std::min<size_t>(huge_end, hi);
        found = true;
        break;
      }
    }
    ASSERT_TRUE(found) << "no mapping holds the buffer's last byte";
    size_t resident_past = 0, checked = 0;
    for (size_t a = end; a < huge_end; a += page) {
      unsigned char v = 0;
      if (mincore(reinterpret_cast<void*>(a), page, &v) == 0) {
        ++checked;
        resident_past += v & 1;
      }
    }
    EXPECT_EQ(resident_past, 0u) << "of " << checked << " mapped pages past the end";
    std::free(p);
  }
#else
  GTEST_SKIP() << "residency is checked on Linux only";
#endif
}

TEST(LargeArray, ShrinkKeepsContentsAndMovesOwnership) {
  LargeArray<uint32_t> a(1000, 7u);
  for (uint32_t i = 0; i < 1000; ++i) a[i] = i;
  a.shrink(10);
  EXPECT_EQ(a.size(), 10u);
  a.shrink(20);  // never grows
  EXPECT_EQ(a.size(), 10u);
  uint64_t sum = 0;
  for (uint32_t x : a) sum += x;
  EXPECT_EQ(sum, 45u);
  LargeArray<uint32_t> b = std::move(a);
  EXPECT_EQ(b.size(), 10u);
  EXPECT_TRUE(a.empty());
  EXPECT_EQ(b[9], 9u);
}

// A count whose byte size overflows size_t is refused, not wrapped into a small buffer.
TEST(LargeArray, OverflowingCountsAreRefused) {
  EXPECT_THROW(LargeArray<uint64_t>(SIZE_MAX / 4), std::bad_alloc);
  LargeAllocator<uint64_t> alloc;
  EXPECT_THROW(alloc.allocate(SIZE_MAX / 4), std::bad_alloc);
  LargeVector<uint32_t> v;
  EXPECT_THROW(v.reserve(SIZE_MAX / 2), std::length_error);  // std::vector's own limit first
}

}  // namespace
}  // namespace slim
