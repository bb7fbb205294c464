// core/large_array.h: the huge-page buffers of the builds (alignment, sizes, overflow refusal).
#include <gtest/gtest.h>

#include <cstdint>
#include <cstdlib>
#include <new>

#if defined(__linux__)
#include <malloc.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>
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

#if defined(__linux__)
// The VmFlags line of /proc/self/smaps for the mapping that holds address a, and its range.
struct Vma {
  uintptr_t lo = 0, hi = 0;
  std::string flags;
};
Vma vma_of(uintptr_t a) {
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  Vma v;
  bool in = false;
  while (std::getline(smaps, line)) {
    unsigned long lo = 0, hi = 0;
    char dash = 0;
    if (std::sscanf(line.c_str(), "%lx%c%lx", &lo, &dash, &hi) == 3 && dash == '-') {
      in = lo <= a && a < hi;
      if (in) v.lo = lo, v.hi = hi;
    } else if (in && line.rfind("VmFlags:", 0) == 0) {
      v.flags = line.substr(8) + " ";
      return v;
    }
  }
  return v;
}
bool has_flag(const Vma& v, const char* f) {
  return v.flags.find(std::string(" ") + f + " ") != std::string::npos;
}

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
constexpr bool kGlibcMalloc = false;  // the sanitizer's allocator: mallopt does not apply
#else
constexpr bool kGlibcMalloc = true;
#endif

// In a process of its own (see the test): 0 when every check passed, else a message on stderr.
int kept_buffer_checks() {
  const size_t page = size_t(sysconf(_SC_PAGESIZE));
  constexpr size_t kHuge = size_t(2) << 20;
  // Buffers below 32 MB from the heap, which grows by 4 MB more than asked: the memory past a
  // buffer's end is then fresh heap, mapped and never touched.
  if (kGlibcMalloc) {
    mallopt(M_MMAP_THRESHOLD, 32 << 20);
    mallopt(M_TOP_PAD, 4 << 20);
  }
  int failures = 0;
  for (size_t bytes : {(size_t(5) << 20) + 100, (size_t(9) << 20) + 4096 * 3}) {
    // From the first page boundary past the last byte to the end of its huge page.
    std::vector<unsigned char> before(kHuge / page), after(kHuge / page);
    auto* p = static_cast<unsigned char*>(large_alloc(bytes, 64, /*kept=*/true));
    const uintptr_t first = reinterpret_cast<uintptr_t>(p), last = first + bytes - 1;
    const uintptr_t end = (last + page) / page * page;
    const uintptr_t huge_end = (end + kHuge - 1) / kHuge * kHuge;
    const size_t n = (huge_end - end) / page;
    auto residency = [&](std::vector<unsigned char>& r) {
      for (size_t k = 0; k < n; ++k)
        if (mincore(reinterpret_cast<void*>(end + k * page), page, &r[k]) != 0) r[k] = 2;
    };
    // The advice: huge pages up to the end of the last whole 2 MB page, and from there no huge
    // page for the tail, whatever earlier advice its address range had.
    const uintptr_t whole = first + bytes / kHuge * kHuge;
    const Vma head = vma_of(whole - 1), tail = vma_of(last);
    if (!has_flag(head, "hg") || head.hi != whole) {
      std::fprintf(stderr,
                   "%zu bytes: the mapping [%lx, %lx) of the last whole huge page has flags "
                   "'%s'; expected hg, ending at %lx\n",
                   bytes, (unsigned long)head.lo, (unsigned long)head.hi, head.flags.c_str(),
                   (unsigned long)whole);
      ++failures;
    }
    if (!has_flag(tail, "nh") || has_flag(tail, "hg") || tail.lo != whole) {
      std::fprintf(stderr,
                   "%zu bytes: the mapping [%lx, %lx) of the last byte has flags '%s'; expected "
                   "nh, from %lx\n",
                   bytes, (unsigned long)tail.lo, (unsigned long)tail.hi, tail.flags.c_str(),
                   (unsigned long)whole);
      ++failures;
    }
    // The residency: touching the whole buffer makes no page past its end resident.
    residency(before);
    for (size_t i = 0; i < bytes; i += 512) p[i] = 1;
    p[bytes - 1] = 1;
    residency(after);
    size_t fresh = 0, newly_resident = 0;
    for (size_t k = 0; k < n; ++k) {
      if (before[k] != 0) continue;  // unmapped (2) or resident before: not the buffer's doing
      ++fresh;
      newly_resident += after[k] & 1;
    }
    if (newly_resident) {
      std::fprintf(stderr, "%zu bytes: %zu of %zu pages past the end became resident\n", bytes,
                   newly_resident, fresh);
      ++failures;
    }
    // All fresh heap but the pages malloc wrote its chunk headers into.
    if (kGlibcMalloc && fresh + 4 < n) {
      std::fprintf(stderr,
                   "%zu bytes: %zu of the %zu pages past the end were fresh heap; expected all "
                   "but malloc's headers\n",
                   bytes, fresh, n);
      ++failures;
    }
    std::free(p);
  }
  return failures;
}
#endif

// A kept buffer whose rounding to whole huge pages would add more than 1/32 is advised as huge
// pages only over its whole 2 MB pages, and its tail as no huge pages: once it is touched
// throughout, no page past its end has become resident (the memory figures count its bytes).
// 5 MB: rounding to 6 MB would add 20%. Run in a process of its own, with the memory past the end
// fresh heap (glibc: the mmap threshold and the heap's top pad set there), so that the pages
// past the end are neither another buffer's nor resident before; the advice is checked in the
// mappings' flags (/proc/self/smaps).
TEST(LargeArray, KeptBufferIsNeverBackedPastItsEnd) {
#if defined(__linux__)
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  EXPECT_EXIT(
      {
        const int failures = kept_buffer_checks();
        std::fflush(stderr);
        std::_Exit(failures);
      },
      ::testing::ExitedWithCode(0), "");
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
