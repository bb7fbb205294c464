// Output files that are either complete or absent: every file slimrt writes (images, JSON,
// plots) goes through write_atomically(), so a full disk, a quota, an I/O error or a second
// process writing the same name never leaves a truncated or mixed file behind.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

namespace slim {

// Writes `path` through a temporary file in the same folder: fill(tmp) writes the temporary file
// by name (it may open and truncate it), then the file is flushed to disk (fsync), checked
// (non-empty unless allow_empty), renamed onto `path` (rename(2) replaces it in one step) and the
// folder is flushed too. A symbolic link is followed: its target is replaced, the link stays.
// A character device (/dev/null) or a named pipe is written in place (fill gets its name); a
// pipe without a reader is an error at once instead of a wait without end.
// On any failure, including an exception from fill, the temporary file is removed and
// slim::Error names `path` and the system error (e.g. "No space left on device").
void write_atomically(const std::string& path, const std::function<void(const std::string&)>& fill,
                      bool allow_empty = false);

// write_atomically() of a byte string.
void write_file_atomically(const std::string& path, std::string_view bytes);

// Checks before any long work that `path` can be written: its folder (that of the link's target
// for a symbolic link) exists and accepts a new file (a temporary one is created and removed),
// and `path` is not a folder; a device or named pipe must be writable by this user. Throws
// slim::Error naming the path, what was expected and the system error.
void check_output_path(const std::string& path);

// Memory the loaders and the CLI's buffers may use: half the machine's physical memory
// (sysconf(_SC_PHYS_PAGES) * page size), at least 256 MiB.
uint64_t memory_budget();

// "1.5 GiB" style byte count for messages.
std::string format_bytes(uint64_t bytes);

}  // namespace slim
