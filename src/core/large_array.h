// Big buffers (tens to hundreds of MB for millions of primitives) backed by transparent huge pages
// where the system offers them (Linux, THP "madvise" mode, Debian's default), as Embree's own
// allocator does. The first touch of fresh memory costs a page fault per page, which on virtual
// machines is a large part of a build: a fresh 256 MB buffer took 1.0 s to fill with 4 KB pages
// and 0.05-0.6 s with 2 MB pages on a 2-core AMD VM. The random accesses of the builders and the
// pairing miss the TLB less, too.
#pragma once

#if defined(__linux__)
#include <sys/mman.h>
#endif

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

namespace slim {

// `bytes` uninitialised bytes aligned to `align` (a power of two <= 2 MB); free with std::free.
// Buffers of 2 MB or more are 2 MB-aligned and advised as huge pages. A temporary buffer is
// rounded up to whole 2 MB pages. A buffer that a scene keeps (`kept`: its memory figures count
// its bytes) is rounded up only if that adds at most 1/32 (close to Embree's os_malloc: 2 MB
// multiples, or >= 128 MB), since the kernel backs a touched huge page whole; otherwise only its
// whole 2 MB pages are advised and the tail (< 2 MB) takes 4 KB pages, so that the memory backing
// it never exceeds its bytes by more than a 4 KB page. The tail is advised MADV_NOHUGEPAGE: memory
// that malloc hands out again may lie in a range advised as huge pages for an earlier buffer (the
// advice stays with the address range after free), where touching the tail would back a whole
// huge page past the buffer's end. Before, such a buffer took 4 KB pages
// throughout: the 60 MB leaf arena of torus:1024 (bvh8-tri4v) cost ~4000 page faults per build,
// at ~15 us each on this project's VMs (a fresh 64 MB buffer: 240 ms on 4 KB pages, 4 ms on
// 2 MB pages). Throws std::bad_alloc.
inline void* large_alloc(size_t bytes, size_t align = 64, bool kept = false) {
  constexpr size_t kHuge = size_t(2) << 20;
  void* p = nullptr;
  size_t advised = 0, tail = 0;  // bytes advised as huge pages, then as no huge pages
  if (bytes >= kHuge) {
    const size_t rounded = (bytes + kHuge - 1) / kHuge * kHuge;
    const bool round_up = !kept || (rounded - bytes) <= bytes / 32;
    // posix_memalign: aligned_alloc requires a size that is a multiple of the alignment (ASan
    // enforces it), which a kept buffer that is not rounded up is not.
    if (posix_memalign(&p, kHuge, round_up ? rounded : bytes) != 0) p = nullptr;
    advised = round_up ? rounded : bytes / kHuge * kHuge;
    // The tail (madvise extends it to the end of the page holding the last byte).
    if (!round_up) tail = bytes - advised;
  } else if (bytes > 0) {
    align = std::max(align, alignof(std::max_align_t));
    p = std::aligned_alloc(align, (bytes + align - 1) / align * align);
  }
  if (!p && bytes > 0) throw std::bad_alloc();
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  if (p && advised) madvise(p, advised, MADV_HUGEPAGE);
  if (p && tail) madvise(static_cast<char*>(p) + advised, tail, MADV_NOHUGEPAGE);
#endif
  return p;
}

// Uninitialised array of trivially copyable T on large_alloc. size() can be lowered (shrink)
// without moving: the pages past the new size that were never touched cost no memory.
template <class T>
class LargeArray {
  static_assert(std::is_trivially_copyable_v<T>);

 public:
  LargeArray() = default;
  explicit LargeArray(size_t n) : n_(n) {
    if (n > SIZE_MAX / sizeof(T)) throw std::bad_alloc();
    p_ = static_cast<T*>(large_alloc(n * sizeof(T), alignof(T)));
  }
  LargeArray(size_t n, const T& value) : LargeArray(n) { std::fill(p_, p_ + n_, value); }
  ~LargeArray() { std::free(p_); }
  LargeArray(LargeArray&& o) noexcept : p_(o.p_), n_(o.n_) { o.p_ = nullptr, o.n_ = 0; }
  LargeArray& operator=(LargeArray&& o) noexcept {
    std::swap(p_, o.p_);
    std::swap(n_, o.n_);
    return *this;
  }
  LargeArray(const LargeArray&) = delete;
  LargeArray& operator=(const LargeArray&) = delete;
  void shrink(size_t n) { n_ = std::min(n, n_); }
  T* data() { return p_; }
  const T* data() const { return p_; }
  size_t size() const { return n_; }
  bool empty() const { return n_ == 0; }
  T& operator[](size_t i) { return p_[i]; }
  const T& operator[](size_t i) const { return p_[i]; }
  T* begin() { return p_; }
  T* end() { return p_ + n_; }
  const T* begin() const { return p_; }
  const T* end() const { return p_ + n_; }

 private:
  T* p_ = nullptr;
  size_t n_ = 0;
};

// std::allocator on large_alloc (`Kept`: memory a scene keeps, see large_alloc), whose resize()
// default-initialises: no write to the fresh pages of a trivial T until the caller fills them
// (in parallel, say).
template <class T, bool Kept = false>
struct LargeAllocator {
  using value_type = T;
  template <class U>
  struct rebind {
    using other = LargeAllocator<U, Kept>;
  };
  LargeAllocator() = default;
  template <class U>
  LargeAllocator(const LargeAllocator<U, Kept>&) noexcept {}
  T* allocate(size_t n) {
    if (n > SIZE_MAX / sizeof(T)) throw std::bad_alloc();
    return static_cast<T*>(large_alloc(n * sizeof(T), alignof(T), Kept));
  }
  void deallocate(T* p, size_t) noexcept { std::free(p); }
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... A>
  void construct(U* p, A&&... a) {
    ::new (static_cast<void*>(p)) U(std::forward<A>(a)...);
  }
  friend bool operator==(const LargeAllocator&, const LargeAllocator&) { return true; }
};

template <class T, bool Kept = false>
using LargeVector = std::vector<T, LargeAllocator<T, Kept>>;

}  // namespace slim
