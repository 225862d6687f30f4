// disk_cache.hpp: a folder of byte ranges kept between runs (`--cache DIR --cache-size 2G`), least
// recently used first out, so that a second run over the same remote container starts warm.
//
// One file per entry, named by a 64-bit hash of its key: "VRCACHE1", the key's length (u32) and
// text, the data's length (u64) and bytes, and a CRC-32C of everything before it. An entry is
// written atomically (temporary name, then rename); one that does not read back intact, or holds
// another key, is removed and counts as a miss. Use is recorded in the file's modification time,
// so the order survives between runs. Several processes may share a folder; each evicts by what it
// knows, so the folder can briefly exceed the size until the next insertion.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

namespace volreel::remote {

class DiskCache {
 public:
  /// Opens (creating it if needed) the folder and takes stock of its entries. Throws
  /// format::FormatError naming the folder if it cannot be made or is not a directory.
  DiskCache(std::filesystem::path dir, std::uint64_t max_bytes);

  /// The entry's data, or nullopt (missing or damaged: then removed).
  std::optional<std::vector<std::byte>> get(const std::string& key);
  /// Whether an entry for key exists (not read, not checked).
  bool contains(const std::string& key) const;
  /// Stores data under key (replacing it), then evicts least recently used entries while the
  /// folder takes more than max_bytes of the disk (whole blocks of the file system: a brick of
  /// 300 bytes takes 4 KiB on most). Data larger than max_bytes (in blocks of 4 KiB) is not stored.
  /// I/O failures are counted (write_failures) and otherwise ignored: a cache that cannot write is
  /// only slower.
  void put(const std::string& key, std::span<const std::byte> data);

  const std::filesystem::path& directory() const { return dir_; }
  std::uint64_t max_bytes() const { return max_bytes_; }
  /// The disk space the entries take (what max_bytes bounds).
  std::uint64_t bytes() const;
  std::size_t entries() const;
  std::uint64_t hits() const;
  std::uint64_t misses() const;
  std::uint64_t write_failures() const;

 private:
  struct Entry {
    std::uint64_t bytes = 0;  ///< the file's size
    std::uint64_t disk = 0;   ///< the disk space it takes: total_ sums these
    std::uint64_t used = 0;   ///< use order
  };
  std::filesystem::path dir_;
  std::uint64_t max_bytes_;
  mutable std::mutex mutex_;
  std::unordered_map<std::string, Entry> entries_;  ///< by file name
  std::map<std::uint64_t, std::string> by_use_;     ///< use order -> file name
  std::uint64_t total_ = 0, clock_ = 0;
  std::uint64_t hits_ = 0, misses_ = 0, write_failures_ = 0;

  static std::string file_name(const std::string& key);
  void touch(const std::string& name, Entry& e);
  void forget(const std::string& name);
  void evict();
};

}  // namespace volreel::remote
