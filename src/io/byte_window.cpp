// ByteWindow: see byte_window.h.
#include "io/byte_window.h"

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "io/xz.h"
#include "slimrt/error.h"

namespace slim::detail {

ByteWindow::ByteWindow(std::string_view data, uint64_t start) {
  buf_ = data.data();
  valid_ = end = buf_ + data.size();
  total_ = data.size();
  cur = buf_ + std::min<uint64_t>(start, data.size());
}

ByteWindow::ByteWindow(const std::string& path, uint64_t start, size_t window, bool lines)
    : path_(path), window_(std::max<size_t>(window, 4096)), lines_(lines) {
  file_ = open_mesh_file(path, total_);
  owned_.resize(window_);
  seek(start);
}

ByteWindow::~ByteWindow() {
  if (file_) std::fclose(file_);
}

void ByteWindow::seek(uint64_t off) {
  if (!file_) {
    cur = buf_ + std::min<uint64_t>(off, total_);
    return;
  }
  off = std::min(off, total_);
  if (fseeko(file_, off_t(off), SEEK_SET) != 0)
    throw Error(path_ + ": cannot seek to byte " + std::to_string(off) + ": " +
                std::strerror(errno));
  base_ = off;
  buf_ = valid_ = cur = end = owned_.data();
}

bool ByteWindow::refill(size_t need) {
  if (!file_) return false;  // in memory: there is nothing beyond `end`
  // Keep [cur, valid_): move it to the front of the buffer.
  const size_t kept = size_t(valid_ - cur);
  const size_t cur_off = size_t(cur - buf_);
  std::memmove(owned_.data(), cur, kept);
  base_ += cur_off;
  // Read until the buffer is full or the file ends.
  size_t have = kept;
  // Never past the size seen at open: a file that grows meanwhile is read as it was.
  auto read_more = [&]() {
    const size_t limit = size_t(std::min<uint64_t>(owned_.size(), total_ - base_));
    while (have < limit) {
      const size_t got = std::fread(owned_.data() + have, 1, limit - have, file_);
      if (got == 0) {
        if (std::ferror(file_))
          throw Error(path_ + ": read error at byte " + std::to_string(base_ + have) + ": " +
                      std::strerror(errno));
        total_ = base_ + have;  // the file ended early (or shrank): its end is here
        break;
      }
      have += got;
    }
  };
  if (owned_.size() < std::max(need, window_)) owned_.resize(std::max(need, window_));
  buf_ = cur = owned_.data();
  read_more();
  valid_ = buf_ + have;
  const bool file_end = base_ + have >= total_;
  if (!lines_) {
    end = valid_;
    return have >= need;
  }
  for (;;) {
    if (file_end || base_ + have >= total_) {
      end = valid_;
      return end > cur;
    }
    const void* nl = nullptr;
    for (size_t i = have; i-- > 0;)
      if (buf_[i] == '\n' || buf_[i] == '\r') {
        nl = buf_ + i;
        break;
      }
    if (nl) {
      end = static_cast<const char*>(nl) + 1;
      return true;
    }
    if (owned_.size() >= kMaxLine)
      throw Error(path_ + ": byte " + std::to_string(base_) + ": a line longer than " +
                  std::to_string(kMaxLine >> 20) + " MiB; expected text lines");
    owned_.resize(std::min(owned_.size() * 2, kMaxLine));
    buf_ = cur = owned_.data();
    read_more();
    valid_ = buf_ + have;
  }
}

}  // namespace slim::detail
