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

// The file a write to `path` lands in: symbolic links are followed (a relative link target is
// relative to the link's folder), so the link itself stays and its target is written.
std::string resolve_links(const std::string& path) {
  std::string p = path;
  for (int hops = 0; hops < 40; ++hops) {
    struct stat st {};
    if (::lstat(p.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return p;
    std::vector<char> buf(size_t(st.st_size > 0 ? st.st_size : 255) + 1);
    const ssize_t n = ::readlink(p.c_str(), buf.data(), buf.size());
    if (n < 0 || size_t(n) >= buf.size())
      throw Error(path + ": cannot read the symbolic link '" + p +
                  "': " + std::strerror(n < 0 ? errno : ENAMETOOLONG));
    const std::string target(buf.data(), size_t(n));
    p = target.front() == '/' ? target : (fs::path(folder_of(p)) / target).string();
  }
  throw Error(path + ": more than 40 levels of symbolic links; expected a file name");
}

// What kind of file `target` is (stat(2) follows symbolic links).
enum class Kind { absent_or_regular, device, fifo };

Kind kind_of(const std::string& path, const std::string& target) {
  struct stat st {};
  if (::stat(target.c_str(), &st) != 0) return Kind::absent_or_regular;
  if (S_ISREG(st.st_mode)) return Kind::absent_or_regular;
  if (S_ISCHR(st.st_mode)) return Kind::device;
  if (S_ISFIFO(st.st_mode)) return Kind::fifo;
  if (S_ISDIR(st.st_mode))
    throw Error(path + ": output path is an existing folder; expected a file name");
  throw Error(path + ": output path is " +
              (S_ISBLK(st.st_mode)    ? "a block device"
               : S_ISSOCK(st.st_mode) ? "a socket"
                                      : "a special file") +
              "; expected a regular file, a character device (/dev/null) or a named pipe");
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

// Creates an empty temporary file beside `target` (mode 0666 less the umask, like fopen) and
// returns its name. `path` is the name the user gave, for messages.
std::string make_temp(const std::string& path, const std::string& target, const std::string& dir) {
  std::string tmpl = dir + "/." + fs::path(target).filename().string() + ".tmp-XXXXXX";
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

// Opens a named pipe for writing without blocking: with no reader, open(2) fails with ENXIO at
// once (a blocking open would wait forever). Returns the descriptor, held open while the output
// is written so that the pipe keeps a writer.
int open_fifo(const std::string& path, const std::string& target) {
  const int fd = ::open(target.c_str(), O_WRONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd >= 0) return fd;
  if (errno == ENXIO)
    throw Error(path +
                ": named pipe has no reader; expected a process reading it (start the "
                "reader first, e.g. 'cat " +
                path + " > out &')");
  throw Error(path + ": cannot open the named pipe for writing: " + std::strerror(errno));
}

// Flushes the folder `dir` to disk, so that a rename into it survives a crash. File systems that
// cannot sync a folder (EINVAL) are accepted.
void sync_folder(const std::string& path, const std::string& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;  // a folder we may write but not read: nothing to sync through
  const int rc = ::fsync(fd);
  const int e = errno;
  ::close(fd);
  if (rc != 0 && e != EINVAL && e != EROFS)
    throw Error(path + ": the file is in place, but its folder '" + dir +
                "' cannot be flushed to disk: " + std::strerror(e));
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
  checked_folder(path);
  // The kind comes from stat(2) on the name itself: the kernel follows every link, also
  // /proc/self/fd/N links to pipes, whose readlink text ("pipe:[N]") is no path.
  const Kind kind = kind_of(path, path);
  if (kind != Kind::absent_or_regular) {
    // Devices and pipes are written in place: nothing to rename, and fsync does not apply.
    const int fifo = kind == Kind::fifo ? open_fifo(path, path) : -1;
    try {
      fill(path);
    } catch (...) {
      if (fifo >= 0) ::close(fifo);
      throw;
    }
    if (fifo >= 0) ::close(fifo);
    return;
  }
  const std::string target = resolve_links(path);
  const std::string dir = checked_folder(target);
  const std::string tmp = make_temp(path, target, dir);
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
  if (::rename(tmp.c_str(), target.c_str()) != 0)
    fail(std::string("cannot rename the finished file into place: ") + std::strerror(errno));
  sync_folder(path, dir);
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
  checked_folder(path);
  if (kind_of(path, path) != Kind::absent_or_regular) {
    // A device or a pipe: writable by this user? (A pipe's reader is checked when writing, so
    // that it may start after slimrt does.)
    if (::access(path.c_str(), W_OK) != 0)
      throw Error(path + ": cannot write: " + std::strerror(errno));
    return;
  }
  const std::string target = resolve_links(path);
  const std::string dir = checked_folder(target);
  const std::string tmp = make_temp(path, target, dir);
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
