// brick_loader.cpp: worker threads reading brick byte ranges with pread, a simulated link
// (bandwidth, latency) and per-key back-off after failures.
#include "volreel/stream/brick_loader.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <utility>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::stream {

std::string read_byte_range(const std::filesystem::path& file, std::uint64_t offset,
                            std::uint32_t bytes, std::vector<std::byte>& out) {
  out.resize(bytes);
  int fd = -1;
  try {
    std::uint64_t size = 0;
    fd = format::detail::open_regular_file(file, size);
  } catch (const format::FormatError& e) {
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

namespace {

/// Reads the request's bytes into a and checks them against the request's CRC, if it has one.
void read_arrival(BrickArrival& a) {
  const BrickRequest& r = a.request;
  a.error = read_byte_range(r.file, r.offset, r.bytes, a.bytes);
  if (a.ok() && r.crc32c) {
    const std::uint32_t found = format::crc32c(a.bytes);
    if (found != *r.crc32c) {
      a.error = r.file.string() + ": offset " + std::to_string(r.offset) +
                ": expected a brick payload of CRC-32C " + std::to_string(*r.crc32c) +
                " (the frame's index), found " + std::to_string(found) + " (payload corrupt)";
      a.bytes.clear();
    }
  }
}

}  // namespace

BrickLoader::BrickLoader(LoaderOptions options) : options_(std::move(options)) {
  options_.threads = std::max(1u, options_.threads);
  options_.max_in_flight = std::max<std::size_t>(1, options_.max_in_flight);
  link_free_ = now();
  started_ = Clock::now();
  if (!options_.clock)
    for (unsigned i = 0; i < options_.threads; ++i) workers_.emplace_back([this] { work(); });
}

BrickLoader::Clock::time_point BrickLoader::now() const {
  if (!options_.clock) return Clock::now();
  return Clock::time_point{} + std::chrono::duration_cast<Clock::duration>(
                                   std::chrono::duration<double>(options_.clock()));
}

BrickLoader::Clock::time_point BrickLoader::arrival_time(Clock::time_point issued,
                                                         std::size_t bytes) {
  // First byte after the latency, then the link's bandwidth, shared in order.
  const auto latency = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(std::max(0.0, options_.latency_s)));
  Clock::time_point at = issued + latency;
  if (options_.bandwidth_bytes_per_s > 0) {
    const auto transfer = std::chrono::duration_cast<Clock::duration>(
        std::chrono::duration<double>(static_cast<double>(bytes) / options_.bandwidth_bytes_per_s));
    at = std::max(at, link_free_) + transfer;
    link_free_ = at;
  }
  return at;
}

BrickLoader::~BrickLoader() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
    queue_.clear();
  }
  wake_.notify_all();
  for (std::thread& w : workers_) w.join();
}

RequestStatus BrickLoader::request(BrickRequest request) {
  const Clock::time_point t = now();
  {
    std::lock_guard lock(mutex_);
    if (in_flight_.count(request.key)) return RequestStatus::already_in_flight;
    if (const auto it = backoff_.find(request.key); it != backoff_.end() && t < it->second.until)
      return RequestStatus::backing_off;
    if (in_flight_.size() >= options_.max_in_flight) return RequestStatus::at_capacity;
    in_flight_.emplace(request.key, 0);
    if (options_.clock) {
      const Clock::time_point at = arrival_time(t, request.bytes);
      on_link_.push_back({std::move(request), t, at});
      return RequestStatus::accepted;
    }
    queue_.push_back({std::move(request), t, {}});
  }
  wake_.notify_one();
  return RequestStatus::accepted;
}

std::vector<BrickArrival> BrickLoader::poll() {
  const Clock::time_point now = this->now();
  std::vector<BrickArrival> out;
  std::lock_guard lock(mutex_);
  // Simulated clock: read what the link has delivered by now, in request order. (A failed read
  // keeps the link time it reserved: the model does not know it will fail when it is accepted.)
  while (!on_link_.empty() && on_link_.front().at <= now) {
    Pending p = std::move(on_link_.front());
    on_link_.pop_front();
    BrickArrival a;
    a.request = std::move(p.request);
    read_arrival(a);
    if (a.ok()) bytes_read_ += a.bytes.size();
    ready_.push_back({std::move(a), p.at});
  }
  // Keep arrival order: ready_ is ordered by completion; deliver those due.
  auto due = std::stable_partition(ready_.begin(), ready_.end(),
                                   [&](const Ready& r) { return r.at <= now; });
  for (auto it = ready_.begin(); it != due; ++it) {
    const KeyframeKey& key = it->arrival.request.key;
    in_flight_.erase(key);
    if (it->arrival.ok()) {
      backoff_.erase(key);
    } else {
      // Back off: initial · 2^(failures − 1), capped.
      Backoff& b = backoff_[key];
      ++b.failures;
      const double wait =
          std::min(options_.retry_max_s,
                   options_.retry_initial_s * std::pow(2.0, static_cast<double>(b.failures - 1)));
      b.until =
          now + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(wait));
    }
    out.push_back(std::move(it->arrival));
  }
  ready_.erase(ready_.begin(), due);
  return out;
}

std::size_t BrickLoader::cancel_queued(const std::function<bool(const BrickRequest&)>& keep) {
  std::lock_guard lock(mutex_);
  std::size_t dropped = 0;
  for (auto it = queue_.begin(); it != queue_.end();) {
    if (!keep(it->request)) {
      in_flight_.erase(it->request.key);
      it = queue_.erase(it);
      ++dropped;
    } else {
      ++it;
    }
  }
  return dropped;
}

double BrickLoader::now_seconds() const {
  if (options_.clock) return options_.clock();
  return std::chrono::duration<double>(Clock::now() - started_).count();
}

std::size_t BrickLoader::in_flight() const {
  std::lock_guard lock(mutex_);
  return in_flight_.size();
}

std::size_t BrickLoader::queued() const {
  std::lock_guard lock(mutex_);
  return queue_.size();
}

bool BrickLoader::is_in_flight(const KeyframeKey& key) const {
  std::lock_guard lock(mutex_);
  return in_flight_.count(key) != 0;
}

std::uint64_t BrickLoader::bytes_read() const {
  std::lock_guard lock(mutex_);
  return bytes_read_;
}

void BrickLoader::work() {
  for (;;) {
    Pending p;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      p = std::move(queue_.front());
      queue_.pop_front();
    }
    BrickArrival a;
    a.request = std::move(p.request);
    read_arrival(a);
    std::lock_guard lock(mutex_);
    // The simulated link; a failed read takes no link time and arrives after the latency.
    Clock::time_point at = p.issued;
    if (a.ok()) {
      bytes_read_ += a.bytes.size();
      at = arrival_time(p.issued, a.bytes.size());
    } else {
      at += std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(std::max(0.0, options_.latency_s)));
    }
    ready_.push_back({std::move(a), at});
  }
}

}  // namespace volreel::stream
