// source.hpp: where a container's files come from. A Container reads its manifest, dictionary and
// frame files through a ContainerSource: a local directory (LocalSource, here), or a web server
// (volreel::remote::HttpSource, remote/), so that everything above the container — the player,
// verify, info, decode — reads local and remote containers alike.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace volreel::format {

/// One byte range of a batch a RangeReader reads.
struct ByteRange {
  std::uint64_t offset = 0;
  std::uint64_t bytes = 0;
};

/// Reads byte ranges of the container's frame files for the loader's workers (called from
/// several threads at once).
class RangeReader {
 public:
  virtual ~RangeReader() = default;
  /// Reads `ranges` of `file` (a frame file as the spatial index names it), back to back in the
  /// file and in increasing order, into out (one buffer per range). Returns an empty string, or
  /// an error naming the file and the offset (then out is left empty).
  virtual std::string read(const std::filesystem::path& file, std::span<const ByteRange> ranges,
                           std::vector<std::vector<std::byte>>& out) = 0;
  /// The most bytes the loader reads as one range from back-to-back requests (0: each alone).
  virtual std::uint64_t coalesce_bytes() const { return 0; }
  /// Whether the range would be read without a transfer (a cache holds it): it is read alone.
  virtual bool holds(const std::filesystem::path&, ByteRange) const { return false; }
  /// Called with a range that arrived and matched its CRC (a cache keeps it).
  virtual void keep(const std::filesystem::path&, std::uint64_t, std::span<const std::byte>) {}
  /// Whether the bytes cross a real network: the loader then simulates no link of its own.
  virtual bool remote() const { return false; }
  /// Ends the reads in progress now, as errors (a loader that is being closed calls it, so that it
  /// does not wait for a slow or stalled server).
  virtual void cancel() {}
};

/// What a message about a URL given where a local path belongs says reads URLs.
inline constexpr const char* url_readers =
    "info, verify, render, play, bench stream and the Python module's volreel.open read a "
    "container's URL";

/// Local files, with pread.
class LocalRangeReader final : public RangeReader {
 public:
  std::string read(const std::filesystem::path& file, std::span<const ByteRange> ranges,
                   std::vector<std::vector<std::byte>>& out) override;
};

class ContainerSource {
 public:
  virtual ~ContainerSource() = default;

  /// The container as the user named it: "out/run.vreel" or "http://host/data/run.vreel".
  virtual const std::string& location() const = 0;
  /// How messages name one of its files ("out/run.vreel/frames/000003.vrf" or the file's URL);
  /// `relative` is a name the manifest allows ("manifest.json", "frames/000003.vrf").
  virtual std::filesystem::path name(const std::string& relative) const = 0;
  /// The directory when the files are local (they are then read with pread);
  /// empty for a remote source.
  virtual std::optional<std::filesystem::path> local_directory() const = 0;
  /// The whole file. Throws FormatError naming the file if it cannot be read or is larger than
  /// max_bytes.
  virtual std::vector<std::byte> read_file(const std::string& relative,
                                           std::uint64_t max_bytes) const = 0;
  /// Bytes [offset, offset + bytes) of the file. Throws FormatError naming the file and the offset
  /// if they cannot be read or fewer arrive.
  virtual std::vector<std::byte> read_range(const std::string& relative, std::uint64_t offset,
                                            std::uint64_t bytes) const = 0;
  /// Bytes received from the source so far (a remote source's transfer; a local one counts what
  /// it read through this interface).
  virtual std::uint64_t bytes_received() const = 0;
  /// Requests made of a remote source so far (0 for a local one).
  virtual std::uint64_t requests() const { return 0; }
  /// Called with bytes of a file that were read through this source and then validated (the
  /// dictionary, a frame's index): a remote source's cache keeps them, for kept().
  virtual void keep(const std::string& /*relative*/, std::uint64_t /*offset*/,
                    std::span<const std::byte> /*bytes*/) const {}
  /// What keep() kept at that offset of the file (in an earlier run, with a cache), if anything.
  virtual std::optional<std::vector<std::byte>> kept(const std::string& /*relative*/,
                                                     std::uint64_t /*offset*/) const {
    return std::nullopt;
  }
  /// What the player's loader reads bricks with: pread on local files, or range requests.
  virtual std::shared_ptr<RangeReader> brick_reader() const = 0;
};

/// A container directory on a local file system.
class LocalSource final : public ContainerSource {
 public:
  explicit LocalSource(std::filesystem::path dir);
  const std::string& location() const override { return location_; }
  std::filesystem::path name(const std::string& relative) const override { return dir_ / relative; }
  std::optional<std::filesystem::path> local_directory() const override { return dir_; }
  std::vector<std::byte> read_file(const std::string& relative,
                                   std::uint64_t max_bytes) const override;
  std::vector<std::byte> read_range(const std::string& relative, std::uint64_t offset,
                                    std::uint64_t bytes) const override;
  std::uint64_t bytes_received() const override;
  std::shared_ptr<RangeReader> brick_reader() const override;

 private:
  std::filesystem::path dir_;
  std::string location_;
  mutable std::atomic<std::uint64_t> received_{0};
};

/// Reads bytes [offset, offset + bytes) of a local regular file with pread into out; returns an
/// error message naming the file and the offset ("frames/000002.vrf: offset 4096: expected 1800
/// bytes, found 12 (file truncated)"), or an empty string on success.
std::string read_file_range(const std::filesystem::path& file, std::uint64_t offset,
                            std::uint64_t bytes, std::vector<std::byte>& out);

}  // namespace volreel::format
