// source.cpp: a container directory on a local file system.
#include "volreel/format/source.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::format {

namespace fs = std::filesystem;

std::string read_file_range(const fs::path& file, std::uint64_t offset, std::uint64_t bytes,
                            std::vector<std::byte>& out) {
  out.resize(bytes);
  int fd = -1;
  try {
    std::uint64_t size = 0;
    fd = detail::open_regular_file(file, size);
  } catch (const FormatError& e) {
    out.clear();
    return e.what();
  }
  std::size_t done = 0;
  std::string error;
  while (done < bytes) {
    const ssize_t n =
        ::pread(fd, out.data() + done, bytes - done, static_cast<off_t>(offset + done));
    if (n < 0) {
      if (errno == EINTR) continue;
      error = file.string() + ": offset " + std::to_string(offset + done) +
              ": read failed: " + std::strerror(errno);
      break;
    }
    if (n == 0) {
      error = file.string() + ": offset " + std::to_string(offset) + ": expected " +
              std::to_string(bytes) + " bytes, found " + std::to_string(done) + " (file truncated)";
      break;
    }
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
  if (!error.empty()) out.clear();
  return error;
}

std::string LocalRangeReader::read(const std::filesystem::path& file,
                                   std::span<const ByteRange> ranges,
                                   std::vector<std::vector<std::byte>>& out) {
  out.assign(ranges.size(), {});
  for (std::size_t i = 0; i < ranges.size(); ++i) {
    std::string error = read_file_range(file, ranges[i].offset, ranges[i].bytes, out[i]);
    if (!error.empty()) {
      out.clear();
      return error;
    }
  }
  return {};
}

LocalSource::LocalSource(fs::path dir) : dir_(std::move(dir)), location_(dir_.string()) {
  if (location_.starts_with("http://") || location_.starts_with("https://"))
    throw FormatError(dir_, std::string("a URL, where this reads a container folder on this "
                                        "machine (") +
                                url_readers + ")");
  std::error_code ec;
  const fs::file_status status = fs::status(dir_, ec);
  if (ec && ec != std::errc::no_such_file_or_directory)
    throw FormatError(dir_, "cannot open the container: " + ec.message());
  if (!fs::exists(status)) throw FormatError(dir_, "not a volreel container (no such directory)");
  if (!fs::is_directory(status))
    throw FormatError(dir_, std::string("not a volreel container: it is ") +
                                detail::file_kind(status.type()) +
                                ", a container is a directory (NAME.vreel)");
  const fs::file_status manifest = fs::symlink_status(dir_ / "manifest.json", ec);
  if (ec && ec != std::errc::no_such_file_or_directory)
    throw FormatError(dir_ / "manifest.json", "cannot open it: " + ec.message());
  if (!fs::exists(manifest))
    throw FormatError(dir_, std::string("not a volreel container: it holds no manifest.json") +
                                (fs::exists(dir_ / "series.json", ec)
                                     ? " but a series.json: a raw series, which `volreel encode "
                                       "DIR --out NAME.vreel` makes a container of"
                                     : ""));
}

std::vector<std::byte> LocalSource::read_file(const std::string& relative,
                                              std::uint64_t max_bytes) const {
  std::vector<std::byte> bytes = detail::read_whole_file(dir_ / relative, max_bytes);
  received_ += bytes.size();
  return bytes;
}

std::vector<std::byte> LocalSource::read_range(const std::string& relative, std::uint64_t offset,
                                               std::uint64_t bytes) const {
  std::vector<std::byte> out;
  const fs::path path = dir_ / relative;
  const std::string error = read_file_range(path, offset, bytes, out);
  // The message begins with the file's name, as FormatError writes it.
  const std::size_t prefix = path.string().size() + 2;
  if (!error.empty()) throw FormatError(path, error.size() > prefix ? error.substr(prefix) : error);
  received_ += out.size();
  return out;
}

std::uint64_t LocalSource::bytes_received() const {
  return received_;
}

std::shared_ptr<RangeReader> LocalSource::brick_reader() const {
  return std::make_shared<LocalRangeReader>();
}

}  // namespace volreel::format
