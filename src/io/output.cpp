// Complete-or-absent output files (slimrt/output.h) and the memory budget of loaders and CLI
// buffers.
#include "slimrt/output.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "slimrt/error.h"

namespace slim {
namespace {

namespace fs = std::filesystem;

std::string folder_of(const std::string& path) {
  const fs::path dir = fs::path(path).parent_path();
  return dir.empty() ? std::string(".") : dir.string();
}

// Checks that `path` names a file (not a folder) in an existing folder; returns the folder.
std::string checked_folder(const std::string& path) {
  if (path.empty()) throw Error("output path is empty; expected a file name");
  const std::string name = fs::path(path).filename().string();
  if (name.empty() || name == "." || name == "..")
    throw Error(path + ": output path names a folder; expected a file name");
  std::error_code ec;
  if (fs::is_directory(path, ec))
    throw Error(path + ": output path is an existing folder; expected a file name");
  const std::string dir = folder_of(path);
  if (!fs::is_directory(dir, ec))
    throw Error(path + ": cannot write: folder '" + dir + "' " +
                (fs::exists(dir, ec) ? "is not a folder" : "does not exist"));
  return dir;
}

// Creates an empty temporary file beside `path` (mode 0666 less the umask, like fopen) and
// returns its name.
std::string make_temp(const std::string& path, const std::string& dir) {
  std::string tmpl = dir + "/." + fs::path(path).filename().string() + ".tmp-XXXXXX";
  std::vector<char> buf(tmpl.begin(), tmpl.end());
  buf.push_back('\0');
  const int fd = ::mkstemp(buf.data());
  if (fd < 0)
    throw Error(path + ": cannot create a file in folder '" + dir + "': " + std::strerror(errno));
  const mode_t mask = ::umask(0);
  ::umask(mask);
  ::fchmod(fd, 0666 & ~mask);
  ::close(fd);
  return std::string(buf.data());
}

uint64_t cgroup_limit() {
  std::ifstream f("/sys/fs/cgroup/memory.max");
  uint64_t v = 0;
  if (f >> v) return v;  // "max" (no limit) fails to parse
  return 0;
}

}  // namespace

void write_atomically(const std::string& path, const std::function<void(const std::string&)>& fill,
                      bool allow_empty) {
  const std::string dir = checked_folder(path);
  const std::string tmp = make_temp(path, dir);
  auto fail = [&](const std::string& what) {
    ::unlink(tmp.c_str());
    throw Error(path + ": " + what);
  };
  try {
    fill(tmp);
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(std::string("cannot reopen the written file: ") + std::strerror(errno));
  struct stat st {};
  const bool empty = ::fstat(fd, &st) == 0 && st.st_size == 0;
  const int sync_rc = ::fsync(fd);
  const int sync_errno = errno;
  const int close_rc = ::close(fd);
  const int close_errno = errno;
  if (sync_rc != 0)
    fail(std::string("cannot flush the file to disk: ") + std::strerror(sync_errno));
  if (close_rc != 0) fail(std::string("cannot close the file: ") + std::strerror(close_errno));
  if (empty && !allow_empty) fail("nothing was written (0 bytes)");
  if (::rename(tmp.c_str(), path.c_str()) != 0)
    fail(std::string("cannot rename the finished file into place: ") + std::strerror(errno));
}

void write_file_atomically(const std::string& path, std::string_view bytes) {
  write_atomically(
      path,
      [&](const std::string& tmp) {
        const int fd = ::open(tmp.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
        if (fd < 0) throw Error(path + ": cannot open for writing: " + std::strerror(errno));
        size_t done = 0;
        while (done < bytes.size()) {
          const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
          if (n < 0 && errno == EINTR) continue;
          if (n <= 0) {
            const int e = n < 0 ? errno : EIO;
            ::close(fd);
            throw Error(path + ": write error after " + std::to_string(done) + " of " +
                        std::to_string(bytes.size()) + " bytes: " + std::strerror(e));
          }
          done += size_t(n);
        }
        if (::close(fd) != 0) throw Error(path + ": write error: " + std::strerror(errno));
      },
      bytes.empty());
}

void check_output_path(const std::string& path) {
  const std::string dir = checked_folder(path);
  const std::string tmp = make_temp(path, dir);
  ::unlink(tmp.c_str());
}

uint64_t memory_budget() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  uint64_t phys = pages > 0 && page > 0 ? uint64_t(pages) * uint64_t(page) : uint64_t(8) << 30;
  if (const uint64_t cg = cgroup_limit(); cg > 0 && cg < phys) phys = cg;
  return std::max<uint64_t>(phys / 2, uint64_t(256) << 20);
}

std::string format_bytes(uint64_t bytes) {
  char buf[64];
  if (bytes >= (uint64_t(1) << 30))
    std::snprintf(buf, sizeof buf, "%.1f GiB", double(bytes) / double(uint64_t(1) << 30));
  else if (bytes >= (uint64_t(1) << 20))
    std::snprintf(buf, sizeof buf, "%.1f MiB", double(bytes) / double(1 << 20));
  else
    std::snprintf(buf, sizeof buf, "%llu bytes", (unsigned long long)bytes);
  return buf;
}

}  // namespace slim
