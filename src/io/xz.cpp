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
#include <vector>

#include "slimrt/error.h"

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

// Runs the xz stream decoder. `fill(strm)` points strm.next_in/avail_in at the next compressed
// bytes and returns false at the end of the input.
template <class Fill>
std::string decode(const std::string& source, Fill&& fill, uint64_t size_hint) {
  lzma_stream s = LZMA_STREAM_INIT;
  if (lzma_stream_decoder(&s, kXzMemLimit, LZMA_CONCATENATED) != LZMA_OK)
    throw Error(source + ": cannot initialise the xz decoder");
  LzmaGuard guard{&s};

  std::string out;
  // Typical meshes compress 2x-4x; start near the final size and grow by doubling.
  out.resize(size_t(std::clamp<uint64_t>(size_hint * 3, 1 << 16, uint64_t(1) << 30)));
  s.next_out = reinterpret_cast<uint8_t*>(out.data());
  s.avail_out = out.size();
  lzma_action action = LZMA_RUN;
  for (;;) {
    if (s.avail_in == 0 && action == LZMA_RUN && !fill(s)) action = LZMA_FINISH;
    if (s.avail_out == 0) {
      size_t used = out.size();
      if (used >= kMaxFileBytes)
        throw_at_byte(source, s.total_in,
                      "xz data decompresses to more than the limit of " + mib(kMaxFileBytes));
      out.resize(size_t(std::min<uint64_t>(uint64_t(used) * 2, kMaxFileBytes)));
      s.next_out = reinterpret_cast<uint8_t*>(out.data()) + used;
      s.avail_out = out.size() - used;
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
  out.resize(size_t(s.total_out));
  out.shrink_to_fit();
  return out;
}

}  // namespace

bool has_xz_suffix(const std::string& path) {
  if (path.size() < 3) return false;
  std::string e = path.substr(path.size() - 3);
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e == ".xz";
}

std::string xz_decompress(const std::string& source, const void* data, size_t size) {
  bool given = false;
  auto fill = [&](lzma_stream& s) {
    if (given) return false;
    given = true;
    s.next_in = static_cast<const uint8_t*>(data);
    s.avail_in = size;
    return size > 0;
  };
  return decode(source, fill, size);
}

std::string read_file(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0)
    throw Error(path + ": cannot open file: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) throw Error(path + ": not a regular file");
  FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) throw Error(path + ": cannot open file: " + std::strerror(errno));
  uint64_t file_bytes = uint64_t(st.st_size);

  if (has_xz_suffix(path)) {
    std::vector<uint8_t> chunk(kChunkBytes);
    auto fill = [&](lzma_stream& s) {
      size_t n = std::fread(chunk.data(), 1, chunk.size(), f.get());
      if (n == 0 && std::ferror(f.get())) throw Error(path + ": read error");
      s.next_in = chunk.data();
      s.avail_in = n;
      return n > 0;
    };
    return decode(path, fill, file_bytes);
  }

  if (file_bytes > kMaxFileBytes)
    throw Error(path + ": file is larger than the limit of " + mib(kMaxFileBytes));
  std::string out(size_t(file_bytes), '\0');
  size_t n = std::fread(out.data(), 1, out.size(), f.get());
  if (n != out.size() || std::ferror(f.get())) throw_at_byte(path, n, "read error");
  return out;
}

}  // namespace slim::detail
