// file_io.hpp: reads that open only regular files (never block on a FIFO, never read a device)
// and refuse files over a size limit, and atomic writes (temporary name, then rename); failures
// are FormatError naming the file. Every volreel reader of files opens them through
// open_regular_file, every writer writes through write_file_atomically.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace volreel::format::detail {

/// What `path` is, for a message: "a directory", "a FIFO (named pipe)", "a character device",
/// "a block device", "a socket", "a regular file" or "another kind of file" (mode from stat).
const char* file_kind(unsigned mode);
/// The same for a std::filesystem file type.
const char* file_kind(std::filesystem::file_type type);

/// Opens `path` read-only without blocking (O_NONBLOCK, so that a FIFO cannot stall the open),
/// refuses anything but a regular file ("is a FIFO (named pipe), expected a regular file"),
/// and returns the descriptor (blocking again) with the file's size in `size`. The caller closes
/// it. Throws FormatError naming the file.
int open_regular_file(const std::filesystem::path& path, std::uint64_t& size);

/// The whole regular file; throws FormatError naming the file if it cannot be opened or read, is
/// not a regular file, or is larger than `max_bytes` (then nothing is read).
std::vector<std::byte> read_whole_file(const std::filesystem::path& path, std::uint64_t max_bytes);

/// Size limits of the files volreel reads whole: JSON documents (manifest, series.json, tours,
/// transfer functions, scripts) and dictionaries.
constexpr std::uint64_t max_json_bytes = std::uint64_t{256} << 20;
constexpr std::uint64_t max_dictionary_bytes = std::uint64_t{1} << 30;

/// The folder inside an output folder (a container, a series, a render) where a run that
/// replaces what is there writes, to move it in once complete.
inline constexpr const char* replacement_folder_name = ".volreel-new";

/// Writes bytes to "PATH.tmp-PID" and renames it to PATH, so that a reader never sees a half
/// written file; throws FormatError (and removes the temporary) on failure.
void write_file_atomically(const std::filesystem::path& path, std::span<const std::byte> bytes);

/// This machine's name ("host" when it has none), which names of temporary files carry so that
/// machines sharing a folder tell theirs apart.
std::string host_name();

/// Checks, before long work, that `target` (a file or directory still to be written) can be
/// created: its name is not empty, and a directory can be made in the nearest directory on its
/// path that exists (`target` itself when it is one; the directory of a file `target` replaces),
/// which is tried and removed again; and `target` is not a device or FIFO (writers put a new file
/// in place by renaming it, which would replace one). Throws FormatError naming `target`,
/// `option` (e.g. "--out") and why not.
void check_writable(const std::filesystem::path& target, const std::string& option);

/// "2G", "500M", "64k", "1T" or a number of bytes -> bytes (powers of 1024), for options such as
/// --cache-size and --memory. Throws std::invalid_argument naming `option`.
std::uint64_t parse_byte_size(const std::string& text, const std::string& option);

}  // namespace volreel::format::detail
