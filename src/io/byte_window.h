// A moving read window over a file, or a fixed one over bytes already in memory: the one input
// the PLY and OBJ parsers see, so that the whole-file readers and the face streams share them.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>
#include <vector>

namespace slim::detail {

class ByteWindow {
 public:
  // Bytes in memory (the whole file image); parsing starts at `start`. Nothing is ever read.
  ByteWindow(std::string_view data, uint64_t start);
  // Reads the file `path` from byte `start` through a buffer of about `window` bytes. `lines`:
  // the window always ends just after a '\n' or '\r' (or at the end of the file), so that a text
  // token never straddles two windows ('\r' ends a window too: OBJ allows it as a line end). Throws
  // slim::Error naming the file if it cannot be read.
  ByteWindow(const std::string& path, uint64_t start, size_t window, bool lines);
  ~ByteWindow();
  ByteWindow(const ByteWindow&) = delete;
  ByteWindow& operator=(const ByteWindow&) = delete;

  const char* cur = nullptr;  // parse position, advanced by the parser
  const char* end = nullptr;  // end of the bytes the parser may look at

  // Absolute file offset of `p` (a pointer into the current window).
  uint64_t offset(const char* p) const { return base_ + uint64_t(p - buf_); }
  uint64_t total() const { return total_; }                   // file size in bytes
  uint64_t left() const { return total_ - offset(cur); }      // bytes from cur to the end of file
  bool at_end() const { return cur == end && eof_window(); }  // nothing left at all

  // Binary: makes at least n bytes available at cur (moving or growing the window). False if
  // fewer than n bytes are left in the file.
  bool ensure(size_t n) { return size_t(end - cur) >= n || refill(n); }
  // Text: moves the window so that it holds more complete lines after cur. False at the end of
  // the file. A line longer than kMaxLine throws slim::Error.
  bool more() { return refill(0); }
  // Restarts at absolute offset `off`.
  void seek(uint64_t off);
  // Bytes of buffer held (for memory accounting).
  size_t buffer_bytes() const { return owned_.capacity(); }

  static constexpr size_t kMaxLine = size_t(256) << 20;

 private:
  bool eof_window() const { return base_ + uint64_t(valid_ - buf_) >= total_ && end == valid_; }
  bool refill(size_t need);

  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<char> owned_;
  const char* buf_ = nullptr;    // window start (file offset base_)
  const char* valid_ = nullptr;  // end of the bytes read into the window
  uint64_t base_ = 0, total_ = 0;
  size_t window_ = 0;
  bool lines_ = false;
};

}  // namespace slim::detail
