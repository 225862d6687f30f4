// brick_loader.cpp: worker threads reading brick byte ranges through a RangeReader (coalescing
// back-to-back requests where it asks for it), a simulated link (bandwidth, latency) and per-key
// back-off after failures.
#include "volreel/stream/brick_loader.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/source.hpp"

namespace volreel::stream {

std::vector<BrickArrival> BrickLoader::read_batch(std::vector<BrickRequest> batch) {
  std::vector<ByteRange> ranges;
  for (const BrickRequest& r : batch) ranges.push_back({r.offset, r.bytes});
  std::vector<std::vector<std::byte>> bytes;
  const std::string error = options_.reader->read(batch.front().file, ranges, bytes);
  std::vector<BrickArrival> out(batch.size());
  for (std::size_t i = 0; i < batch.size(); ++i) {
    BrickArrival& a = out[i];
    a.request = std::move(batch[i]);
    const BrickRequest& r = a.request;
    if (!error.empty()) {
      a.error = error;
      continue;
    }
    a.bytes = std::move(bytes[i]);
    if (r.crc32c) {
      const std::uint32_t found = format::crc32c(a.bytes);
      if (found != *r.crc32c) {
        a.error = r.file.string() + ": offset " + std::to_string(r.offset) +
                  ": expected a brick payload of CRC-32C " + std::to_string(*r.crc32c) +
                  " (the frame's index), found " + std::to_string(found) + " (payload corrupt)";
        a.bytes.clear();
        continue;
      }
      options_.reader->keep(r.file, r.offset, a.bytes);
    }
  }
  return out;
}

std::vector<BrickRequest> BrickLoader::take_batch(BrickRequest first) {
  const std::uint64_t limit = options_.reader->coalesce_bytes();
  std::vector<BrickRequest> before, after;  // before: nearest first
  if (limit > 0 && !options_.reader->holds(first.file, {first.offset, first.bytes})) {
    std::uint64_t begin = first.offset, end = begin + first.bytes;
    // Grow the range at either end with queued requests of the same file that touch it.
    for (bool grew = true; grew;) {
      grew = false;
      for (auto it = queue_.begin(); it != queue_.end(); ++it) {
        const BrickRequest& r = it->request;
        if (r.file != first.file || end - begin + r.bytes > limit ||
            (r.offset != end && r.offset + r.bytes != begin) ||
            options_.reader->holds(r.file, {r.offset, r.bytes}))
          continue;
        if (r.offset == end) {
          end += r.bytes;
          after.push_back(std::move(it->request));
        } else {
          begin = r.offset;
          before.push_back(std::move(it->request));
        }
        queue_.erase(it);
        grew = true;
        break;
      }
    }
  }
  std::vector<BrickRequest> batch;
  batch.reserve(before.size() + 1 + after.size());
  for (auto it = before.rbegin(); it != before.rend(); ++it) batch.push_back(std::move(*it));
  batch.push_back(std::move(first));
  for (BrickRequest& r : after) batch.push_back(std::move(r));
  return batch;
}

BrickLoader::BrickLoader(LoaderOptions options) : options_(std::move(options)) {
  if (!options_.reader) options_.reader = std::make_shared<format::LocalRangeReader>();
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
  options_.reader->cancel();  // reads in progress end now (a stalled server must not hold us)
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
    std::vector<BrickRequest> one;
    one.push_back(std::move(p.request));
    ++reads_;
    BrickArrival a = std::move(read_batch(std::move(one)).front());
    if (a.ok()) {
      bytes_read_ += a.bytes.size();
      ++bricks_read_;
    }
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

std::uint64_t BrickLoader::bricks_read() const {
  std::lock_guard lock(mutex_);
  return bricks_read_;
}

std::uint64_t BrickLoader::reads() const {
  std::lock_guard lock(mutex_);
  return reads_;
}

void BrickLoader::work() {
  for (;;) {
    std::vector<BrickRequest> batch;
    Clock::time_point issued;
    {
      std::unique_lock lock(mutex_);
      wake_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (stopping_) return;
      Pending p = std::move(queue_.front());
      queue_.pop_front();
      issued = p.issued;
      batch = take_batch(std::move(p.request));
      ++reads_;
    }
    std::vector<BrickArrival> arrivals = read_batch(std::move(batch));
    std::lock_guard lock(mutex_);
    for (BrickArrival& a : arrivals) {
      // The simulated link; a failed read takes no link time and arrives after the latency. Over
      // a real network the bytes are there when they have arrived.
      Clock::time_point at = issued;
      if (a.ok()) {
        bytes_read_ += a.bytes.size();
        ++bricks_read_;
      }
      if (options_.reader->remote()) {
        at = Clock::now();
      } else if (a.ok()) {
        at = arrival_time(issued, a.bytes.size());
      } else {
        at += std::chrono::duration_cast<Clock::duration>(
            std::chrono::duration<double>(std::max(0.0, options_.latency_s)));
      }
      ready_.push_back({std::move(a), at});
    }
  }
}

}  // namespace volreel::stream
