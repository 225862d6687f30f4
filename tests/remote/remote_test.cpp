// remote_test.cpp: containers read over HTTP from a real nginx on 127.0.0.1 — the same manifest,
// indexes and bricks as from the folder, coalesced range requests, the disk cache, and faults
// (a corrupted byte, error statuses, truncated and stalled answers, a server that stops and comes
// back) that give clear errors and never hand out bad bytes; plus the pieces alone (Content-Range,
// URL checks, the cache folder).
#include <sys/stat.h>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <thread>

#include "../stream/stream_test_util.hpp"
#include "http_test_util.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/remote/disk_cache.hpp"
#include "volreel/remote/http_source.hpp"
#include "volreel/stream/brick_loader.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::remote {
namespace {

namespace fs = std::filesystem;

const fs::path proxy_script = VOLREEL_FAULT_PROXY;

std::string text_of(const fs::path& path) {
  const std::vector<std::byte> bytes = test::read_bytes(path);
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

// ---------------------------------------------------------------------------------------------
// The pieces.

TEST(RemoteHttp, ParsesContentRange) {
  const auto r = parse_content_range("bytes 100-199/1000");
  ASSERT_TRUE(r);
  EXPECT_EQ(r->first, 100u);
  EXPECT_EQ(r->last, 199u);
  EXPECT_EQ(r->total, 1000u);
  EXPECT_TRUE(parse_content_range("  BYTES 0-0/*\r\n"));
  EXPECT_FALSE(parse_content_range("bytes 0-0/*")->total);
  for (const char* bad : {"", "bytes", "bytes 5-4/10", "bytes 0-9/9", "bytes -1-2/3", "items 0-1/2",
                          "bytes 0-1", "bytes a-b/c", "bytes 0-99999999999999999999/1"})
    EXPECT_FALSE(parse_content_range(bad)) << bad;
}

TEST(RemoteHttp, AcceptsOnlyHttpAndHttpsUrls) {
  EXPECT_EQ(check_url("http://host/a/run.vreel/"), "http://host/a/run.vreel");
  EXPECT_EQ(check_url("HTTPS://host:8443/run.vreel"), "https://host:8443/run.vreel");
  EXPECT_TRUE(is_url("http://x"));
  EXPECT_FALSE(is_url("out/run.vreel"));
  EXPECT_FALSE(is_url("/abs/with://inside"));
  const auto message = [](const std::string& url) {
    try {
      check_url(url);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message("ftp://host/run.vreel").find("unsupported scheme \"ftp://\""),
            std::string::npos);
  EXPECT_NE(message("file:///etc/run.vreel").find("unsupported scheme"), std::string::npos);
  EXPECT_NE(message("http://host/a b").find("spaces"), std::string::npos);
  EXPECT_NE(message("http://host/run.vreel?sig=1").find("query"), std::string::npos);
  EXPECT_NE(message("http:///run.vreel").find("no host"), std::string::npos);
}

TEST(RemoteCache, KeepsEntriesAndEvictsTheLeastRecentlyUsed) {
  test::TempDir dir("remote-cache");
  const std::vector<std::byte> a(3000, std::byte{1}), b(3000, std::byte{2}), c(3000, std::byte{3});
  {
    DiskCache cache(dir / "cache", 9000);  // room for two entries of ~3 KB (4 KiB on the disk)
    cache.put("a", a);
    cache.put("b", b);
    EXPECT_EQ(cache.get("a"), a);  // a is now the most recent
    cache.put("c", c);             // evicts b
    EXPECT_FALSE(cache.get("b"));
    EXPECT_EQ(cache.get("a"), a);
    EXPECT_EQ(cache.get("c"), c);
    EXPECT_LE(cache.bytes(), 9000u);
  }
  // A new instance finds them, oldest use first out.
  DiskCache again(dir / "cache", 9000);
  EXPECT_EQ(again.entries(), 2u);
  EXPECT_EQ(again.get("c"), c);
  // A damaged entry is removed and counts as a miss.
  for (const auto& e : fs::directory_iterator(dir / "cache")) {
    std::fstream f(e.path(), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(40);
    f.put('\x55');
  }
  EXPECT_FALSE(again.get("a"));
  EXPECT_EQ(again.entries(), 1u);
  // The size limit counts the disk's blocks: many small entries (bricks of a few hundred bytes)
  // take a block each, and the folder stays within the limit on the disk.
  {
    DiskCache small(dir / "small", 3 * 4096);
    for (int i = 0; i < 12; ++i)
      small.put("brick " + std::to_string(i), std::vector<std::byte>(200));
    std::uint64_t on_disk = 0;
    for (const auto& e : fs::directory_iterator(dir / "small")) {
      struct stat st {};
      ASSERT_EQ(::stat(e.path().c_str(), &st), 0);
      on_disk += std::max<std::uint64_t>(fs::file_size(e.path()),
                                         static_cast<std::uint64_t>(st.st_blocks) * 512);
    }
    EXPECT_EQ(small.bytes(), on_disk);
    EXPECT_LE(on_disk, 3u * 4096u);
  }
  EXPECT_EQ(format::detail::parse_byte_size("2G", "--cache-size"), std::uint64_t{2} << 30);
  EXPECT_EQ(format::detail::parse_byte_size("500MiB", "--cache-size"), std::uint64_t{500} << 20);
  EXPECT_EQ(format::detail::parse_byte_size("4096", "--cache-size"), 4096u);
  EXPECT_THROW(format::detail::parse_byte_size("lots", "--cache-size"), std::invalid_argument);
  EXPECT_THROW(format::detail::parse_byte_size("-1G", "--cache-size"), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// A container served by nginx.

class RemoteContainer : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("remote-container");
    container_ = new fs::path(test::make_container(dir_->path(), {70, 70, 40}, 6));
    nginx_ = new test::Nginx(dir_->path(), dir_->path() / "nginx");
  }
  static void TearDownTestSuite() {
    delete nginx_;
    delete container_;
    delete dir_;
  }
  static std::string url() { return nginx_->url("test.vreel"); }

  /// Requests every brick of every frame of the index through a loader reading with `reader`,
  /// and returns the arrivals (successes and errors) once each has come once.
  static std::vector<stream::BrickArrival> load_all(const stream::SpatialIndex& index,
                                                    std::shared_ptr<format::RangeReader> reader,
                                                    unsigned threads = 1) {
    stream::LoaderOptions o;
    o.threads = threads;
    o.max_in_flight = 100000;
    o.reader = std::move(reader);
    stream::BrickLoader loader(o);
    std::size_t requested = 0;
    for (const stream::KeyframeId k : index.held_keyframes()) {
      EXPECT_EQ(loader.request(stream::brick_request(index, k)), stream::RequestStatus::accepted);
      ++requested;
    }
    std::vector<stream::BrickArrival> all;
    for (int i = 0; i < 20000 && all.size() < requested; ++i) {
      for (auto& a : loader.poll()) all.push_back(std::move(a));
      if (all.size() < requested) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    EXPECT_EQ(all.size(), requested);
    return all;
  }

  /// What reading every frame's index transfers: its first read (up to 4 KiB), or the index.
  static std::uint64_t index_bytes(const format::Container& c) {
    std::uint64_t total = 0;
    for (std::size_t t = 0; t < c.frame_count(); ++t)
      total += std::max<std::uint64_t>(std::min<std::uint64_t>(c.manifest().frames[t]->bytes, 4096),
                                       c.open_frame_index(t).view().bytes().size());
    return total;
  }

  static test::TempDir* dir_;
  static fs::path* container_;
  static test::Nginx* nginx_;
};

test::TempDir* RemoteContainer::dir_ = nullptr;
fs::path* RemoteContainer::container_ = nullptr;
test::Nginx* RemoteContainer::nginx_ = nullptr;

TEST_F(RemoteContainer, ReadsWhatTheFolderHolds) {
  const format::Container local(*container_);
  const auto source = std::make_shared<HttpSource>(url());
  const format::Container remote(source);
  EXPECT_EQ(format::manifest_to_json(remote.manifest()),
            format::manifest_to_json(local.manifest()));
  EXPECT_EQ(remote.total_bytes(), local.total_bytes());
  for (std::size_t t = 0; t < local.frame_count(); ++t) {
    const format::FrameFile whole = local.open_frame(t);
    const format::FrameFile index = remote.open_frame_index(t);
    // The index alone: everything before the payloads, the same bytes.
    ASSERT_FALSE(index.view().has_payloads());
    ASSERT_EQ(index.view().bytes().size(), whole.view().header().payload_offset);
    EXPECT_TRUE(std::equal(index.view().bytes().begin(), index.view().bytes().end(),
                           whole.view().bytes().begin()));
    EXPECT_THROW(index.view().brick_bytes(0), format::FormatError);
    for (std::uint32_t b = 0; b < whole.view().brick_count(); ++b) {
      const auto payload = remote.read_brick(index.view(), b);
      const auto expected = whole.view().checked_brick_bytes(b);
      ASSERT_TRUE(std::equal(payload.begin(), payload.end(), expected.begin(), expected.end()));
    }
    // Whole frames (decode, verify) are fetched whole.
    const format::FrameFile fetched = remote.open_frame(t);
    EXPECT_TRUE(fetched.view().has_payloads());
    EXPECT_NO_THROW(fetched.view().check_payload_crc());
  }
  EXPECT_TRUE(format::verify_container(source).empty());
  EXPECT_GT(source->requests(), 0u);
  // verify reads every file once: the container's bytes and no more.
  std::uint64_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(*container_))
    if (e.is_regular_file()) files += e.file_size();
  const auto fresh = std::make_shared<HttpSource>(url());
  EXPECT_TRUE(format::verify_container(fresh).empty());
  EXPECT_EQ(fresh->bytes_received(), files);
}

TEST_F(RemoteContainer, CoalescesBackToBackBricksIntoFewRequests) {
  const auto source = std::make_shared<HttpSource>(url());
  const format::Container remote(source);
  const stream::SpatialIndex index = stream::build_spatial_index(remote);
  const format::Container local(*container_);
  const stream::SpatialIndex local_index = stream::build_spatial_index(local);
  ASSERT_EQ(index.keyframe_count(), local_index.keyframe_count());
  const std::uint64_t before = source->requests();
  const auto arrivals = load_all(index, remote.source().brick_reader());
  const std::uint64_t requests = source->requests() - before;
  std::uint64_t bytes = 0;
  for (const auto& a : arrivals) {
    ASSERT_TRUE(a.ok()) << a.error;
    // The same bytes as the local file's.
    std::vector<std::byte> expected;
    const stream::KeyframeId id = a.request.keyframe;
    ASSERT_EQ(format::read_file_range(local_index.frame_file(local_index.keyframe(id).t),
                                      a.request.offset, a.request.bytes, expected),
              "");
    EXPECT_EQ(a.bytes, expected);
    bytes += a.bytes.size();
  }
  // One worker: while it reads one range, the rest queue and are read back to back.
  EXPECT_LE(requests * 2, arrivals.size()) << requests << " requests for " << arrivals.size();
  EXPECT_GE(requests, remote.frame_count());  // one file per frame
  std::printf("%llu requests for %zu bricks (%llu bytes)\n",
              static_cast<unsigned long long>(requests), arrivals.size(),
              static_cast<unsigned long long>(bytes));
}

TEST_F(RemoteContainer, AShapedServerDeliversEveryBrickIntactInFewRequests) {
  // nginx's limit_rate at 1 MB/s per request: a slow link, with many requests waiting.
  test::Nginx slow(dir_->path(), dir_->path() / "nginx-slow", 1000000);
  const auto source = std::make_shared<HttpSource>(slow.url("test.vreel"));
  const format::Container remote(source);
  const stream::SpatialIndex index = stream::build_spatial_index(remote);
  const std::uint64_t before = source->requests();
  std::uint64_t bytes = 0;
  const auto arrivals = load_all(index, remote.source().brick_reader(), 2);
  for (const auto& a : arrivals) {
    ASSERT_TRUE(a.ok()) << a.error;
    EXPECT_EQ(format::crc32c(a.bytes), *a.request.crc32c);
    bytes += a.bytes.size();
  }
  const std::uint64_t requests = source->requests() - before;
  const std::uint64_t received = source->bytes_received();
  EXPECT_LE(requests * 2, arrivals.size()) << requests << " requests for " << arrivals.size();
  // Nothing but the manifest (zfp: no dictionary), the indexes and the bricks.
  EXPECT_EQ(received, bytes + fs::file_size(*container_ / "manifest.json") + index_bytes(remote));
}

TEST_F(RemoteContainer, HttpsServesOverHttp2OnOneConnection) {
  test::Nginx tls(dir_->path(), dir_->path() / "nginx-tls", 0, true);
  // A certificate the system does not trust is a clear error.
  try {
    format::Container c(std::make_shared<HttpSource>(tls.url("test.vreel")));
    ADD_FAILURE() << "opened";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("certificate"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("(--ca-file, or ca_file= in Python)"), std::string::npos)
        << e.what();
  }
  RemoteOptions o;
  o.http.ca_file = tls.certificate().string();
  const auto source = std::make_shared<HttpSource>(tls.url("test.vreel"), o);
  const format::Container remote(source);
  const stream::SpatialIndex index = stream::build_spatial_index(remote);
  for (const auto& a : load_all(index, remote.source().brick_reader(), 4))
    ASSERT_TRUE(a.ok()) << a.error;
  const HttpClient& client = source->client();
  EXPECT_EQ(client.http2_responses(), client.requests());
  // Indexes fetched 16 at a time and 4 loader threads: multiplexed, not a connection each.
  EXPECT_LE(client.connections_opened(), 2u) << client.requests() << " requests";
}

TEST_F(RemoteContainer, ASecondRunWithTheCacheTransfersOnlyTheManifest) {
  test::TempDir cache("remote-cache-run");
  RemoteOptions o;
  o.cache_dir = cache.path();
  std::uint64_t first_bytes = 0, manifest_bytes = 0;
  for (int run = 0; run < 2; ++run) {
    const auto source = std::make_shared<HttpSource>(url(), o);
    const format::Container remote(source);
    const stream::SpatialIndex index = stream::build_spatial_index(remote);
    for (const auto& a : load_all(index, remote.source().brick_reader())) ASSERT_TRUE(a.ok());
    manifest_bytes = fs::file_size(*container_ / "manifest.json");
    if (run == 0) {
      first_bytes = source->bytes_received();
      EXPECT_GT(first_bytes, 10 * manifest_bytes);
    } else {
      EXPECT_EQ(source->bytes_received(), manifest_bytes);  // the manifest is always fresh
      EXPECT_GT(source->cache_bytes_served(), 0u);
    }
  }
}

TEST_F(RemoteContainer, FramesReadWholeComeFromTheCacheOnASecondRun) {
  // What Python's Container.frame and `volreel decode URL` read: whole frame files.
  test::TempDir cache("remote-cache-whole");
  RemoteOptions o;
  o.cache_dir = cache.path();
  std::vector<std::byte> first;
  for (int run = 0; run < 2; ++run) {
    const auto source = std::make_shared<HttpSource>(url(), o);
    const format::Container remote(source);
    const std::uint64_t before = source->bytes_received();
    const format::FrameFile frame = remote.open_frame(2);
    const auto bytes = frame.view().bytes();
    if (run == 0) {
      first.assign(bytes.begin(), bytes.end());
      EXPECT_GE(source->bytes_received() - before, first.size());
    } else {
      EXPECT_TRUE(std::equal(bytes.begin(), bytes.end(), first.begin(), first.end()));
      EXPECT_EQ(source->bytes_received(), before);  // nothing more than the manifest
      EXPECT_GE(source->cache_bytes_served(), first.size());
    }
  }
}

TEST_F(RemoteContainer, AWholeFileDamagedOnTheWayIsNotKeptInTheCache) {
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  test::TempDir cache("remote-cache-damaged");
  RemoteOptions o;
  o.attempts = 1;
  o.cache_dir = cache.path();
  proxy.set_mode("flip frames");
  {
    const format::Container remote(std::make_shared<HttpSource>(proxy.url("test.vreel"), o));
    try {  // the index may be intact: a payload's damage shows when it is decoded
      remote.open_frame(2);
    } catch (const format::FormatError&) {
    }
  }
  // The server's bytes intact again: read from it, not the damaged copy from the cache.
  proxy.set_mode("pass");
  const format::Container remote(std::make_shared<HttpSource>(proxy.url("test.vreel"), o));
  const format::FrameFile frame = remote.open_frame(2);
  const auto on_disk = format::detail::read_whole_file(*container_ / format::frame_file_name(2),
                                                       std::uint64_t{1} << 30);
  const auto bytes = frame.view().bytes();
  EXPECT_TRUE(std::equal(bytes.begin(), bytes.end(), on_disk.begin(), on_disk.end()));
}

TEST_F(RemoteContainer, ACorruptedByteIsRequestedAgainAndNeverHandedOut) {
  test::Nginx& nginx = *nginx_;
  test::FaultProxy proxy(proxy_script, nginx.port(), dir_->path());
  const auto source = std::make_shared<HttpSource>(proxy.url("test.vreel"));
  const format::Container remote(source);
  const stream::SpatialIndex index = stream::build_spatial_index(remote);
  stream::LoaderOptions o;
  o.threads = 2;
  o.retry_initial_s = 0.05;
  o.reader = remote.source().brick_reader();
  stream::BrickLoader loader(o);
  const stream::BrickRequest r = stream::brick_request(index, index.held_keyframes().back());
  const auto wait_one = [&] {
    for (int i = 0; i < 5000; ++i) {
      auto got = loader.poll();
      if (!got.empty()) return std::move(got.front());
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return stream::BrickArrival{};
  };
  proxy.set_mode("flip");
  ASSERT_EQ(loader.request(r), stream::RequestStatus::accepted);
  const stream::BrickArrival bad = wait_one();
  EXPECT_FALSE(bad.ok());
  EXPECT_TRUE(bad.bytes.empty());
  EXPECT_NE(bad.error.find("payload corrupt"), std::string::npos) << bad.error;
  EXPECT_NE(bad.error.find(r.file.string()), std::string::npos) << bad.error;
  // Backing off, then asked again: the intact bytes.
  proxy.set_mode("pass");
  EXPECT_EQ(loader.request(r), stream::RequestStatus::backing_off);
  std::this_thread::sleep_for(std::chrono::milliseconds(80));
  ASSERT_EQ(loader.request(r), stream::RequestStatus::accepted);
  const stream::BrickArrival good = wait_one();
  ASSERT_TRUE(good.ok()) << good.error;
  EXPECT_EQ(format::crc32c(good.bytes), *r.crc32c);
}

TEST_F(RemoteContainer, APasswordInTheUrlIsSentButNeverShownNorCached) {
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  proxy.set_mode("auth YWxpY2U6czNjcmV0IQ==");  // "alice:s3cret!" in base64
  test::TempDir cache("remote-cache-password");
  RemoteOptions o;
  o.attempts = 1;
  o.cache_dir = cache.path();
  std::string url = proxy.url("test.vreel");
  url.insert(url.find("://") + 3, "alice:s3cret%21@");  // '!' percent-encoded, as URLs write it
  const auto source = std::make_shared<HttpSource>(url, o);
  EXPECT_EQ(source->location(), proxy.url("test.vreel"));
  const format::Container remote(source);  // the manifest and the dictionary: authenticated
  EXPECT_NO_THROW(remote.open_frame(1));
  try {  // a message names the URL without the password
    source->read_file("frames/no-such-file.vrf", 100);
    ADD_FAILURE() << "read";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find(proxy.url("test.vreel/frames/no-such-file.vrf")),
              std::string::npos)
        << e.what();
    EXPECT_EQ(std::string(e.what()).find("s3cret"), std::string::npos) << e.what();
  }
  for (const auto& entry : fs::recursive_directory_iterator(cache.path())) {
    EXPECT_EQ(entry.path().string().find("s3cret"), std::string::npos) << entry.path();
    if (!entry.is_regular_file()) continue;
    const std::vector<std::byte> bytes = format::detail::read_whole_file(entry.path(), 1 << 30);
    const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    EXPECT_EQ(text.find("s3cret"), std::string_view::npos) << entry.path();
  }
  // Without the password the server refuses.
  try {
    format::Container again(std::make_shared<HttpSource>(proxy.url("test.vreel"), RemoteOptions{}));
    ADD_FAILURE() << "opened without the password";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("HTTP 401"), std::string::npos) << e.what();
  }
}

TEST_F(RemoteContainer, TheAutomaticTransferFunctionTriesOneFrameOfAFailingServer) {
  // Over HTTP the automatic transfer function samples the middle frame alone: a server that fails
  // its reads fails every frame's (the view waited for 6 frames' tries, minutes with the default
  // stall timeout and tries, with nothing on the screen).
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  RemoteOptions o;
  o.attempts = 2;
  o.retry_initial_s = 0.01;
  const auto source = std::make_shared<HttpSource>(proxy.url("test.vreel"), o);
  const format::Container remote(source);
  ASSERT_EQ(remote.frame_count(), 6u);
  proxy.set_mode("status 503");
  const std::uint64_t before = source->requests();
  const cpu_render::TransferFunction tf = loop::quantile_transfer(remote);
  EXPECT_EQ(source->requests() - before, 2u);  // the middle frame's index, tried twice
  // The fallback: the preset over the manifest's value range.
  const auto& m = remote.manifest();
  const auto preset = cpu_render::TransferFunction::preset(
      "cool-warm", static_cast<float>(m.value_min), static_cast<float>(m.value_max));
  EXPECT_EQ(tf.lookup(static_cast<float>(m.value_max)),
            preset.lookup(static_cast<float>(m.value_max)));
}

TEST_F(RemoteContainer, ErrorStatusesTruncationAndStallsAreClearErrors) {
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  RemoteOptions o;
  o.attempts = 2;
  o.retry_initial_s = 0.01;
  o.http.stall_timeout_s = 1;
  const auto source = std::make_shared<HttpSource>(proxy.url("test.vreel"), o);
  const format::Container remote(source);
  const format::FrameFile frame = remote.open_frame_index(1);
  const auto error_of = [&](const std::string& mode) {
    proxy.set_mode(mode);
    try {
      remote.read_brick(frame.view(), 0);
    } catch (const format::FormatError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  const std::string name = proxy.url("test.vreel/frames/000001.vrf");
  for (const auto& [mode, expected] :
       std::vector<std::pair<std::string, std::string>>{{"status 404", "found HTTP 404"},
                                                        {"status 503", "found HTTP 503"},
                                                        {"status 200", "found HTTP 200"},
                                                        {"whole", "does not serve byte ranges"},
                                                        {"truncate", "bytes"},
                                                        {"stall", "no byte arrived for 1 s"},
                                                        {"flip", "payload corrupt"}}) {
    const std::string e = error_of(mode);
    EXPECT_EQ(e.rfind(name, 0), 0u) << mode << ": " << e;
    EXPECT_NE(e.find(expected), std::string::npos) << mode << ": " << e;
  }
  // An error page longer than the range asked for is named by its status (not as "found more"),
  // and a 5xx is tried again.
  for (const std::string status : {"503", "404"}) {
    proxy.set_mode("page " + status);
    try {
      source->read_range("frames/000001.vrf", 0, 16);
      ADD_FAILURE() << "read";
    } catch (const format::FormatError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("bytes 0-15: expected HTTP 206, found HTTP " + status), std::string::npos)
          << what;
      EXPECT_EQ(what.find("the last of 2 tries") != std::string::npos, status == "503") << what;
    }
  }
  proxy.set_mode("pass");
  EXPECT_NO_THROW(remote.read_brick(frame.view(), 0));
  // A manifest that cannot be had is an error naming it.
  proxy.set_mode("status 500");
  try {
    format::Container again(std::make_shared<HttpSource>(proxy.url("test.vreel"), o));
    ADD_FAILURE() << "opened";
  } catch (const NetworkError& e) {
    EXPECT_NE(std::string(e.what()).find("manifest.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("HTTP 500"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("the last of 2 tries"), std::string::npos) << e.what();
  }
  // A stalled one says what stalled and how long it was waited for.
  proxy.set_mode("stall");
  try {
    format::Container again(std::make_shared<HttpSource>(proxy.url("test.vreel"), o));
    ADD_FAILURE() << "opened";
  } catch (const NetworkError& e) {
    const std::string what = e.what();
    EXPECT_EQ(what.rfind(proxy.url("test.vreel/manifest.json"), 0), 0u) << what;
    EXPECT_NE(what.find("no byte arrived for 1 s after 1 bytes"), std::string::npos) << what;
    EXPECT_NE(what.find("then stopped sending"), std::string::npos) << what;
    EXPECT_NE(what.find("the last of 2 tries over "), std::string::npos) << what;
  }
  // Half the body at once, then nothing: each try ends about a second after its last byte (the
  // progress callback), where libcurl's average speed over its last seconds (LOW_SPEED_TIME
  // alone) took 6 s a try after such a burst: 2 tries well under 8 s.
  proxy.set_mode("stall half");
  try {
    format::Container again(std::make_shared<HttpSource>(proxy.url("test.vreel"), o));
    ADD_FAILURE() << "opened";
  } catch (const NetworkError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no byte arrived for 1 s after "), std::string::npos) << what;
    const std::size_t over = what.find("the last of 2 tries over ");
    ASSERT_NE(over, std::string::npos) << what;
    EXPECT_LT(std::stod(what.substr(over + 25)), 8.0) << what;
  }
}

TEST_F(RemoteContainer, CancelEndsWhatRunsAndNotWhatComesAfter) {
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  HttpClient client;
  const std::string manifest = proxy.url("test.vreel/manifest.json");
  // A stalled answer ends at once, named, instead of at the stall timeout.
  proxy.set_mode("stall");
  auto stalled = client.get(manifest, 0, 64);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const auto start = std::chrono::steady_clock::now();
  client.cancel_all();
  const HttpResponse r = stalled.get();
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5));
  EXPECT_NE(r.error.find(manifest), std::string::npos) << r.error;
  EXPECT_NE(r.error.find("cancelled"), std::string::npos) << r.error;
  // A request made right after a cancel is a later request: it runs (a loader closing must not
  // fail the next reader's first request).
  proxy.set_mode("pass");
  for (int i = 0; i < 50; ++i) {
    client.cancel_all();
    const HttpResponse after = client.get(manifest, 0, 64).get();
    ASSERT_TRUE(after.ok()) << i << ": " << after.error;
    EXPECT_EQ(after.body.size(), 64u);
  }
}

TEST_F(RemoteContainer, LoadingResumesWhenTheServerComesBack) {
  const auto source = std::make_shared<HttpSource>(url());
  const format::Container remote(source);
  const stream::SpatialIndex index = stream::build_spatial_index(remote);
  nginx_->stop();
  const auto during = load_all(index, remote.source().brick_reader(), 2);
  for (const auto& a : during) {
    EXPECT_FALSE(a.ok());
    EXPECT_NE(a.error.find("127.0.0.1"), std::string::npos) << a.error;
  }
  nginx_->start();
  for (const auto& a : load_all(index, remote.source().brick_reader(), 2))
    EXPECT_TRUE(a.ok()) << a.error;
}

TEST_F(RemoteContainer, PlaybackGoesOnWhileTheServerIsAwayAndCatchesUpAfter) {
  const auto source = std::make_shared<HttpSource>(url());
  const format::Container remote(source);
  const format::Manifest& m = remote.manifest();
  loop::FrameLoopOptions o;
  o.width = 48;
  o.height = 40;
  o.atlas_bytes = std::uint64_t{30} * 93312;  // room for about one time step's bricks
  o.scheduler.loader.retry_initial_s = 0.05;
  o.scheduler.loader.retry_max_s = 0.2;
  loop::CpuFrameLoop frames(remote, o);
  const auto camera = player::OrbitCamera::framing({m.dims[0], m.dims[1], m.dims[2]}, 48, 40);
  const auto tf = cpu_render::TransferFunction::preset("cool-warm", static_cast<float>(m.value_min),
                                                       static_cast<float>(m.value_max));
  const auto play = [&](double playhead, int max_frames) {
    loop::FrameReport report;
    std::size_t errors = 0;
    for (int i = 0; i < max_frames; ++i) {
      report = frames.frame(camera, playhead, tf);
      errors += report.new_errors.size();
      if (report.stats.fraction_at_target == 1.0 && report.stats.requests_in_flight == 0) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return std::pair{report, errors};
  };
  // The first time step loads while the server is up.
  auto [first, first_errors] = play(0.0, 2000);
  EXPECT_EQ(first.stats.fraction_at_target, 1.0);
  EXPECT_EQ(first_errors, 0u);
  // The server goes away; the playhead moves on: frames keep coming (drawn from what is
  // resident), the errors name the server, nothing throws.
  nginx_->stop();
  auto [away, away_errors] = play(5.0, 60);
  EXPECT_LT(away.stats.fraction_at_target, 1.0);
  EXPECT_GT(away_errors, 0u);
  EXPECT_GT(away.stats.svo_nodes, 0u);  // something is still drawn
  // It comes back: loading resumes by itself and the new time step is reached.
  nginx_->start();
  auto [back, back_errors] = play(5.0, 4000);
  EXPECT_EQ(back.stats.fraction_at_target, 1.0);
  (void)back_errors;
}

TEST_F(RemoteContainer, ARemoteManifestNamesOnlyTheContainersOwnFiles) {
  test::TempDir served("remote-evil");
  fs::create_directories(served / "evil.vreel");
  // A manifest whose CRC holds (recomputed), with a frame file outside the container.
  nlohmann::json j = nlohmann::json::parse(text_of(*container_ / "manifest.json"));
  j["frames"][1]["file"] = "../../etc/passwd";
  std::ofstream(served / "evil.vreel" / "manifest.json") << format::manifest_text(j);
  test::Nginx server(served.path(), served / "nginx");
  try {
    format::Container c(std::make_shared<HttpSource>(server.url("evil.vreel")));
    ADD_FAILURE() << "opened";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("frames[1].file"), std::string::npos) << e.what();
  }
  // The loader refuses files outside the container.
  const auto source = std::make_shared<HttpSource>(url());
  const format::Container remote(source);
  std::vector<std::vector<std::byte>> out;
  const format::ByteRange range{0, 16};
  const std::string error =
      source->read(nginx_->url("other.vreel/frames/000000.vrf"), {&range, 1}, out);
  EXPECT_NE(error.find("not a file of the container"), std::string::npos) << error;
}

TEST_F(RemoteContainer, TheCommandsReadAUrl) {
  const std::string volreel = VOLREEL_BINARY;
  const fs::path out = dir_->path() / "cli";
  fs::create_directories(out);
  const auto run = [&](const std::string& args, const std::string& log) {
    return std::system((volreel + " " + args + " > " + (out / log).string() + " 2>&1").c_str());
  };
  const auto text = [&](const std::string& log) { return text_of(out / log); };
  ASSERT_EQ(run("info " + url(), "info.txt"), 0) << text("info.txt");
  EXPECT_NE(text("info.txt").find("6 frames"), std::string::npos) << text("info.txt");
  ASSERT_EQ(run("verify " + url(), "verify.txt"), 0) << text("verify.txt");
  EXPECT_NE(text("verify.txt").find("OK"), std::string::npos);
  ASSERT_EQ(run("render " + url() + " --cpu --size 64x48 --max-frames 4 --cache " +
                    (out / "cache").string() + " --out " + (out / "frames").string(),
                "render.txt"),
            0)
      << text("render.txt");
  EXPECT_TRUE(fs::exists(out / "frames" / "frame_00003.png"));
  EXPECT_NE(text("render.txt").find("HTTP requests"), std::string::npos) << text("render.txt");
  EXPECT_EQ(text("render.txt").find("error"), std::string::npos) << text("render.txt");
  // A password in the URL is printed by no command (nginx here asks for none).
  std::string with_password = url();
  with_password.insert(with_password.find("://") + 3, "alice:s3cret@");
  for (const std::string command : {"info", "verify"}) {
    ASSERT_EQ(run(command + " " + with_password, "password.txt"), 0) << text("password.txt");
    EXPECT_EQ(text("password.txt").find("s3cret"), std::string::npos) << text("password.txt");
  }
  EXPECT_NE(run("info ftp://alice:s3cret@127.0.0.1/x.vreel", "password.txt"), 0);
  EXPECT_EQ(text("password.txt").find("s3cret"), std::string::npos) << text("password.txt");
  // Only http and https; a server that answers 404 names the URL.
  EXPECT_NE(run("info ftp://127.0.0.1/x.vreel", "ftp.txt"), 0);
  EXPECT_NE(text("ftp.txt").find("unsupported scheme"), std::string::npos) << text("ftp.txt");
  EXPECT_NE(run("info " + nginx_->url("missing.vreel"), "missing.txt"), 0);
  EXPECT_NE(text("missing.txt").find("missing.vreel/manifest.json"), std::string::npos)
      << text("missing.txt");
  EXPECT_NE(text("missing.txt").find("HTTP 404 (no such file on the server: check the URL)"),
            std::string::npos)
      << text("missing.txt");
  // A server that stops sending is given up after --stall-timeout, --tries times.
  test::FaultProxy proxy(proxy_script, nginx_->port(), dir_->path());
  proxy.set_mode("stall");
  EXPECT_NE(run("info " + proxy.url("test.vreel") + " --stall-timeout 1 --tries 2", "stall.txt"),
            0);
  EXPECT_NE(text("stall.txt").find("manifest.json: no byte arrived for 1 s"), std::string::npos)
      << text("stall.txt");
  EXPECT_NE(text("stall.txt").find("the last of 2 tries"), std::string::npos) << text("stall.txt");
  EXPECT_NE(run("info " + url() + " --stall-timeout nan", "nan.txt"), 0);
  EXPECT_NE(text("nan.txt").find("--stall-timeout"), std::string::npos) << text("nan.txt");
}

}  // namespace
}  // namespace volreel::remote
