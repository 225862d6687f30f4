// error.hpp: the error every volreel format reader throws on a bad file.
#pragma once

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

namespace volreel::format {

/// A file that is missing, short, corrupt or of an unknown version, or a write that failed.
/// The message reads "FILE: offset N: expected E, found F" (offset omitted where it means nothing),
/// so a user can tell which file is bad, where, and how.
class FormatError : public std::runtime_error {
 public:
  static constexpr std::uint64_t no_offset = ~std::uint64_t{0};

  FormatError(const std::filesystem::path& file, std::uint64_t offset, const std::string& expected,
              const std::string& found);
  /// An error that is not about a byte position (cannot open, cannot rename, ...).
  FormatError(const std::filesystem::path& file, const std::string& what);

  const std::filesystem::path& file() const noexcept { return file_; }
  /// Byte offset of the bad field, or no_offset.
  std::uint64_t offset() const noexcept { return offset_; }

 private:
  std::filesystem::path file_;
  std::uint64_t offset_ = no_offset;
};

}  // namespace volreel::format
