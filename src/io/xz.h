// Whole-file input for the mesh loaders, with transparent .xz decompression (liblzma).
#pragma once

#include <cstdint>
#include <string>

namespace slim::detail {

// Largest plain or decompressed file the loaders accept (a binary PLY of about 400M triangles).
// A decompression bomb stops here with an Error instead of exhausting memory.
constexpr uint64_t kMaxFileBytes = uint64_t(8) << 30;
// Memory the xz decoder may use (xz -9 needs 65 MiB; dictionaries above 1 GiB are refused).
constexpr uint64_t kXzMemLimit = uint64_t(1) << 30;

// True if `path` ends with ".xz" (case-insensitive).
bool has_xz_suffix(const std::string& path);

// Reads the whole file `path` into memory. If the name ends with ".xz" the content is decompressed
// (concatenated xz streams allowed). Throws slim::Error naming the file on a missing or unreadable
// file, and "<file>: byte N: ..." (N = offset in the compressed file) on bad magic, corrupt or
// truncated xz data, or a stream needing more than kXzMemLimit to decode. Byte offsets reported
// later by the format parsers refer to the returned (decompressed) bytes.
std::string read_file(const std::string& path);

// Decompresses an in-memory .xz image; `source` names it in errors. Used by read_file and tests.
std::string xz_decompress(const std::string& source, const void* data, size_t size);

}  // namespace slim::detail
