// Whole-file input for the mesh loaders, with transparent .xz decompression (liblzma).
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <string_view>
#include <utility>

namespace slim::detail {

// Memory the xz decoder may use (xz -9 needs 65 MiB; dictionaries above 1 GiB are refused).
constexpr uint64_t kXzMemLimit = uint64_t(1) << 30;

// A file's bytes in one malloc'd block. Decompression grows it with realloc, which glibc does
// with mremap for large blocks: no copy, and only the pages written so far are resident.
class FileBytes {
 public:
  FileBytes() = default;
  FileBytes(FileBytes&& o) noexcept : p_(o.p_), n_(o.n_), cap_(o.cap_) {
    o.p_ = nullptr, o.n_ = o.cap_ = 0;
  }
  FileBytes& operator=(FileBytes&& o) noexcept {
    std::swap(p_, o.p_), std::swap(n_, o.n_), std::swap(cap_, o.cap_);
    return *this;
  }
  ~FileBytes() { std::free(p_); }
  std::string_view view() const { return {p_, n_}; }
  size_t size() const { return n_; }

 private:
  friend struct FileBytesAccess;
  char* p_ = nullptr;
  size_t n_ = 0, cap_ = 0;
};

// Largest plain or decompressed file accepted, in bytes held in memory: `limit` if nonzero, else
// slim::memory_budget() (half the machine's memory). A decompression bomb stops here with an
// Error instead of exhausting memory.
uint64_t max_file_bytes(uint64_t limit = 0);

// True if `path` ends with ".xz" (case-insensitive).
bool has_xz_suffix(const std::string& path);

// Reads the whole file `path` into memory. If the name ends with ".xz" the content is decompressed
// (concatenated xz streams allowed). Throws slim::Error naming the file on a missing or unreadable
// file, a file or decompressed content larger than max_file_bytes(limit), and "<file>: byte N:
// ..." (N = offset in the compressed file) on bad magic, corrupt or truncated xz data, or a stream
// needing more than kXzMemLimit to decode. Byte offsets reported later by the format parsers refer
// to the returned (decompressed) bytes.
FileBytes read_file(const std::string& path, uint64_t limit = 0);

// Opens the mesh file `path` for reading (the caller fcloses it) and gives its size: checked to be
// a regular file before it is opened, so that a FIFO or device cannot block the open. Throws
// slim::Error naming the file (read_file's messages).
std::FILE* open_mesh_file(const std::string& path, uint64_t& size);

// Decompresses an in-memory .xz image; `source` names it in errors. Used by read_file and tests.
std::string xz_decompress(const std::string& source, const void* data, size_t size,
                          uint64_t limit = 0);

}  // namespace slim::detail
