// file_io.hpp: whole-file reads and atomic writes (temporary name, then rename) that report
// failures as FormatError. Every volreel writer of files goes through write_file_atomically.
#pragma once

#include <cstddef>
#include <filesystem>
#include <span>
#include <vector>

namespace volreel::format::detail {

/// The whole file; throws FormatError naming the file if it cannot be opened or read.
std::vector<std::byte> read_whole_file(const std::filesystem::path& path);

/// Writes bytes to "PATH.tmp-PID" and renames it to PATH, so that a reader never sees a half
/// written file; throws FormatError (and removes the temporary) on failure.
void write_file_atomically(const std::filesystem::path& path, std::span<const std::byte> bytes);

}  // namespace volreel::format::detail
