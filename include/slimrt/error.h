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

// A configuration that does not apply to the given meshes (for example Embree's quad geometry on
// a mesh with triangles): not a malformed input, a combination to skip and report as such.
class NotApplicable : public Error {
 public:
  explicit NotApplicable(const std::string& what) : Error(what) {}
};

// A build stopped because its progress callback (BuildOptions::progress) returned false. Nothing
// of the build is kept: every structure made so far is freed before the exception leaves
// Scene::build.
class Cancelled : public Error {
 public:
  explicit Cancelled(const std::string& what) : Error(what) {}
};

// "file:line: message" for text formats.
[[noreturn]] void throw_at_line(const std::string& file, uint64_t line, const std::string& msg);
// "file: byte N: message" for binary formats.
[[noreturn]] void throw_at_byte(const std::string& file, uint64_t offset, const std::string& msg);

}  // namespace slim
