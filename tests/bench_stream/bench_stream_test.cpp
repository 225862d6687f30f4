// bench_stream_test.cpp: the library side of `volreel bench stream` that needs no container — the
// --bandwidth rate (a rate, unlimited, a multiple of the playback rate, and its refusals), the
// seeks and fastest playback of a tour, the settings' checks and their messages, and the paths
// taken from a manifest's source.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "volreel/cpu_render/tour.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/container.hpp"
#include "volreel/stream_bench/bench_stream.hpp"

namespace volreel {
namespace {

using stream_bench::BenchStreamSettings;

/// The message of what `f` throws (InputError, or std::invalid_argument from loop's parsers; ""
/// when it throws none).
template <typename F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(StreamBenchBandwidth, RatesUnlimitedAndMultiples) {
  EXPECT_DOUBLE_EQ(stream_bench::bench_bandwidth("20MB/s", 0), 20e6);
  EXPECT_DOUBLE_EQ(stream_bench::bench_bandwidth("500kB/s", 0), 500e3);
  EXPECT_DOUBLE_EQ(stream_bench::bench_bandwidth("unlimited", 1e6), 0);
  EXPECT_DOUBLE_EQ(stream_bench::bench_bandwidth("0.5x", 4e6), 2e6);
  EXPECT_DOUBLE_EQ(stream_bench::bench_bandwidth("2X", 4e6), 8e6);
  EXPECT_EQ(stream_bench::rate_text(2.5e6), "2.5 MB/s");
  EXPECT_EQ(stream_bench::rate_text(0), "unlimited");
}

TEST(StreamBenchBandwidth, Refusals) {
  EXPECT_EQ(error_of([] { stream_bench::bench_bandwidth("-1x", 4e6); }),
            "--bandwidth: expected a multiple of the playback data rate such as 0.5x, or a rate "
            "such as 20MB/s, found '-1x'");
  EXPECT_EQ(error_of([] { stream_bench::bench_bandwidth("x", 4e6); }).rfind("--bandwidth: ", 0),
            0u);
  EXPECT_EQ(error_of([] { stream_bench::bench_bandwidth("0.5x", 0); }),
            "--bandwidth 0.5x: the tour never plays, so there is no playback data rate; give a "
            "rate such as 1MB/s");
  EXPECT_EQ(error_of([] { stream_bench::bench_bandwidth("fast", 0); }),
            "--bandwidth: expected a rate such as 20MB/s, 500kB/s or 1GB/s (0: unlimited), found "
            "'fast'");
}

TEST(StreamBenchTour, SeeksAndPlaySpeed) {
  const cpu_render::TourContext context{{40, 36, 30}, 6, {0, 1}};
  // Play 2 s at 1.5 keyframes/s (to 3), seek to 1, pause 1 s, reverse 1 s at 0.5/s, seek to 4.
  const cpu_render::Tour tour = cpu_render::Tour::parse(R"({"duration": 6, "segments": [
      {"play": 2, "speed": 1.5}, {"seek": 1}, {"pause": 1}, {"reverse": 1, "speed": 0.5},
      {"seek": 4}]})",
                                                        context, "tour.json");
  const std::vector<std::pair<double, double>> seeks = stream_bench::tour_seeks(tour);
  ASSERT_EQ(seeks.size(), 2u);
  EXPECT_DOUBLE_EQ(seeks[0].first, 2);
  EXPECT_DOUBLE_EQ(seeks[0].second, 1);
  EXPECT_DOUBLE_EQ(seeks[1].first, 4);
  EXPECT_DOUBLE_EQ(seeks[1].second, 4);
  EXPECT_DOUBLE_EQ(stream_bench::tour_play_speed(tour), 1.5);
  // A tour that never plays: no seeks, speed 0.
  const cpu_render::Tour still =
      cpu_render::Tour::parse(R"({"duration": 2, "segments": [{"pause": 2}]})", context, "t");
  EXPECT_TRUE(stream_bench::tour_seeks(still).empty());
  EXPECT_DOUBLE_EQ(stream_bench::tour_play_speed(still), 0);
  // The built-in tour: five seeks, and it plays.
  const cpu_render::Tour bench = stream_bench::bench_tour(context, 10, 1, 48, 48);
  EXPECT_EQ(stream_bench::tour_seeks(bench).size(), 5u);
  EXPECT_GT(stream_bench::tour_play_speed(bench), 0);
}

TEST(StreamBenchSettings, Checks) {
  const BenchStreamSettings valid;
  EXPECT_EQ(error_of([&] { valid.check(); }), "");
  EXPECT_EQ(valid.policies().size(), 2u);
  EXPECT_EQ(valid.transfer_spec(), "auto");
  const auto check = [](auto change) {
    BenchStreamSettings s;
    change(s);
    return error_of([&] { s.check(); });
  };
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.duration = 0; }),
            "--duration: expected seconds in (0, 3600], found '0'");
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.clock = "fast"; }),
            "--clock: expected simulated or wall, found 'fast'");
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.atlas_slots = 0; }),
            "--atlas-slots: expected 1..65536 slots, found '0'");
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.policy = "best"; }),
            "--policy: expected both, patent or nearest, found 'best'");
  EXPECT_EQ(check([](BenchStreamSettings& s) {
              s.seeds = 3;
              s.tour = "t.json";
            }),
            "--seeds 3: several seeds vary the built-in tour; drop --tour or --seeds");
  EXPECT_EQ(check([](BenchStreamSettings& s) {
              s.duration = 5;
              s.tour = "t.json";
            }),
            "--duration with --tour t.json: the length of the built-in tour; a tour file gives "
            "its own \"duration\"");
  EXPECT_EQ(check([](BenchStreamSettings& s) {
              s.seed = 7;
              s.tour = "t.json";
            }),
            "--seed with --tour t.json: the seed of the built-in tour's seeks; a tour file gives "
            "its own seeks");
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.seeds = 101; }),
            "--seeds: expected 1..100 tours, found '101'");
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.size = "48"; }),
            "--size: expected WIDTHxHEIGHT such as 512x512 (1 to 16384 each), found '48'");
  EXPECT_NE(check([](BenchStreamSettings& s) { s.bandwidth = "fast"; }), "");
  // A multiple of the playback rate is checked once the tour is known.
  EXPECT_EQ(check([](BenchStreamSettings& s) { s.bandwidth = "0.5x"; }), "");
}

TEST(StreamBenchSource, CandidatesFromTheManifest) {
  format::Manifest m;
  m.source = "raw series /data/blobs";
  EXPECT_EQ(stream_bench::source_candidates(m), std::vector<std::string>{"/data/blobs"});
  m.source = "raw file /data/v.raw (f32)";
  EXPECT_EQ(stream_bench::source_candidates(m), std::vector<std::string>{"/data/v.raw"});
  m.source = "HDF5 run.h5 (datasets Pressure_*)";
  m.encoder = {{"series", "series/run"}};
  EXPECT_EQ(stream_bench::source_candidates(m), (std::vector<std::string>{"run.h5", "series/run"}));
  m.source = "";
  m.encoder = nlohmann::json::object();
  EXPECT_TRUE(stream_bench::source_candidates(m).empty());
}

}  // namespace
}  // namespace volreel
