// file_io.cpp: whole-file reads and atomic writes.
#include "volreel/format/file_io.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>

#include "volreel/format/error.hpp"

namespace volreel::format::detail {

namespace fs = std::filesystem;

std::vector<std::byte> read_whole_file(const fs::path& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) throw FormatError(path, std::string("cannot open: ") + std::strerror(errno));
  std::vector<std::byte> bytes;
  std::byte chunk[1 << 16];
  for (;;) {
    const std::size_t got = std::fread(chunk, 1, sizeof chunk, f);
    bytes.insert(bytes.end(), chunk, chunk + got);
    if (got < sizeof chunk) break;
  }
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed)
    throw FormatError(path, "read error after " + std::to_string(bytes.size()) + " bytes");
  return bytes;
}

void write_file_atomically(const fs::path& path, std::span<const std::byte> bytes) {
  const fs::path tmp = path.string() + ".tmp-" + std::to_string(getpid());
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) throw FormatError(tmp, std::string("cannot create: ") + std::strerror(errno));
  const std::size_t put = std::fwrite(bytes.data(), 1, bytes.size(), f);
  const bool flushed = std::fflush(f) == 0;
  const bool closed = std::fclose(f) == 0;
  std::error_code ec;
  if (put != bytes.size() || !flushed || !closed) {
    fs::remove(tmp, ec);
    throw FormatError(tmp, "write failed after " + std::to_string(put) + " of " +
                               std::to_string(bytes.size()) + " bytes (disk full?)");
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw FormatError(path, "cannot rename '" + tmp.string() + "' to it: " + ec.message());
  }
}

}  // namespace volreel::format::detail
