// run_summary_test.cpp: stream_bench::summarize on hand-made frame records — the averages (PSNR
// capped for identical images), holes after the first root brick, the byte totals, and the time
// from each seek to full LOD and to full quality, bounded by the next seek — and the run's JSON
// and CSV.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "../test_util.hpp"
#include "volreel/stream_bench/run_report.hpp"
#include "volreel/stream_bench/run_summary.hpp"

namespace volreel {
namespace {

using stream_bench::FrameRecord;
using stream_bench::RunResult;

/// A frame at `time` with `at_target` of 4 target nodes at their LOD and `current` of them also
/// at the right keyframes.
FrameRecord frame(double time, std::uint32_t at_target, std::uint32_t current, double psnr) {
  FrameRecord f;
  f.time = time;
  f.stats.target_nodes = 4;
  f.stats.at_target_nodes = at_target;
  f.stats.fraction_at_target = at_target / 4.0;
  f.current_nodes = current;
  f.fraction_current = current / 4.0;
  f.psnr = psnr;
  f.ssim = 0.5;
  f.frame_ms = 10;
  return f;
}

TEST(StreamBenchSummary, AveragesCapThePsnrAndCountHolesAfterTheRoot) {
  RunResult r;
  r.frames = {frame(0.0, 0, 0, 20), frame(0.1, 4, 4, std::numeric_limits<double>::infinity()),
              frame(0.2, 4, 2, 30), frame(0.3, 2, 2, 40)};
  r.frames[0].stats.holes = 3;  // before the root brick: not counted after it
  r.frames[2].root_resident = r.frames[3].root_resident = true;
  r.frames[2].stats.holes = 1;
  r.frames[3].stats.holes = 2;
  r.frames[3].stats.bytes_loaded = 5000;
  r.frames[3].bytes_uploaded = 4000;
  stream_bench::summarize(r, {});
  EXPECT_DOUBLE_EQ(r.mean_psnr, (20 + stream_bench::psnr_cap_db + 30 + 40) / 4);
  EXPECT_DOUBLE_EQ(r.min_psnr, 20);
  EXPECT_DOUBLE_EQ(r.mean_ssim, 0.5);
  EXPECT_DOUBLE_EQ(r.mean_fraction, (0 + 1 + 1 + 0.5) / 4);
  EXPECT_DOUBLE_EQ(r.mean_current, (0 + 1 + 0.5 + 0.5) / 4);
  EXPECT_DOUBLE_EQ(r.full_lod_share, 0.5);
  EXPECT_DOUBLE_EQ(r.full_quality_share, 0.25);
  EXPECT_EQ(r.hole_frames, 3u);
  EXPECT_EQ(r.frames_with_holes_after_root, 2u);
  EXPECT_EQ(r.max_holes_after_root, 2u);
  EXPECT_DOUBLE_EQ(r.bytes_loaded, 5000);
  EXPECT_DOUBLE_EQ(r.bytes_uploaded, 4000);
  EXPECT_DOUBLE_EQ(r.mean_frame_ms, 10);
  EXPECT_TRUE(r.seeks.empty());
}

TEST(StreamBenchSummary, SeekTimesStopAtTheNextSeek) {
  RunResult r;
  // Seek 1 at 0.1 s: full LOD at 0.2 s, full quality at 0.3 s. Seek 2 at 0.4 s: full LOD at
  // once, full quality not before seek 3 (its frame at 0.7 s counts for seek 3 only). Seek 3 at
  // 0.6 s: both at 0.7 s.
  r.frames = {frame(0.0, 4, 4, 30), frame(0.1, 1, 0, 30), frame(0.2, 4, 2, 30),
              frame(0.3, 4, 4, 30), frame(0.4, 4, 3, 30), frame(0.5, 2, 2, 30),
              frame(0.6, 3, 3, 30), frame(0.7, 4, 4, 30)};
  const std::vector<std::pair<double, double>> seeks = {{0.1, 2.5}, {0.4, 0.5}, {0.6, 4.0}};
  stream_bench::summarize(r, seeks);
  ASSERT_EQ(r.seeks.size(), 3u);
  EXPECT_DOUBLE_EQ(r.seeks[0].time, 0.1);
  EXPECT_DOUBLE_EQ(r.seeks[0].keyframe, 2.5);
  EXPECT_NEAR(r.seeks[0].to_full_lod, 0.1, 1e-12);
  EXPECT_NEAR(r.seeks[0].to_full_quality, 0.2, 1e-12);
  EXPECT_DOUBLE_EQ(r.seeks[1].to_full_lod, 0.0);
  EXPECT_TRUE(std::isnan(r.seeks[1].to_full_quality));
  EXPECT_NEAR(r.seeks[2].to_full_lod, 0.1, 1e-12);
  EXPECT_NEAR(r.seeks[2].to_full_quality, 0.1, 1e-12);
}

TEST(StreamBenchReport, JsonNullsWhatWasNotReachedAndCsvMarksSeeks) {
  RunResult r;
  r.name = "patent";
  r.frames = {frame(0.0, 4, 4, 30), frame(0.1, 1, 0, 30), frame(0.2, 4, 4, 30)};
  const std::vector<std::pair<double, double>> seeks = {{0.05, 1.0}};
  stream_bench::summarize(r, seeks);
  r.seeks[0].to_full_quality = std::numeric_limits<double>::quiet_NaN();
  const nlohmann::json j = stream_bench::summary_json(r);
  EXPECT_EQ(j["policy"], "patent");
  EXPECT_EQ(j["frames"], 3u);
  EXPECT_TRUE(j["first_root_brick_s"].is_null());  // never set: NaN
  ASSERT_EQ(j["seeks"].size(), 1u);
  EXPECT_TRUE(j["seeks"][0]["to_full_quality_s"].is_null());
  EXPECT_NEAR(j["seeks"][0]["to_full_lod_s"].get<double>(), 0.15, 1e-12);
  EXPECT_EQ(stream_bench::seconds_or_dash(std::nan("")), "-");
  EXPECT_EQ(stream_bench::seconds_or_dash(1.234), "1.23 s");
  EXPECT_EQ(stream_bench::mb_text(1.5e6), "1.50 MB");

  test::TempDir dir("stream-bench-csv");
  stream_bench::write_csv(dir / "run.csv", r, seeks);
  std::ifstream in(dir / "run.csv");
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  ASSERT_EQ(lines.size(), 4u);  // header and three frames
  EXPECT_EQ(lines[0].rfind("frame,time_s,playhead,seek,", 0), 0u);
  EXPECT_EQ(lines[1].rfind("0,0.0000,0.0000,0,", 0), 0u);
  EXPECT_EQ(lines[2].rfind("1,0.1000,0.0000,1,", 0), 0u);  // the first frame after the seek
  EXPECT_EQ(lines[3].rfind("2,0.2000,0.0000,0,", 0), 0u);
}

}  // namespace
}  // namespace volreel
