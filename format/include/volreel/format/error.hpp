// error.hpp: the error every volreel format reader throws on a bad file, and how its messages
// (and every volreel message) write a number.
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

/// A number for a message, in 6 significant digits: "45.1235", "1e-07", "3", "inf" (where
/// std::to_string's six decimals would write 1e-07 as "0.000000").
std::string number_text(double v);

}  // namespace volreel::format
