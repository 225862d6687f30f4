// http_source.hpp: a container on a web server or object store, read by HTTP(S) GETs: the
// manifest whole (always fresh), the dictionary whole, each frame's index by range, and bricks by
// range for the player's loader — back-to-back bricks of one frame as one request, what arrives
// intact kept in an optional disk cache.
//
// Only the container's own files are ever asked for: the manifest reader accepts no other names
// ("dictionary.bin", "frames/NNNNNN.vrf"), and the loader's requests must lie under the container's
// URL. Reads for the container (manifest, dictionary, indexes) retry transient failures with
// back-off; the loader's reads are tried once, since the loader backs off itself.
//
// Cache keys carry the container's identifier and the file's CRC-32C from the manifest, so a
// container encoded again at the same URL never reads another's bytes; nothing is cached before
// the manifest has been read.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "volreel/format/error.hpp"
#include "volreel/format/source.hpp"
#include "volreel/remote/disk_cache.hpp"
#include "volreel/remote/http_client.hpp"

namespace volreel::remote {

/// A container read over HTTP that failed: no connection, a timeout, an HTTP error status, a short
/// answer (after the retries). A FormatError, so that what catches the one catches the other.
class NetworkError : public format::FormatError {
 public:
  using FormatError::FormatError;
};

struct RemoteOptions {
  /// What a user may ask for (the command line's options, the Python module's keywords).
  static constexpr unsigned max_attempts = 20;
  static constexpr unsigned max_connections = 64;
  static constexpr double min_stall_timeout_s = 1, max_stall_timeout_s = 3600;
  /// cache_bytes as a user writes it by default.
  static constexpr const char* default_cache_size = "2G";

  HttpOptions http;
  unsigned attempts = 4;          ///< tries of a container read (manifest, dictionary, index)
  double retry_initial_s = 0.25;  ///< back-off before the second try, doubling after
  double retry_max_s = 8;         ///< up to this
  std::uint64_t coalesce_bytes = std::uint64_t{1} << 20;  ///< the largest range of several bricks
  std::filesystem::path cache_dir;                        ///< empty: no cache
  std::uint64_t cache_bytes = std::uint64_t{2} << 30;
  /// Called about every 0.1 s on a thread that waits for an answer or for the back-off before a
  /// retry (an embedding's check for an interrupt, such as Python's for Ctrl-C); what it throws
  /// ends the read. Empty: none.
  std::function<void()> while_waiting;
};

class HttpSource final : public format::ContainerSource,
                         public format::RangeReader,
                         public std::enable_shared_from_this<HttpSource> {
 public:
  /// Checks the URL (check_url: http or https only); reads nothing yet. Throws
  /// std::invalid_argument for a bad URL, FormatError for a cache folder that cannot be used.
  HttpSource(std::string url, RemoteOptions options = {});

  // ContainerSource
  const std::string& location() const override { return url_; }
  std::filesystem::path name(const std::string& relative) const override;
  std::optional<std::filesystem::path> local_directory() const override { return std::nullopt; }
  std::vector<std::byte> read_file(const std::string& relative,
                                   std::uint64_t max_bytes) const override;
  std::vector<std::byte> read_range(const std::string& relative, std::uint64_t offset,
                                    std::uint64_t bytes) const override;
  std::uint64_t bytes_received() const override { return client_->bytes_received(); }
  void keep(const std::string& relative, std::uint64_t offset,
            std::span<const std::byte> bytes) const override;
  std::optional<std::vector<std::byte>> kept(const std::string& relative,
                                             std::uint64_t offset) const override;
  std::shared_ptr<format::RangeReader> brick_reader() const override;

  // RangeReader (the player's loader)
  std::string read(const std::filesystem::path& file, std::span<const format::ByteRange> ranges,
                   std::vector<std::vector<std::byte>>& out) override;
  std::uint64_t coalesce_bytes() const override { return options_.coalesce_bytes; }
  bool holds(const std::filesystem::path& file, format::ByteRange range) const override;
  void keep(const std::filesystem::path& file, std::uint64_t offset,
            std::span<const std::byte> bytes) override;
  bool remote() const override { return true; }
  void cancel() override { client_->cancel_all(); }

  /// HTTP requests completed so far (any outcome).
  std::uint64_t requests() const override { return client_->requests(); }
  const HttpClient& client() const { return *client_; }
  /// The cache, if any.
  const DiskCache* cache() const { return cache_.get(); }
  /// Bytes served from the cache instead of the network.
  std::uint64_t cache_bytes_served() const;

 private:
  std::string url_;
  RemoteOptions options_;
  std::unique_ptr<HttpClient> client_;
  std::unique_ptr<DiskCache> cache_;
  mutable std::mutex mutex_;
  struct FileTag {
    std::string tag;  ///< "CONTAINER_ID/CRC32C"
    std::uint64_t bytes = 0;
    std::uint32_t crc32c = 0;  ///< the manifest's, checked before a whole file is cached
  };
  /// Per file of the manifest (set when the manifest is read).
  mutable std::map<std::string, FileTag> tags_;
  mutable std::uint64_t cache_served_ = 0;

  /// The container-relative name of a loader's file (its URL), or empty if it is not one.
  std::string relative_of(const std::filesystem::path& file) const;
  /// The cache key of a range of a file (bytes: its length, or "*" for what keep() kept at
  /// offset), or empty when it is not to be cached.
  std::string cache_key(const std::string& relative, std::uint64_t offset,
                        const std::string& bytes) const;
  std::optional<std::vector<std::byte>> cached(const std::string& relative, std::uint64_t offset,
                                               std::uint64_t bytes) const;
  /// The answer of a GET, calling options_.while_waiting while it has not come.
  HttpResponse answer(std::future<HttpResponse> response) const;
  /// GET with retries of transient failures; throws NetworkError with the last error.
  std::vector<std::byte> fetch(const std::string& relative, std::uint64_t offset,
                               std::uint64_t bytes) const;
  /// Records the manifest's identifier and CRCs for cache keys.
  void learn_manifest(std::span<const std::byte> bytes) const;
};

/// The source of a container named by a path or a URL.
std::shared_ptr<const format::ContainerSource> open_source(const std::string& location,
                                                           const RemoteOptions& options = {});

}  // namespace volreel::remote
