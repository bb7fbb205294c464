// slimrt errors: every malformed input (file, mesh, option) is reported as a slim::Error whose
// message names the source (file), the place (line for text, byte offset for binary) and what was
// expected. The library never calls exit() and never crashes on untrusted input.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace slim {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& what) : std::runtime_error(what) {}
};

// "file:line: message" for text formats.
[[noreturn]] void throw_at_line(const std::string& file, uint64_t line, const std::string& msg);
// "file: byte N: message" for binary formats.
[[noreturn]] void throw_at_byte(const std::string& file, uint64_t offset, const std::string& msg);

}  // namespace slim
