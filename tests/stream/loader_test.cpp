// loader_test.cpp: byte-range reads on worker threads, the cap on requests in flight, the link
// model, and errors with back-off.
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <thread>

#include "../test_util.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/stream/brick_loader.hpp"

namespace volreel::stream {
namespace {

std::vector<std::byte> pattern(std::size_t n) {
  std::vector<std::byte> b(n);
  for (std::size_t i = 0; i < n; ++i) b[i] = static_cast<std::byte>((i * 131 + 7) & 0xFF);
  return b;
}

void write_file(const std::filesystem::path& path, const std::vector<std::byte>& bytes) {
  std::ofstream f(path, std::ios::binary);
  f.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

/// Polls until `count` arrivals came (at most about 10 s; no timing is asserted).
std::vector<BrickArrival> poll_until(BrickLoader& loader, std::size_t count) {
  std::vector<BrickArrival> all;
  for (int i = 0; i < 10000 && all.size() < count; ++i) {
    for (auto& a : loader.poll()) all.push_back(std::move(a));
    if (all.size() < count) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return all;
}

BrickRequest request(const std::filesystem::path& file, std::uint32_t x, std::uint64_t offset,
                     std::uint32_t bytes) {
  BrickRequest r;
  r.key = {2, x, 0, 0, 0};
  r.keyframe = x;
  r.file = file;
  r.offset = offset;
  r.bytes = bytes;
  return r;
}

TEST(StreamLoader, ReadsByteRangesWithACapOnRequestsInFlight) {
  test::TempDir dir("stream-loader");
  const auto data = pattern(10000);
  write_file(dir / "frame.vrf", data);
  LoaderOptions o;
  o.threads = 2;
  o.max_in_flight = 2;
  o.bandwidth_bytes_per_s = 1e6;
  o.latency_s = 0.002;
  BrickLoader loader(o);
  EXPECT_EQ(loader.request(request(dir / "frame.vrf", 0, 100, 400)), RequestStatus::accepted);
  EXPECT_EQ(loader.request(request(dir / "frame.vrf", 0, 100, 400)),
            RequestStatus::already_in_flight);
  EXPECT_EQ(loader.request(request(dir / "frame.vrf", 1, 5000, 1234)), RequestStatus::accepted);
  EXPECT_EQ(loader.request(request(dir / "frame.vrf", 2, 0, 4)), RequestStatus::at_capacity);
  EXPECT_EQ(loader.in_flight(), 2u);
  auto arrivals = poll_until(loader, 2);
  ASSERT_EQ(arrivals.size(), 2u);
  EXPECT_EQ(loader.in_flight(), 0u);
  for (const BrickArrival& a : arrivals) {
    ASSERT_TRUE(a.ok()) << a.error;
    const auto begin = data.begin() + static_cast<std::ptrdiff_t>(a.request.offset);
    EXPECT_TRUE(std::equal(a.bytes.begin(), a.bytes.end(), begin, begin + a.request.bytes));
    EXPECT_EQ(a.bytes.size(), a.request.bytes);
  }
  EXPECT_EQ(loader.bytes_read(), 400u + 1234u);
  EXPECT_EQ(loader.request(request(dir / "frame.vrf", 2, 0, 4)), RequestStatus::accepted);
  EXPECT_EQ(poll_until(loader, 1).size(), 1u);
}

TEST(StreamLoader, ArrivalsAreCheckedAgainstTheirChecksum) {
  test::TempDir dir("stream-loader-crc");
  const auto data = pattern(4000);
  write_file(dir / "frame.vrf", data);
  const std::uint32_t crc = format::crc32c(std::span(data).subspan(100, 400));
  LoaderOptions o;
  o.threads = 1;
  o.max_in_flight = 4;
  BrickLoader loader(o);
  BrickRequest good = request(dir / "frame.vrf", 0, 100, 400),
               bad = request(dir / "frame.vrf", 1, 100, 400);
  good.crc32c = crc;
  bad.crc32c = crc ^ 1u;
  ASSERT_EQ(loader.request(good), RequestStatus::accepted);
  ASSERT_EQ(loader.request(bad), RequestStatus::accepted);
  const auto arrivals = poll_until(loader, 2);
  ASSERT_EQ(arrivals.size(), 2u);
  for (const BrickArrival& a : arrivals) {
    if (a.request.key.x == 0) {
      EXPECT_TRUE(a.ok()) << a.error;
      EXPECT_EQ(a.bytes.size(), 400u);
    } else {
      EXPECT_FALSE(a.ok());
      EXPECT_TRUE(a.bytes.empty());  // nothing of a bad payload is handed out
      EXPECT_NE(a.error.find("frame.vrf: offset 100"), std::string::npos) << a.error;
      EXPECT_NE(a.error.find("payload corrupt"), std::string::npos) << a.error;
    }
  }
}

TEST(StreamLoader, FailedReadsAreReportedAndBackOff) {
  test::TempDir dir("stream-loader-errors");
  write_file(dir / "short.vrf", pattern(100));
  LoaderOptions o;
  o.retry_initial_s = 30;  // long enough that the immediate retry below is refused
  BrickLoader loader(o);
  ASSERT_EQ(loader.request(request(dir / "missing.vrf", 0, 0, 16)), RequestStatus::accepted);
  ASSERT_EQ(loader.request(request(dir / "short.vrf", 1, 64, 64)), RequestStatus::accepted);
  ASSERT_EQ(loader.request(request(dir / "short.vrf", 2, 0, 64)), RequestStatus::accepted);
  const auto arrivals = poll_until(loader, 3);
  ASSERT_EQ(arrivals.size(), 3u);
  for (const BrickArrival& a : arrivals) {
    if (a.request.key.x == 0) {
      EXPECT_NE(a.error.find("missing.vrf"), std::string::npos) << a.error;
    } else if (a.request.key.x == 1) {
      EXPECT_NE(a.error.find("short.vrf: offset 64: expected 64 bytes, found 36"),
                std::string::npos)
          << a.error;
    } else {
      EXPECT_TRUE(a.ok()) << a.error;  // a failure elsewhere does not block it
    }
  }
  EXPECT_EQ(loader.request(request(dir / "missing.vrf", 0, 0, 16)), RequestStatus::backing_off);
  EXPECT_EQ(loader.request(request(dir / "short.vrf", 1, 64, 64)), RequestStatus::backing_off);
  EXPECT_EQ(loader.request(request(dir / "short.vrf", 2, 0, 64)), RequestStatus::accepted);
}

TEST(StreamLoader, BackOffEndsAndTheRetrySucceeds) {
  test::TempDir dir("stream-loader-retry");
  LoaderOptions o;
  o.retry_initial_s = 0.01;
  o.retry_max_s = 0.02;
  BrickLoader loader(o);
  ASSERT_EQ(loader.request(request(dir / "late.vrf", 0, 0, 8)), RequestStatus::accepted);
  const auto first = poll_until(loader, 1);
  ASSERT_EQ(first.size(), 1u);
  EXPECT_FALSE(first[0].ok());
  write_file(dir / "late.vrf", pattern(8));
  // Retried until accepted (the back-off is short), then it arrives intact.
  RequestStatus s = RequestStatus::backing_off;
  for (int i = 0; i < 10000 && s != RequestStatus::accepted; ++i) {
    s = loader.request(request(dir / "late.vrf", 0, 0, 8));
    if (s != RequestStatus::accepted) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ASSERT_EQ(s, RequestStatus::accepted);
  const auto second = poll_until(loader, 1);
  ASSERT_EQ(second.size(), 1u);
  EXPECT_TRUE(second[0].ok()) << second[0].error;
  EXPECT_EQ(second[0].bytes, pattern(8));
}

TEST(StreamLoader, SimulatedClockDeliversAtTheLinkModelsTimes) {
  test::TempDir dir("stream-loader-sim");
  const auto data = pattern(10000);
  write_file(dir / "frame.vrf", data);
  double t = 10.0;
  LoaderOptions o;
  o.bandwidth_bytes_per_s = 1000;  // 1 byte per ms
  o.latency_s = 0.05;
  o.max_in_flight = 8;
  o.clock = [&t] { return t; };
  BrickLoader loader(o);
  // Accepted at t = 10: the first arrives at 10.05 + 0.1, the second shares the link after it
  // (10.15 + 0.2); one accepted at 10.3 starts after its own latency (10.35 + 0.05).
  ASSERT_EQ(loader.request(request(dir / "frame.vrf", 0, 0, 100)), RequestStatus::accepted);
  ASSERT_EQ(loader.request(request(dir / "frame.vrf", 1, 200, 200)), RequestStatus::accepted);
  EXPECT_EQ(loader.queued(), 0u);  // on the link at once, as with the workers
  EXPECT_EQ(loader.cancel_queued([](const BrickRequest&) { return false; }), 0u);
  const auto at = [&](double when) {
    t = when;
    std::vector<std::uint32_t> xs;
    for (const BrickArrival& a : loader.poll()) {
      EXPECT_TRUE(a.ok()) << a.error;
      const auto begin = data.begin() + static_cast<std::ptrdiff_t>(a.request.offset);
      EXPECT_TRUE(std::equal(a.bytes.begin(), a.bytes.end(), begin, begin + a.request.bytes));
      xs.push_back(a.request.key.x);
    }
    return xs;
  };
  EXPECT_TRUE(at(10.149).empty());
  EXPECT_EQ(at(10.151), std::vector<std::uint32_t>{0});
  t = 10.3;
  ASSERT_EQ(loader.request(request(dir / "frame.vrf", 2, 1000, 50)), RequestStatus::accepted);
  EXPECT_TRUE(at(10.349).empty());
  EXPECT_EQ(at(10.351), std::vector<std::uint32_t>{1});
  EXPECT_EQ(loader.in_flight(), 1u);
  EXPECT_TRUE(at(10.399).empty());
  EXPECT_EQ(at(10.401), std::vector<std::uint32_t>{2});
  EXPECT_EQ(loader.in_flight(), 0u);
  EXPECT_EQ(loader.bytes_read(), 350u);
}

TEST(StreamLoader, SimulatedClockBacksOffInSimulatedTime) {
  test::TempDir dir("stream-loader-sim-retry");
  double t = 0;
  LoaderOptions o;
  o.retry_initial_s = 1.0;
  o.retry_max_s = 4.0;
  o.clock = [&t] { return t; };
  BrickLoader loader(o);
  ASSERT_EQ(loader.request(request(dir / "late.vrf", 0, 0, 8)), RequestStatus::accepted);
  const auto failed = loader.poll();  // no latency: due at once
  ASSERT_EQ(failed.size(), 1u);
  EXPECT_NE(failed[0].error.find("late.vrf"), std::string::npos) << failed[0].error;
  write_file(dir / "late.vrf", pattern(8));
  t = 0.999;
  EXPECT_EQ(loader.request(request(dir / "late.vrf", 0, 0, 8)), RequestStatus::backing_off);
  t = 1.0;
  ASSERT_EQ(loader.request(request(dir / "late.vrf", 0, 0, 8)), RequestStatus::accepted);
  const auto second = loader.poll();
  ASSERT_EQ(second.size(), 1u);
  EXPECT_EQ(second[0].bytes, pattern(8));
}

}  // namespace
}  // namespace volreel::stream
