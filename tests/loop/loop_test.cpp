// loop_test.cpp: volreel::loop — loop::CpuFrameLoop streams a small zfp container until every
// visible node is at its target LOD and keeps the last image; loop_settings parses sizes, rates
// and durations and applies them to FrameLoopOptions.
#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "../test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"

namespace volreel {
namespace {

TEST(CpuFrameLoop, ConvergesAndKeepsTheLastImage) {
  test::TempDir dir("loop-cpu");
  const Dims dims{40, 36, 30};
  {
    datasets::AnalyticParams p;
    p.field = datasets::AnalyticField::blobs;
    p.dims = dims;
    p.frames = 4;
    datasets::RawSeriesWriter w(dir / "series", dims, "test");
    datasets::generate_analytic(p, w);
  }
  encoder::EncodeJob job;
  job.coding.codec = format::Codec::zfp;
  job.coding.zfp_accuracy = 1e-3;
  encoder::encode_series(*datasets::open_series(dir / "series"), dir / "test.vreel", job);
  const format::Container container(dir / "test.vreel");
  const format::Manifest& m = container.manifest();

  loop::FrameLoopOptions o;
  o.atlas_bytes = std::uint64_t{125} * 93312;  // 125 slots of a 16-bit atlas
  o.width = 48;
  o.height = 40;
  loop::CpuFrameLoop frames(container, o);
  EXPECT_EQ(frames.slot_count(), 125u);
  EXPECT_EQ(frames.scheduler().settings().atlas_slots, 125u);
  EXPECT_FALSE(frames.can_pipeline());
  EXPECT_EQ(frames.describe().rfind("CPU reference renderer", 0), 0u) << frames.describe();

  const auto camera = player::OrbitCamera::framing({40, 36, 30}, 48, 40);
  const auto tf = cpu_render::TransferFunction::preset("cool-warm", static_cast<float>(m.value_min),
                                                       static_cast<float>(m.value_max));
  loop::FrameReport report;
  bool converged = false;
  for (int i = 0; i < 500 && !converged; ++i) {
    report = frames.frame(camera, 1.5, tf);
    EXPECT_EQ(report.ticket, static_cast<loop::Ticket>(i + 1));
    EXPECT_TRUE(report.new_errors.empty()) << report.new_errors.front();
    converged = report.stats.fraction_at_target == 1.0 && report.stats.requests_in_flight == 0 &&
                report.stats.arrivals_waiting == 0 && report.stats.uploads == 0;
  }
  ASSERT_TRUE(converged) << "at target " << report.stats.fraction_at_target;
  EXPECT_GT(report.stats.atlas_occupied, 0u);
  const cpu_render::RgbaImage image = frames.read_back(report.ticket);
  EXPECT_EQ(image.width, 48);
  EXPECT_EQ(image.height, 40);
  EXPECT_EQ(image.rgba, frames.last_image(report.ticket).rgba);
  EXPECT_THROW(frames.read_back(report.ticket - 1), std::invalid_argument);
  frames.resize(64, 32);
  EXPECT_EQ(frames.options().width, 64);
  EXPECT_EQ(frames.options().height, 32);
}

TEST(LoopSettings, ParsesSizesRatesAndDurations) {
  EXPECT_EQ(loop::parse_size("512x256"), (std::pair<int, int>{512, 256}));
  EXPECT_THROW(loop::parse_size("512"), std::invalid_argument);
  EXPECT_THROW(loop::parse_size("0x10"), std::invalid_argument);
  EXPECT_DOUBLE_EQ(loop::parse_bandwidth("20MB/s"), 20e6);
  EXPECT_DOUBLE_EQ(loop::parse_bandwidth("500kB/s"), 500e3);
  EXPECT_DOUBLE_EQ(loop::parse_bandwidth("3"), 3e6);
  EXPECT_THROW(loop::parse_bandwidth("fast"), std::invalid_argument);
  EXPECT_DOUBLE_EQ(loop::parse_latency("50ms"), 0.05);
  EXPECT_DOUBLE_EQ(loop::parse_latency("0.2s"), 0.2);
  EXPECT_THROW(loop::parse_latency("-1"), std::invalid_argument);
}

TEST(LoopSettings, AppliesToTheOptions) {
  loop::LoopSettings s;
  s.size = "320x200";
  s.atlas_mb = 2;
  s.bandwidth = "1GB/s";
  s.no_culling = true;
  loop::FrameLoopOptions o;
  loop::apply(s, o);
  EXPECT_EQ(o.width, 320);
  EXPECT_EQ(o.height, 200);
  EXPECT_EQ(o.atlas_bytes, std::uint64_t{2} << 20);
  EXPECT_DOUBLE_EQ(o.scheduler.loader.bandwidth_bytes_per_s, 1e9);
  EXPECT_FALSE(o.transfer_culling);
  s.size = "wide";
  EXPECT_THROW(loop::apply(s, o), std::invalid_argument);
}

}  // namespace
}  // namespace volreel
