// core/large_array.h: the huge-page buffers of the builds (alignment, sizes, overflow refusal).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <new>

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
      // Huge-page candidates are 2 MB aligned: temporaries from 2 MB, kept buffers only where
      // the rounding adds at most 1/32 (5 MB + rounding to 6 MB adds 20%: not kept on huge pages).
      const bool huge = bytes >= (size_t(2) << 20) && (!kept || bytes % (size_t(2) << 20) == 0);
      if (huge) {
        EXPECT_EQ(reinterpret_cast<uintptr_t>(p) % (size_t(2) << 20), 0u);
      }
      static_cast<char*>(p)[bytes - 1] = 1;  // the whole range is usable
      std::free(p);
    }
  EXPECT_EQ(large_alloc(0), nullptr);
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
