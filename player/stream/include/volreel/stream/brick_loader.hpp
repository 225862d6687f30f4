// brick_loader.hpp: requests for brick bytes (Cesium patent [0037], [0063]; docs/design.md,
// "Streaming", step 2), read on worker threads as byte ranges of the frame files (pread), with a
// cap on requests in flight and an optional bandwidth and latency limit that makes a local disk act
// like a slow network or disk (`--bandwidth 20MB/s --latency 50ms`). Arrivals wait in a thread-safe
// queue until the scheduler polls them, once per rendered frame.
//
// Link model (local files, or any reader on a simulated clock; over a real network, the network is
// the link): a request accepted at time s has its first byte at s + latency; the bytes of all
// requests share one link of `bandwidth` bytes/s in the order they are read, so a request of B
// bytes arrives at max(s + latency, link free) + B / bandwidth.
//
// Where the bytes come from: a RangeReader — local files with pread (the default), or a web server
// (remote::HttpSource), which also reads back-to-back requests of one frame file as one range
// (coalescing: one HTTP request for several bricks) and keeps what arrives intact in a disk cache.
//
// A failed read (missing file, short file, I/O or network error, a payload whose CRC-32C does not
// match the frame's index) arrives as an error naming the file and the offset; the key then backs
// off (retry_initial_s, doubling up to retry_max_s) before request() accepts it again. Failures
// never hold a slot in flight and never stop other requests.
//
// Simulated time (LoaderOptions::clock): the same link model on a caller's clock instead of the
// steady clock, with no worker threads. A request takes its place on the link when accepted (as
// the workers do at once in real time), and poll() reads, synchronously and in request order, the
// requests whose arrival time has come. A run then depends only on the sequence of calls and the
// clock's values, not on the machine's speed: benchmarks use it to compare policies without noise.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "volreel/format/source.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {

using format::ByteRange;
using format::RangeReader;

struct LoaderOptions {
  unsigned threads = 4;              ///< worker threads reading files (≥ 1)
  std::size_t max_in_flight = 32;    ///< requests accepted and not yet polled (≥ 1)
  double bandwidth_bytes_per_s = 0;  ///< 0: unlimited
  double latency_s = 0;              ///< added to every request
  double retry_initial_s = 0.25;     ///< first back-off after a failure
  double retry_max_s = 8.0;          ///< longest back-off
  /// Simulated time in seconds (non-decreasing); empty: the steady clock and worker threads.
  std::function<double()> clock;
  /// Where the bytes come from (Container::source().brick_reader()); empty: local files.
  std::shared_ptr<RangeReader> reader;
};

struct BrickRequest {
  KeyframeKey key;
  KeyframeId keyframe = no_keyframe;  ///< the caller's id, returned with the arrival
  std::filesystem::path file;
  std::uint64_t offset = 0;  ///< absolute byte offset in file
  std::uint32_t bytes = 0;
  /// The payload's CRC-32C from the frame's index: an arrival that does not match is an error
  /// (never handed out as bytes). Unset: not checked.
  std::optional<std::uint32_t> crc32c;
};

/// The request for keyframe node `id` of the index: its frame file, offset, length and CRC.
inline BrickRequest brick_request(const SpatialIndex& index, KeyframeId id) {
  const KeyframeNode& k = index.keyframe(id);
  BrickRequest r;
  r.key = index.key(id);
  r.keyframe = id;
  r.file = index.frame_file(k.t);
  r.offset = k.offset;
  r.bytes = k.bytes;
  r.crc32c = k.crc32c;
  return r;
}

struct BrickArrival {
  BrickRequest request;
  std::vector<std::byte> bytes;  ///< request.bytes bytes, unless error
  std::string error;             ///< empty on success
  bool ok() const { return error.empty(); }
};

enum class RequestStatus {
  accepted,
  at_capacity,  ///< max_in_flight requests are in flight: try again later
  already_in_flight,
  backing_off,  ///< the key failed recently: try again later
};

class BrickLoader {
 public:
  explicit BrickLoader(LoaderOptions options = {});
  /// Stops the workers; requests not yet read are dropped.
  ~BrickLoader();
  BrickLoader(const BrickLoader&) = delete;
  BrickLoader& operator=(const BrickLoader&) = delete;

  /// Queues a read (requests are read in the order accepted).
  RequestStatus request(BrickRequest request);
  /// Arrivals whose time has come (successes and errors), in arrival order. Never blocks on I/O.
  std::vector<BrickArrival> poll();
  /// Drops queued requests that no worker has started and `keep` rejects; they leave the
  /// in-flight count. Returns how many were dropped (always 0 on a simulated clock, where every
  /// accepted request is already on the link).
  std::size_t cancel_queued(const std::function<bool(const BrickRequest&)>& keep);

  std::size_t in_flight() const;
  /// The loader's clock in seconds: the simulated clock's value, or the steady clock's time since
  /// construction.
  double now_seconds() const;
  /// Requests accepted that no worker has started reading yet.
  std::size_t queued() const;
  bool is_in_flight(const KeyframeKey& key) const;
  /// Bytes read successfully since construction.
  std::uint64_t bytes_read() const;
  /// Bricks read successfully since construction.
  std::uint64_t bricks_read() const;
  /// Reads issued to the reader (a coalesced batch is one) since construction.
  std::uint64_t reads() const;
  const LoaderOptions& options() const { return options_; }

 private:
  using Clock = std::chrono::steady_clock;
  struct Pending {
    BrickRequest request;
    Clock::time_point issued;
    Clock::time_point at;  ///< simulated clock: when the link delivers it
  };
  struct Ready {
    BrickArrival arrival;
    Clock::time_point at;
  };
  struct Backoff {
    unsigned failures = 0;
    Clock::time_point until;
  };

  LoaderOptions options_;
  mutable std::mutex mutex_;
  std::condition_variable wake_;
  bool stopping_ = false;
  std::deque<Pending> queue_;
  std::deque<Pending> on_link_;  ///< simulated clock: accepted, in request order
  std::vector<Ready> ready_;
  std::unordered_map<KeyframeKey, char, KeyframeKeyHash> in_flight_;
  std::unordered_map<KeyframeKey, Backoff, KeyframeKeyHash> backoff_;
  Clock::time_point link_free_;
  Clock::time_point started_;
  std::uint64_t bytes_read_ = 0;
  std::uint64_t reads_ = 0;
  std::uint64_t bricks_read_ = 0;
  std::vector<std::thread> workers_;

  /// Reads a batch of back-to-back requests of one file with the reader, checks each against its
  /// CRC and passes the good ones to the reader's keep().
  std::vector<BrickArrival> read_batch(std::vector<BrickRequest> batch);
  /// Moves queued requests back to back with `first` (same file, adjacent ranges, not held by
  /// the reader) into a batch with it, up to the reader's coalescing limit. Requires mutex_.
  std::vector<BrickRequest> take_batch(BrickRequest first);

  Clock::time_point now() const;
  /// The link model: when a successful read of `bytes` bytes issued at `issued` arrives; advances
  /// the link. Requires mutex_.
  Clock::time_point arrival_time(Clock::time_point issued, std::size_t bytes);
  void work();
};

}  // namespace volreel::stream
