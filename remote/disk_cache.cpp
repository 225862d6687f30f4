// disk_cache.cpp: the folder of cached byte ranges (see disk_cache.hpp).
#include "volreel/remote/disk_cache.hpp"

#include <fcntl.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>

#include "volreel/format/bytes.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::remote {

namespace fs = std::filesystem;

namespace {

constexpr char cache_magic[8] = {'V', 'R', 'C', 'A', 'C', 'H', 'E', '1'};
constexpr std::string_view entry_suffix = ".entry";

std::uint64_t fnv1a(std::string_view s) {
  std::uint64_t h = 0xcbf29ce484222325ull;
  for (const char c : s) {
    h ^= static_cast<unsigned char>(c);
    h *= 0x100000001b3ull;
  }
  return h;
}

/// The data of an entry file's bytes if they are intact and hold `key`.
std::optional<std::vector<std::byte>> parse_entry(std::span<const std::byte> b,
                                                  const std::string& key) {
  if (b.size() < 8 + 4 + 8 + 4 || std::memcmp(b.data(), cache_magic, 8) != 0) return std::nullopt;
  std::uint32_t crc = 0;
  std::memcpy(&crc, b.data() + b.size() - 4, 4);
  if (format::crc32c(b.first(b.size() - 4)) != crc) return std::nullopt;
  std::uint32_t key_bytes = 0;
  std::memcpy(&key_bytes, b.data() + 8, 4);
  if (key_bytes != key.size() || 12 + std::uint64_t{key_bytes} + 8 + 4 > b.size() ||
      std::memcmp(b.data() + 12, key.data(), key.size()) != 0)
    return std::nullopt;
  std::uint64_t data_bytes = 0;
  std::memcpy(&data_bytes, b.data() + 12 + key_bytes, 8);
  if (12 + std::uint64_t{key_bytes} + 8 + data_bytes + 4 != b.size()) return std::nullopt;
  const std::byte* data = b.data() + 12 + key_bytes + 8;
  return std::vector<std::byte>(data, data + data_bytes);
}

}  // namespace

std::string DiskCache::file_name(const std::string& key) {
  char name[17];
  std::snprintf(name, sizeof name, "%016llx", static_cast<unsigned long long>(fnv1a(key)));
  return std::string(name) + std::string(entry_suffix);
}

namespace {

/// The disk space of the file at `path` of `bytes` bytes: its blocks, at least its size.
std::uint64_t disk_bytes(const fs::path& path, std::uint64_t bytes) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return bytes;
  return std::max<std::uint64_t>(bytes, static_cast<std::uint64_t>(st.st_blocks) * 512);
}

}  // namespace

DiskCache::DiskCache(fs::path dir, std::uint64_t max_bytes)
    : dir_(std::move(dir)), max_bytes_(max_bytes) {
  std::error_code ec;
  fs::create_directories(dir_, ec);
  if (!fs::is_directory(dir_))
    throw format::FormatError(dir_, "cannot use as a cache folder: " +
                                        (ec ? ec.message() : std::string("not a directory")));
  // Existing entries, oldest use first.
  std::vector<std::pair<fs::file_time_type, std::pair<std::string, std::uint64_t>>> found;
  for (const fs::directory_entry& e : fs::directory_iterator(dir_, ec)) {
    const std::string name = e.path().filename().string();
    std::error_code e2;
    if (name.size() != 16 + entry_suffix.size() || !name.ends_with(entry_suffix) ||
        !e.is_regular_file(e2))
      continue;
    const auto size = e.file_size(e2);
    const auto time = e.last_write_time(e2);
    if (!e2) found.push_back({time, {name, size}});
  }
  std::sort(found.begin(), found.end());
  for (const auto& [time, entry] : found) {
    Entry& e = entries_[entry.first];
    e.bytes = entry.second;
    e.disk = disk_bytes(dir_ / entry.first, e.bytes);
    total_ += e.disk;
    e.used = ++clock_;
    by_use_[e.used] = entry.first;
  }
  std::lock_guard lock(mutex_);
  evict();
}

