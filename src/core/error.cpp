#include "slimrt/error.h"

namespace slim {

void throw_at_line(const std::string& file, uint64_t line, const std::string& msg) {
  throw Error(file + ":" + std::to_string(line) + ": " + msg);
}

void throw_at_byte(const std::string& file, uint64_t offset, const std::string& msg) {
  throw Error(file + ": byte " + std::to_string(offset) + ": " + msg);
}

}  // namespace slim
