// loop_test.cpp: volreel::loop — loop::CpuFrameLoop streams a small zfp container until every
// visible node is at its target LOD and keeps the last image; loop_settings parses sizes, rates
// and durations and applies them to FrameLoopOptions; ResolutionControl holds a frame-time target
// on simulated renderers.
#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

#include "../blobs_container.hpp"
#include "../test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/loop/resolution_control.hpp"

namespace volreel {
namespace {

/// A small zfp container of blobs (40×36×30, 4 frames) in `dir`.
void make_container(const test::TempDir& dir) {
  test::write_blobs_container(dir.path(), {40, 36, 30}, 4);
}

/// Frames of 48×40 over a slow link: the container's bricks arrive over several frames.
loop::FrameLoopOptions slow_link_options() {
  loop::FrameLoopOptions o;
  o.width = 48;
  o.height = 40;
  o.scheduler.loader.bandwidth_bytes_per_s = 2e6;
  o.scheduler.loader.latency_s = 0.01;
  return o;
}

TEST(CpuFrameLoop, ConvergesAndKeepsTheLastImage) {
  test::TempDir dir("loop-cpu");
  make_container(dir);
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

TEST(CpuFrameLoop, ThePreviousWorkingSetDrawsTheLastFrameAgainAndChangesNothing) {
  test::TempDir dir("loop-previous");
  make_container(dir);
  const format::Container container(dir / "test.vreel");
  // Two loops on simulated clocks that advance alike (10 ms a frame): one draws the previous
  // working set before every frame, the other never does.
  double clock[2] = {0, 0};
  std::unique_ptr<loop::CpuFrameLoop> loops[2];
  for (int k = 0; k < 2; ++k) {
    loop::FrameLoopOptions o = slow_link_options();
    o.scheduler.lod_blend.fade_s = 0.05;  // bricks fade in
    o.scheduler.loader.clock = [&clock, k] { return clock[k]; };
    loops[k] = std::make_unique<loop::CpuFrameLoop>(container, o);
  }
  loop::CpuFrameLoop& frames = *loops[0];
  const auto camera = player::OrbitCamera::framing({40, 36, 30}, 48, 40);
  const auto tf = cpu_render::TransferFunction::preset("cool-warm", -1, 1);
  EXPECT_EQ(frames.render_previous_working_set(camera, 1.5, tf).width, 0);  // no frame yet
  std::size_t changed = 0, unchanged = 0, blended = 0;
  for (int i = 0; i < 400; ++i) {
    const cpu_render::RgbaImage before = frames.render_previous_working_set(camera, 1.5, tf);
    const loop::FrameReport report = frames.frame(camera, 1.5, tf);
    const loop::FrameReport other = loops[1]->frame(camera, 1.5, tf);
    clock[0] += 0.01, clock[1] += 0.01;
    const cpu_render::RgbaImage& drawn = frames.last_image(report.ticket);
    // Drawing the previous working set changes nothing the loop does.
    ASSERT_EQ(drawn.rgba, loops[1]->last_image(other.ticket).rgba) << "frame " << i;
    // Right after a frame, its own working set at its own view and time draws it again, to the
    // bit, whatever arrived or was fading in it.
    ASSERT_EQ(frames.render_previous_working_set(camera, 1.5, tf).rgba, drawn.rgba)
        << "frame " << i;
    blended += report.stats.blended_leaves > 0 ? 1 : 0;
    if (i > 0 && report.stats.uploads == 0 && report.stats.blended_leaves == 0) {
      EXPECT_EQ(before.rgba, drawn.rgba) << "frame " << i << ": nothing arrived or faded";
      ++unchanged;
    }
    if (i > 0 && before.rgba != drawn.rgba) ++changed;
    if (report.stats.fraction_at_target == 1.0 && report.stats.requests_in_flight == 0 &&
        report.stats.uploads == 0 && report.stats.blended_leaves == 0 && unchanged > 2)
      break;
  }
  EXPECT_GT(changed, 0u);  // arrivals changed the picture
  EXPECT_GT(unchanged, 0u);
  EXPECT_GT(blended, 0u);  // and some faded in
}

TEST(CpuFrameLoop, WaitingForAViewDrawsItCompleteOnTheFirstFrame) {
  test::TempDir dir("loop-wait");
  make_container(dir);
  const format::Container container(dir / "test.vreel");
  const loop::FrameLoopOptions o = slow_link_options();
  const auto camera = player::OrbitCamera::framing({40, 36, 30}, 48, 40);
  const auto tf = cpu_render::TransferFunction::preset("cool-warm", -1, 1);
  {
    // Without waiting, the first frame has nothing yet.
    loop::CpuFrameLoop frames(container, o);
    EXPECT_LT(frames.frame(camera, 1.5, tf).stats.fraction_at_target, 1.0);
  }
  loop::CpuFrameLoop frames(container, o);
  // A timeout too short for the link: reported, not complete.
  const loop::ViewWait early = loop::wait_for_view(frames, camera, 1.5, 0.0);
  EXPECT_TRUE(early.timed_out);
  EXPECT_FALSE(early.complete);
  const loop::ViewWait wait = loop::wait_for_view(frames, camera, 1.5, 30.0);
  ASSERT_TRUE(wait.complete) << "at target " << wait.stats.fraction_at_target << " after "
                             << wait.seconds << " s";
  EXPECT_FALSE(wait.timed_out);
  EXPECT_GT(wait.steps, 1u);
  EXPECT_TRUE(wait.new_errors.empty());
  // Streaming steps render nothing; the first frame draws everything they decoded.
  const loop::FrameReport first = frames.frame(camera, 1.5, tf);
  EXPECT_EQ(first.ticket, 1u);
  EXPECT_EQ(first.stats.fraction_at_target, 1.0);
  EXPECT_EQ(first.stats.holes, 0u);
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
  EXPECT_EQ(o.gpu.decode, loop::FrameLoopOptions::Decode::automatic);
  s.decode = "cpu";
  loop::apply(s, o);
  EXPECT_EQ(o.gpu.decode, loop::FrameLoopOptions::Decode::cpu);
  s.decode = "fpga";
  EXPECT_THROW(loop::apply(s, o), std::invalid_argument);
  s.decode = "gpu";
  // Level-of-detail blending.
  s.lod_fade = 0.75;
  s.spatial_blend = true;
  loop::apply(s, o);
  EXPECT_DOUBLE_EQ(o.scheduler.lod_blend.fade_s, 0.75);
  EXPECT_TRUE(o.scheduler.lod_blend.spatial);
  s.lod_fade = -1;
  EXPECT_THROW(loop::apply(s, o), std::invalid_argument);
  s.lod_fade = 0;
  // Ray-guided feedback, on by default.
  EXPECT_TRUE(o.scheduler.ray_feedback);
  s.ray_feedback = false;
  loop::apply(s, o);
  EXPECT_FALSE(o.scheduler.ray_feedback);
  s.size = "wide";
  EXPECT_THROW(loop::apply(s, o), std::invalid_argument);
}

// A renderer whose frame costs fixed + per · s² milliseconds at scale s.
struct SimulatedRenderer {
  double fixed = 0, per = 0;
  double cost(double scale) const { return fixed + per * scale * scale; }
};

/// Runs `frames` busy frames through the control; returns the last scale.
double settle(loop::ResolutionControl& control, const SimulatedRenderer& r, int frames) {
  double s = 1;
  for (int i = 0; i < frames; ++i) {
    s = control.next(true);
    control.measured(s, r.cost(s));
  }
  return s;
}

TEST(ResolutionControl, HoldsTheFrameTimeWhileBusyAndRefinesWhenStill) {
  // 1.5 s a full frame with 10 ms that do not scale: about sqrt(90/1500) = 0.245 of the side.
  loop::ResolutionControl control({100, 0.125, 0.2});
  const SimulatedRenderer slow{10, 1490};
  const double s = settle(control, slow, 12);
  EXPECT_LE(slow.cost(s), 100 * 1.2) << "scale " << s;
  EXPECT_GE(slow.cost(s + 1.0 / 16), 100) << "the largest step that fits: scale " << s;
  EXPECT_NEAR(control.predict(1.0), slow.cost(1.0), 1.0);
  EXPECT_NEAR(control.predict(0.25), slow.cost(0.25), 1.0);
  // Still: one full frame; busy again: back to the busy scale at once.
  EXPECT_EQ(control.next(false), 1.0);
  control.measured(1.0, slow.cost(1.0));
  EXPECT_EQ(control.next(true), s);
}

TEST(ResolutionControl, GrowsWhenTheRendererGetsFasterAndStaysWithinItsRange) {
  loop::ResolutionControl control({100, 0.25, 0.2});
  // A renderer far too slow for the target: the smallest scale, never below it.
  EXPECT_EQ(settle(control, {150, 5000}, 12), 0.25);
  // A fast renderer (a GPU, a smaller view): full resolution while busy too.
  EXPECT_EQ(settle(control, {2, 40}, 24), 1.0);
  // The scale does not move with a little noise about the target.
  loop::ResolutionControl steady({100, 0.125, 0.2});
  const SimulatedRenderer r{0, 400};  // 100 ms at scale 0.5
  const double s = settle(steady, r, 12);
  EXPECT_EQ(s, 0.5);
  for (int i = 0; i < 20; ++i) {
    EXPECT_EQ(steady.next(true), s);
    steady.measured(s, r.cost(s) * (i % 2 ? 1.1 : 0.9));
  }
  EXPECT_THROW(loop::ResolutionControl({0, 0.5, 0.2}), std::invalid_argument);
  EXPECT_THROW(loop::ResolutionControl({100, 0, 0.2}), std::invalid_argument);
  EXPECT_EQ(loop::scaled_size(512, 300, 0.25), (std::pair<int, int>{128, 75}));
  EXPECT_EQ(loop::scaled_size(3, 2, 0.1), (std::pair<int, int>{1, 1}));
}

}  // namespace
}  // namespace volreel