void DiskCache::touch(const std::string& name, Entry& e) {
  by_use_.erase(e.used);
  e.used = ++clock_;
  by_use_[e.used] = name;
  // The order for the next run: the file's modification time.
  const struct timespec now[2] = {{0, UTIME_NOW}, {0, UTIME_NOW}};
  ::utimensat(AT_FDCWD, (dir_ / name).c_str(), now, 0);
}

void DiskCache::forget(const std::string& name) {
  const auto it = entries_.find(name);
  if (it == entries_.end()) return;
  by_use_.erase(it->second.used);
  total_ -= it->second.disk;
  entries_.erase(it);
  std::error_code ec;
  fs::remove(dir_ / name, ec);
}

void DiskCache::evict() {
  while (total_ > max_bytes_ && !by_use_.empty()) {
    const std::string name = by_use_.begin()->second;  // a copy: forget() erases the map's
    forget(name);
  }
}

std::optional<std::vector<std::byte>> DiskCache::get(const std::string& key) {
  const std::string name = file_name(key);
  std::lock_guard lock(mutex_);
  const auto it = entries_.find(name);
  if (it == entries_.end()) {
    ++misses_;
    return std::nullopt;
  }
  std::optional<std::vector<std::byte>> data;
  try {
    data = parse_entry(format::detail::read_whole_file(dir_ / name, it->second.bytes), key);
  } catch (const format::FormatError&) {
    data.reset();
  }
  if (!data) {
    forget(name);
    ++misses_;
    return std::nullopt;
  }
  touch(name, it->second);
  ++hits_;
  return data;
}

bool DiskCache::contains(const std::string& key) const {
  std::lock_guard lock(mutex_);
  return entries_.count(file_name(key)) != 0;
}

void DiskCache::put(const std::string& key, std::span<const std::byte> data) {
  std::vector<std::byte> file;
  file.reserve(8 + 4 + key.size() + 8 + data.size() + 4);
  file.insert(file.end(), reinterpret_cast<const std::byte*>(cache_magic),
              reinterpret_cast<const std::byte*>(cache_magic) + 8);
  format::detail::append_value(file, static_cast<std::uint32_t>(key.size()));
  file.insert(file.end(), reinterpret_cast<const std::byte*>(key.data()),
              reinterpret_cast<const std::byte*>(key.data()) + key.size());
  format::detail::append_value(file, static_cast<std::uint64_t>(data.size()));
  file.insert(file.end(), data.begin(), data.end());
  format::detail::append_value(file, format::crc32c(file));
  // Larger than the whole cache on the disk (its size in blocks of 4 KiB, as most file systems
  // take it): not written, so that it does not evict everything and then itself.
  if ((file.size() + 4095) / 4096 * 4096 > max_bytes_) return;
  const std::string name = file_name(key);
  std::lock_guard lock(mutex_);
  forget(name);
  try {
    format::detail::write_file_atomically(dir_ / name, file);
  } catch (const format::FormatError&) {
    ++write_failures_;
    return;
  }
  Entry& e = entries_[name];
  e.bytes = file.size();
  e.disk = disk_bytes(dir_ / name, e.bytes);
  total_ += e.disk;
  e.used = ++clock_;
  by_use_[e.used] = name;
  evict();
}

std::uint64_t DiskCache::bytes() const {
  std::lock_guard lock(mutex_);
  return total_;
}

std::size_t DiskCache::entries() const {
  std::lock_guard lock(mutex_);
  return entries_.size();
}

std::uint64_t DiskCache::hits() const {
  std::lock_guard lock(mutex_);
  return hits_;
}

std::uint64_t DiskCache::misses() const {
  std::lock_guard lock(mutex_);
  return misses_;
}

std::uint64_t DiskCache::write_failures() const {
  std::lock_guard lock(mutex_);
  return write_failures_;
}

}  // namespace volreel::remote
