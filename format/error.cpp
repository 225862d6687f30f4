// error.cpp: FormatError messages.
#include "volreel/format/error.hpp"

#include <cstdio>

namespace volreel::format {

FormatError::FormatError(const std::filesystem::path& file, std::uint64_t offset,
                         const std::string& expected, const std::string& found)
    : std::runtime_error(
          file.string() +
          (offset == no_offset ? std::string() : ": offset " + std::to_string(offset)) +
          ": expected " + expected + ", found " + found),
      file_(file),
      offset_(offset) {}

FormatError::FormatError(const std::filesystem::path& file, const std::string& what)
    : std::runtime_error(file.string() + ": " + what), file_(file) {}

std::string number_text(double v) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", v);
  return text;
}

}  // namespace volreel::format
