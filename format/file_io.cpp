// file_io.cpp: whole-file reads and atomic writes.
#include "volreel/format/file_io.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>

#include "volreel/format/error.hpp"

namespace volreel::format::detail {

namespace fs = std::filesystem;

const char* file_kind(fs::file_type type) {
  switch (type) {
    case fs::file_type::regular:
      return "a regular file";
    case fs::file_type::directory:
      return "a directory";
    case fs::file_type::fifo:
      return "a FIFO (named pipe)";
    case fs::file_type::character:
      return "a character device";
    case fs::file_type::block:
      return "a block device";
    case fs::file_type::socket:
      return "a socket";
    default:
      return "another kind of file";
  }
}

const char* file_kind(unsigned mode) {
  // stat's mode as the std::filesystem type it names, so that one table names both.
  if (S_ISREG(mode)) return file_kind(fs::file_type::regular);
  if (S_ISDIR(mode)) return file_kind(fs::file_type::directory);
  if (S_ISFIFO(mode)) return file_kind(fs::file_type::fifo);
  if (S_ISCHR(mode)) return file_kind(fs::file_type::character);
  if (S_ISBLK(mode)) return file_kind(fs::file_type::block);
  if (S_ISSOCK(mode)) return file_kind(fs::file_type::socket);
  return file_kind(fs::file_type::unknown);
}

int open_regular_file(const fs::path& path, std::uint64_t& size) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK | O_NOCTTY);
  if (fd < 0) throw FormatError(path, std::string("cannot open: ") + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const int e = errno;
    ::close(fd);
    throw FormatError(path, std::string("cannot stat: ") + std::strerror(e));
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    throw FormatError(path, FormatError::no_offset, "a regular file",
                      file_kind(static_cast<unsigned>(st.st_mode)));
  }
  const int flags = ::fcntl(fd, F_GETFL);
  if (flags < 0 || ::fcntl(fd, F_SETFL, flags & ~O_NONBLOCK) != 0) {
    const int e = errno;
    ::close(fd);
    throw FormatError(path, std::string("cannot set blocking reads: ") + std::strerror(e));
  }
  size = static_cast<std::uint64_t>(st.st_size);
  return fd;
}

std::vector<std::byte> read_whole_file(const fs::path& path, std::uint64_t max_bytes) {
  std::uint64_t size = 0;
  const int fd = open_regular_file(path, size);
  if (size > max_bytes) {
    ::close(fd);
    throw FormatError(path, FormatError::no_offset,
                      "at most " + std::to_string(max_bytes) + " bytes",
                      std::to_string(size) + " bytes");
  }
  std::vector<std::byte> bytes(static_cast<std::size_t>(size));
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int e = errno;
      ::close(fd);
      throw FormatError(path, done, std::to_string(size) + " bytes (its size)",
                        n == 0 ? "the end of the file (it shrank while being read)"
                               : std::string("a read error: ") + std::strerror(e));
    }
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
  return bytes;
}

namespace {

/// Throws unless `path` is absent, a regular file or a directory (a device or FIFO there would
/// be replaced by the rename that puts a new file in place).
void refuse_special_file(const fs::path& path, const std::string& option) {
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (!fs::exists(status) || fs::is_regular_file(status) || fs::is_directory(status)) return;
  throw FormatError(path, "cannot write it" + (option.empty() ? "" : " (" + option + ")") +
                              ": it is " + file_kind(status.type()) +
                              ", and volreel writes a new file and renames it into place, which "
                              "would replace it: choose another name");
}

}  // namespace

void write_file_atomically(const fs::path& path, std::span<const std::byte> bytes) {
  refuse_special_file(path, "");
  const fs::path tmp = path.string() + ".tmp-" + std::to_string(getpid());
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f)
    throw FormatError(path, std::string("cannot create it (its temporary '") +
                                tmp.filename().string() + "' first): " + std::strerror(errno));
  const std::size_t put = std::fwrite(bytes.data(), 1, bytes.size(), f);
  const bool flushed = std::fflush(f) == 0;
  const bool closed = std::fclose(f) == 0;
  std::error_code ec;
  if (put != bytes.size() || !flushed || !closed) {
    fs::remove(tmp, ec);
    throw FormatError(path, "write failed after " + std::to_string(put) + " of " +
                                std::to_string(bytes.size()) + " bytes (disk full?)");
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw FormatError(path, "cannot rename '" + tmp.string() + "' to it: " + ec.message());
  }
}

std::uint64_t parse_byte_size(const std::string& text, const std::string& option) {
  const auto bad = [&] {
    return std::invalid_argument(option + " " + text +
                                 ": expected a size such as 2G, 500M, 64k or a number of bytes");
  };
  double value = 0;
  std::size_t used = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw bad();
  }
  std::string unit = text.substr(used);
  if (!unit.empty() && (unit.back() == 'B' || unit.back() == 'b')) unit.pop_back();
  if (!unit.empty() && unit.back() == 'i') unit.pop_back();
  double scale = 1;
  if (unit == "k" || unit == "K")
    scale = 1024.0;
  else if (unit == "M" || unit == "m")
    scale = 1024.0 * 1024;
  else if (unit == "G" || unit == "g")
    scale = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "t")
    scale = 1024.0 * 1024 * 1024 * 1024;
  else if (!unit.empty())
    throw bad();
  const double bytes = value * scale;
  if (!std::isfinite(bytes) || bytes < 0 || bytes > 1e18) throw bad();
  return static_cast<std::uint64_t>(bytes);
}

std::string host_name() {
  char name[256] = {};
  if (::gethostname(name, sizeof name - 1) != 0 || name[0] == 0) return "host";
  return name;
}

void check_writable(const fs::path& target, const std::string& option) {
  if (target.empty())
    throw std::invalid_argument(option + " is empty: expected the name of what to write");
  refuse_special_file(target, option);
  std::error_code ec;
  fs::path at = fs::absolute(target, ec);
  if (ec) throw FormatError(target, "cannot write it (" + option + "): " + ec.message());
  // A file there is replaced: where it goes is its directory.
  if (fs::exists(fs::symlink_status(at, ec)) && !fs::is_directory(fs::status(at, ec)))
    at = at.parent_path();
  while (!fs::exists(fs::symlink_status(at, ec)) && at.has_parent_path() && at != at.parent_path())
    at = at.parent_path();
  const fs::file_status status = fs::status(at, ec);
  if (!fs::is_directory(status))
    throw FormatError(target, "cannot write it (" + option + "): '" + at.string() + "' is " +
                                  file_kind(status.type()) + ", not a directory");
  static std::atomic<unsigned> counter{0};
  const fs::path probe = at / (".volreel-write-check-" + host_name() + "-" +
                               std::to_string(::getpid()) + "-" + std::to_string(counter++));
  if (!fs::create_directory(probe, ec) || ec)
    throw FormatError(
        target, "cannot write it (" + option + "): cannot create anything in '" + at.string() +
                    "': " + (ec ? ec.message() : std::string("a check's name is taken")));
  fs::remove(probe, ec);
}

}  // namespace volreel::format::detail
