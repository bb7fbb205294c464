// write_atomically (slimrt/output.h) flushes the finished file and then its folder to disk, and
// a failed flush is an error that leaves nothing behind. The test binary interposes fsync(2):
// the definition below takes the place of the C library's for every call from this executable
// (the static slimrt library included), records what each call flushed, and can fail on demand.
// Unarmed, it only forwards to the C library's fsync.
#include <dlfcn.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <string>
#include <vector>

#include "slimrt/output.h"
#include "temp_dir.h"
#include "test_util.h"

namespace {

struct SyncCall {
  dev_t dev;
  ino_t ino;
  bool folder;
};

struct SyncRecorder {
  std::mutex mutex;
  bool armed = false;
  std::vector<SyncCall> calls;
  int fail_files = 0;    // errno for fsync of a regular file (0: pass through)
  int fail_folders = 0;  // errno for fsync of a folder
};

SyncRecorder& recorder() {
  static SyncRecorder r;
  return r;
}

// Arms the recorder for one scope.
struct Armed {
  explicit Armed(int fail_files = 0, int fail_folders = 0) {
    SyncRecorder& r = recorder();
    std::lock_guard<std::mutex> lock(r.mutex);
    r.calls.clear();
    r.armed = true;
    r.fail_files = fail_files;
    r.fail_folders = fail_folders;
  }
  ~Armed() {
    SyncRecorder& r = recorder();
    std::lock_guard<std::mutex> lock(r.mutex);
    r.armed = false;
  }
  std::vector<SyncCall> calls() const {
    SyncRecorder& r = recorder();
    std::lock_guard<std::mutex> lock(r.mutex);
    return r.calls;
  }
};

struct stat stat_of(const std::string& path) {
  struct stat st {};
  EXPECT_EQ(::stat(path.c_str(), &st), 0) << path;
  return st;
}

}  // namespace

extern "C" int fsync(int fd) {
  using Fn = int (*)(int);
  static const Fn real = reinterpret_cast<Fn>(::dlsym(RTLD_NEXT, "fsync"));
  SyncRecorder& r = recorder();
  {
    std::lock_guard<std::mutex> lock(r.mutex);
    if (r.armed) {
      struct stat st {};
      if (::fstat(fd, &st) == 0) {
        const bool folder = S_ISDIR(st.st_mode);
        r.calls.push_back({st.st_dev, st.st_ino, folder});
        const int fail = folder ? r.fail_folders : r.fail_files;
        if (fail) {
          errno = fail;
          return -1;
        }
      }
    }
  }
  return real ? real(fd) : 0;
}

namespace {

using slim::test::error_of;
using slim::test::TempDir;

// The finished file is flushed, then its folder (after the rename, so that the new name is on
// disk); through a symbolic link, the link target's folder.
TEST(OutputSync, FileAndFolderAreFlushed) {
  TempDir d{"slim_sync"};
  std::filesystem::create_directories(d.path("real"));
  std::filesystem::create_symlink(d.path("real/b.bin"), d.path("b.bin"));
  struct Case {
    std::string name, file, folder;
  };
  for (const Case& c : {Case{d.path("a.bin"), d.path("a.bin"), d.dir()},
                        Case{d.path("b.bin"), d.path("real/b.bin"), d.path("real")}}) {
    SCOPED_TRACE(c.name);
    std::vector<SyncCall> calls;
    {
      Armed armed;
      slim::write_file_atomically(c.name, "contents");
      calls = armed.calls();
    }
    const struct stat file = stat_of(c.file), folder = stat_of(c.folder);
    ASSERT_EQ(calls.size(), 2u);
    EXPECT_FALSE(calls[0].folder);
    EXPECT_EQ(calls[0].dev, file.st_dev);
    EXPECT_EQ(calls[0].ino, file.st_ino);  // the temporary file, renamed onto the name
    EXPECT_TRUE(calls[1].folder);
    EXPECT_EQ(calls[1].dev, folder.st_dev);
    EXPECT_EQ(calls[1].ino, folder.st_ino);
  }
}

// A failed flush of the file is an error naming the system error; the old contents stay and no
// temporary file is left. A failed flush of the folder is an error too (the file is in place).
TEST(OutputSync, FailedFlushIsAnError) {
  TempDir d{"slim_sync"};
  const std::string path = d.path("a.bin");
  slim::write_file_atomically(path, "old");
  std::string msg;
  {
    Armed armed(EIO, 0);
    msg = error_of([&] { slim::write_file_atomically(path, "new contents"); });
  }
  EXPECT_NE(msg.find("cannot flush the file to disk: Input/output error"), std::string::npos)
      << msg;
  std::ifstream in(path);
  EXPECT_EQ(std::string(std::istreambuf_iterator<char>(in), {}), "old");
  EXPECT_EQ(d.entries(), 1u);
  {
    Armed armed(0, EIO);
    msg = error_of([&] { slim::write_file_atomically(path, "new contents"); });
  }
  EXPECT_NE(msg.find("cannot be flushed to disk: Input/output error"), std::string::npos) << msg;
  EXPECT_EQ(d.entries(), 1u);
}

}  // namespace
