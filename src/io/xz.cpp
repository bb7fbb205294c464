// Whole-file input for the mesh loaders, with transparent .xz decompression (liblzma's stream
// decoder, fed in 1 MiB chunks so the compressed file is never held in memory as a whole).
#include "io/xz.h"

#include <lzma.h>
#include <sys/stat.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include "slimrt/error.h"
#include "slimrt/output.h"

namespace slim::detail {
namespace {

constexpr size_t kChunkBytes = size_t(1) << 20;

struct FileCloser {
  void operator()(FILE* f) const { std::fclose(f); }
};
using FilePtr = std::unique_ptr<FILE, FileCloser>;

struct LzmaGuard {
  lzma_stream* s;
  ~LzmaGuard() { lzma_end(s); }
};

std::string mib(uint64_t bytes) { return std::to_string((bytes + (1 << 20) - 1) >> 20) + " MiB"; }

}  // namespace

struct FileBytesAccess {
  // Grows b's block to `cap` bytes (realloc: mremap for large blocks, so no copy).
  static void reserve(FileBytes& b, size_t cap) {
    if (cap <= b.cap_) return;
    char* p = static_cast<char*>(std::realloc(b.p_, cap));
    if (!p) throw std::bad_alloc();
    b.p_ = p;
    b.cap_ = cap;
  }
  static char* data(FileBytes& b) { return b.p_; }
  static size_t capacity(const FileBytes& b) { return b.cap_; }
  static void set_size(FileBytes& b, size_t n) { b.n_ = n; }
};

namespace {

// Runs the xz stream decoder. `fill(strm)` points strm.next_in/avail_in at the next compressed
// bytes and returns false at the end of the input.
template <class Fill>
FileBytes decode(const std::string& source, Fill&& fill, uint64_t size_hint, uint64_t limit) {
  lzma_stream s = LZMA_STREAM_INIT;
  if (lzma_stream_decoder(&s, kXzMemLimit, LZMA_CONCATENATED) != LZMA_OK)
    throw Error(source + ": cannot initialise the xz decoder");
  LzmaGuard guard{&s};

  FileBytes out;
  using A = FileBytesAccess;
  // Typical meshes compress 2x-4x; start near the final size and grow by doubling. Pages past
  // what was written are never touched, so the limit counts the bytes written (total_out).
  try {
    const uint64_t first = std::min<uint64_t>(std::max<uint64_t>(size_hint * 3, 1 << 16), 1 << 30);
    A::reserve(out, size_t(std::max<uint64_t>(std::min(first, limit), 1)));
  } catch (const std::bad_alloc&) {
    throw Error(source + ": out of memory while allocating the decompression buffer");
  }
  s.next_out = reinterpret_cast<uint8_t*>(A::data(out));
  s.avail_out = A::capacity(out);
  lzma_action action = LZMA_RUN;
  for (;;) {
    if (s.avail_in == 0 && action == LZMA_RUN && !fill(s)) action = LZMA_FINISH;
    if (s.avail_out == 0) {
      // Capacity goes up to limit + 1 so that an output of exactly `limit` bytes ends cleanly.
      const size_t used = A::capacity(out);
      if (used > limit)
        throw_at_byte(source, s.total_in,
                      "xz data decompresses to more than " + mib(limit) +
                          "; expected at most the memory limit (half of this machine's memory)");
      try {
        A::reserve(out, size_t(std::min<uint64_t>(uint64_t(used) * 2, limit + 1)));
      } catch (const std::bad_alloc&) {
        throw_at_byte(source, s.total_in,
                      "out of memory while growing the decompression buffer beyond " + mib(used));
      }
      s.next_out = reinterpret_cast<uint8_t*>(A::data(out)) + used;
      s.avail_out = A::capacity(out) - used;
    }
    lzma_ret ret = lzma_code(&s, action);
    if (ret == LZMA_STREAM_END) break;
    if (ret == LZMA_OK) continue;
    switch (ret) {
      case LZMA_FORMAT_ERROR:  // reported once the 12-byte stream header has been read
        throw_at_byte(source, s.total_in >= 12 ? s.total_in - 12 : 0,
                      "not xz data; expected the xz magic bytes FD 37 7A 58 5A 00");
      case LZMA_DATA_ERROR:
        throw_at_byte(source, s.total_in, "corrupt xz data (bad header, block or checksum)");
      case LZMA_BUF_ERROR:
        throw_at_byte(source, s.total_in,
                      "xz data ends early (truncated file); expected more compressed bytes");
      case LZMA_MEMLIMIT_ERROR:
        throw_at_byte(source, s.total_in,
                      "xz stream needs " + mib(lzma_memusage(&s)) + " to decompress, more than " +
                          "the limit of " + mib(kXzMemLimit));
      case LZMA_OPTIONS_ERROR:
        throw_at_byte(source, s.total_in, "unsupported xz compression options");
      case LZMA_MEM_ERROR:
        throw_at_byte(source, s.total_in, "out of memory while decompressing xz data");
      default:
        throw_at_byte(source, s.total_in, "xz decoder error " + std::to_string(int(ret)));
    }
  }
  if (s.total_out > limit)
    throw_at_byte(source, s.total_in,
                  "xz data decompresses to more than " + mib(limit) +
                      "; expected at most the memory limit (half of this machine's memory)");
  A::set_size(out, size_t(s.total_out));
  return out;
}

}  // namespace

uint64_t max_file_bytes(uint64_t limit) { return limit ? limit : memory_budget(); }

bool has_xz_suffix(const std::string& path) {
  if (path.size() < 3) return false;
  std::string e = path.substr(path.size() - 3);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e == ".xz";
}

std::string xz_decompress(const std::string& source, const void* data, size_t size,
                          uint64_t limit) {
  bool given = false;
  auto fill = [&](lzma_stream& s) {
    if (given) return false;
    given = true;
    s.next_in = static_cast<const uint8_t*>(data);
    s.avail_in = size;
    return size > 0;
  };
  return std::string(decode(source, fill, size, max_file_bytes(limit)).view());
}

std::FILE* open_mesh_file(const std::string& path, uint64_t& size) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(path + ": cannot open file: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode))
    throw Error(path + ": not a regular file (a folder or device); expected a mesh file");
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw Error(path + ": cannot open file: " + std::strerror(errno));
  size = uint64_t(st.st_size);
  return f;
}

FileBytes read_file(const std::string& path, uint64_t limit) {
  limit = max_file_bytes(limit);
  uint64_t file_bytes = 0;
  FilePtr f(open_mesh_file(path, file_bytes));

  if (has_xz_suffix(path)) {
    std::vector<uint8_t> chunk(kChunkBytes);
    auto fill = [&](lzma_stream& s) {
      size_t n = std::fread(chunk.data(), 1, chunk.size(), f.get());
      if (n == 0 && std::ferror(f.get())) throw Error(path + ": read error");
      s.next_in = chunk.data();
      s.avail_in = n;
      return n > 0;
    };
    return decode(path, fill, file_bytes, limit);
  }

  if (file_bytes > limit)
    throw Error(path + ": file is " + mib(file_bytes) + "; expected at most " + mib(limit) +
                " (the memory limit, half of this machine's memory)");
  FileBytes out;
  try {
    FileBytesAccess::reserve(out, size_t(std::max<uint64_t>(file_bytes, 1)));
  } catch (const std::bad_alloc&) {
    throw Error(path + ": out of memory while reading the file (" + mib(file_bytes) + ")");
  }
  size_t n = std::fread(FileBytesAccess::data(out), 1, size_t(file_bytes), f.get());
  if (n != file_bytes || std::ferror(f.get())) throw_at_byte(path, n, "read error");
  FileBytesAccess::set_size(out, n);
  return out;
}

}  // namespace slim::detail
