// tour_test.cpp: tours — camera, playhead and transfer-function interpolation, playback segments
// (play, reverse, seek, pause, holding at the ends), validation errors that name the field, the
// JSON round trip, and the default tour.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <string>

#include "../test_util.hpp"
#include "volreel/cpu_render/tour.hpp"
#include "volreel/datasets/volume.hpp"

namespace volreel {
namespace {

using cpu_render::Tour;
using cpu_render::TourContext;

const TourContext context{{240, 40, 30}, 5, {-1, 1}};

Tour tour(const std::string& text) {
  return Tour::parse(text, context, "tour.json");
}

TEST(CpuRenderTour, CameraKeysInterpolate) {
  const Tour t = tour(R"({"duration": 10, "camera": [
      {"t": 0, "azimuth": 0, "elevation": 10, "distance": 100, "target": [0, 0, 0], "fov": 40},
      {"t": 10, "azimuth": 360, "distance": 300, "target": [10, 20, 30]}]})");
  const auto mid = t.at(5).camera;
  EXPECT_NEAR(mid.azimuth, std::numbers::pi, 1e-12);
  EXPECT_NEAR(mid.elevation, 10 * std::numbers::pi / 180, 1e-12);  // repeated from key 0
  EXPECT_NEAR(mid.fov_y, 40 * std::numbers::pi / 180, 1e-12);
  EXPECT_DOUBLE_EQ(mid.distance, 200);
  EXPECT_DOUBLE_EQ(mid.target.y, 10);
  EXPECT_EQ(mid.width, 512);
  EXPECT_DOUBLE_EQ(t.at(-3).camera.distance, 100);  // clamped to the tour
  EXPECT_DOUBLE_EQ(t.at(99).camera.distance, 300);
  // No camera: the framing camera throughout.
  const auto framing = player::OrbitCamera::framing({240, 40, 30}, 512, 512);
  const auto still = tour(R"({"duration": 1})").at(0.5).camera;
  EXPECT_NEAR(still.distance, framing.distance, 1e-9);
  EXPECT_NEAR(still.azimuth, framing.azimuth, 1e-12);
  EXPECT_DOUBLE_EQ(still.target.x, 120);
}

TEST(CpuRenderTour, PlayheadKeysAndCuts) {
  const Tour t = tour(R"({"duration": 8, "fps": 10, "size": [64, 32], "playhead": [
      {"t": 1, "keyframe": 0}, {"t": 3, "keyframe": 4}, {"t": 3, "keyframe": 1}, {"t": 5, "keyframe": 2}]})");
  EXPECT_DOUBLE_EQ(t.at(0).playhead, 0);
  EXPECT_DOUBLE_EQ(t.at(2).playhead, 2);
  EXPECT_NEAR(t.at(2.999).playhead, 3.998, 1e-9);
  EXPECT_DOUBLE_EQ(t.at(3).playhead, 1);  // the cut: the later key wins at its time
  EXPECT_DOUBLE_EQ(t.at(4).playhead, 1.5);
  EXPECT_DOUBLE_EQ(t.at(7).playhead, 2);
  EXPECT_EQ(t.frame_count(), 80u);
  EXPECT_EQ(t.width(), 64);
  EXPECT_EQ(t.at(0).camera.height, 32);
}

TEST(CpuRenderTour, Segments) {
  // 5 keyframes (0..4): play at 2/s reaches 4 at t = 2 and holds; reverse 1 s at 1/s -> 3;
  // seek to 1.5; pause 1 s; play 0.5 s at 1/s -> 2; then hold.
  const Tour t = tour(R"({"duration": 10, "segments": [
      {"play": 4, "speed": 2}, {"reverse": 1}, {"seek": 1.5}, {"pause": 1}, {"play": 0.5}]})");
  EXPECT_DOUBLE_EQ(t.at(0).playhead, 0);
  EXPECT_DOUBLE_EQ(t.at(1).playhead, 2);
  EXPECT_DOUBLE_EQ(t.at(2).playhead, 4);
  EXPECT_DOUBLE_EQ(t.at(3).playhead, 4);
  EXPECT_DOUBLE_EQ(t.at(4.5).playhead, 3.5);
  EXPECT_NEAR(t.at(4.999).playhead, 3.001, 1e-9);
  EXPECT_DOUBLE_EQ(t.at(5).playhead, 1.5);
  EXPECT_DOUBLE_EQ(t.at(5.5).playhead, 1.5);
  EXPECT_DOUBLE_EQ(t.at(6.25).playhead, 1.75);
  EXPECT_DOUBLE_EQ(t.at(9).playhead, 2);
  // Reverse from a start holds at 0.
  const Tour r = tour(R"({"duration": 4, "start": 1, "segments": [{"reverse": 3, "speed": 0.5}]})");
  EXPECT_DOUBLE_EQ(r.at(1).playhead, 0.5);
  EXPECT_DOUBLE_EQ(r.at(2).playhead, 0);
  EXPECT_DOUBLE_EQ(r.at(3.5).playhead, 0);
}

TEST(CpuRenderTour, TransferKeysBlend) {
  const Tour t = tour(R"({"duration": 2, "transfer": [
      {"t": 0, "points": [[0, 0, 0, 0, 0]], "range": [0, 1]},
      {"t": 2, "points": [[0, 1, 1, 1, 1]], "range": [0, 1]}]})");
  EXPECT_FLOAT_EQ(t.at(0).transfer.lookup(0.5f)[3], 0);
  EXPECT_FLOAT_EQ(t.at(0.5).transfer.lookup(0.5f)[3], 0.25f);
  EXPECT_FLOAT_EQ(t.at(2).transfer.lookup(0.5f)[3], 1);
  // Default: cool-warm over the container's range.
  EXPECT_EQ(tour(R"({"duration": 1})").at(0).transfer,
            cpu_render::TransferFunction::preset("cool-warm", -1, 1));
}

std::string tour_error(const std::string& text) {
  try {
    tour(text);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CpuRenderTour, ValidationNamesTheField) {
  const auto expect = [](const std::string& text, const std::string& needle) {
    const std::string message = tour_error(text);
    EXPECT_NE(message.find(needle), std::string::npos)
        << "input " << text << " gave \"" << message << "\", expected it to mention " << needle;
  };
  expect(R"({"duration": 1,)", "tour.json: not valid JSON");
  expect(R"({"duration": 1e999})", "tour.json: not valid JSON: number overflow");
  expect(std::string(100000, '[') + std::string(100000, ']'),
         "tour.json: expected JSON nested at most 64");
  expect(R"({})", "tour.json: missing field \"duration\"");
  expect(R"({"duration": -1})", "tour.json.duration: expected seconds in (0, 1e6], found -1");
  expect(R"({"duration": 1, "durtion": 2})", "unknown field \"durtion\"");
  expect(R"({"duration": 1, "fps": "30"})", "tour.json.fps: expected a number, found \"30\"");
  expect(R"({"duration": 1, "size": [64]})", "tour.json.size: expected [width, height]");
  expect(R"({"duration": 1, "size": [64, 0]})", "tour.json.size[1]");
  expect(R"({"duration": 1, "size": [64.5, 10]})", "tour.json.size[0]: expected a whole number");
  expect(R"({"duration": 5, "camera": [{"t": 3}, {"t": 1}]})",
         "tour.json.camera[1].t: expected a time ≥ 3 (the previous key's), found 1");
  expect(R"({"duration": 5, "camera": [{"t": 6}]})", "tour.json.camera[0].t");
  expect(R"({"duration": 5, "camera": [{"azimuth": 3}]})",
         "tour.json.camera[0]: missing field \"t\"");
  expect(R"({"duration": 5, "camera": [{"t": 0, "elevation": 90}]})",
         "tour.json.camera[0].elevation");
  expect(R"({"duration": 5, "camera": [{"t": 0, "distance": 0}]})", "tour.json.camera[0].distance");
  expect(R"({"duration": 5, "camera": [{"t": 0, "target": [1, 2]}]})",
         "tour.json.camera[0].target");
  expect(R"({"duration": 5, "camera": [{"t": 0, "fov": 180}]})", "tour.json.camera[0].fov");
  expect(R"({"duration": 5, "camera": []})", "tour.json.camera: expected a non-empty array");
  expect(R"({"duration": 5, "playhead": [{"t": 0, "keyframe": 4.5}]})",
         "tour.json.playhead[0].keyframe: expected a number in [0, 4]");
  expect(R"({"duration": 5, "playhead": [{"t": 0}]})", "missing field \"keyframe\"");
  expect(R"({"duration": 5, "playhead": [{"t": 0, "keyframe": 0}], "segments": [{"pause": 1}]})",
         "not both");
  expect(R"({"duration": 5, "segments": [{"play": 1, "pause": 1}]})",
         "tour.json.segments[0]: expected exactly one of");
  expect(R"({"duration": 5, "segments": [{"play": 0}]})", "tour.json.segments[0].play");
  expect(R"({"duration": 5, "segments": [{"play": 1, "speed": -1}]})",
         "tour.json.segments[0].speed");
  expect(R"({"duration": 5, "segments": [{"seek": 9}]})", "tour.json.segments[0].seek");
  expect(R"({"duration": 5, "segments": [{"pause": 1, "speed": 2}]})", "\"speed\" applies");
  expect(R"({"duration": 5, "start": 1})", "\"start\" applies to \"segments\" only");
  expect(R"({"duration": 5, "transfer": [{"t": 0, "preset": "lava"}]})",
         "tour.json.transfer[0].preset");
  expect(R"({"duration": 5, "transfer": [{"t": 0, "points": [[0, 0, 0, 0, 2]]}]})",
         "tour.json.transfer[0].points[0][4] (a)");
  EXPECT_EQ(tour_error(R"({"duration": 5})"), "");
}

void expect_same_frames(const Tour& a, const Tour& b) {
  ASSERT_EQ(a.frame_count(), b.frame_count());
  for (std::size_t i = 0; i < a.frame_count(); i += 7) {
    const auto x = a.at(a.frame_time(i)), y = b.at(b.frame_time(i));
    EXPECT_DOUBLE_EQ(x.playhead, y.playhead) << "frame " << i;
    EXPECT_DOUBLE_EQ(x.camera.azimuth, y.camera.azimuth) << "frame " << i;
    EXPECT_DOUBLE_EQ(x.camera.elevation, y.camera.elevation) << "frame " << i;
    EXPECT_DOUBLE_EQ(x.camera.distance, y.camera.distance) << "frame " << i;
    EXPECT_EQ(x.transfer, y.transfer) << "frame " << i;
  }
}

TEST(CpuRenderTour, DefaultTourAndRoundTrip) {
  const Tour t = Tour::default_for(context, 3);
  EXPECT_EQ(t.frame_count(), 360u);  // 12 s at 30 fps
  EXPECT_EQ(t.width(), 512);
  // Plays forward to the last keyframe in 4 s, then reverses for 2 s.
  EXPECT_DOUBLE_EQ(t.at(0).playhead, 0);
  EXPECT_DOUBLE_EQ(t.at(4).playhead, 4);
  EXPECT_NEAR(t.at(6 - 1e-9).playhead, 2, 1e-6);
  // A seek at t = 6, then a pause: constant over [6, 7].
  EXPECT_DOUBLE_EQ(t.at(6).playhead, t.at(7).playhead);
  // Slow motion afterwards: fractional playheads between keyframes.
  EXPECT_NEAR(t.at(9).playhead, std::min(t.at(7).playhead + 0.5, 4.0), 1e-12);
  // One orbit.
  EXPECT_NEAR(t.at(12).camera.azimuth - t.at(0).camera.azimuth, 2 * std::numbers::pi, 1e-9);
  // Through JSON text and a file.
  expect_same_frames(t, Tour::parse(t.to_json().dump(2), context));
  test::TempDir dir("tour");
  std::ofstream(dir / "tour.json") << t.to_json().dump();
  expect_same_frames(t, Tour::load(dir / "tour.json", context));
  EXPECT_THROW(Tour::load(dir / "missing.json", context), InputError);
  // From a manifest.
  format::Manifest manifest;
  manifest.dims = {240, 40, 30};
  manifest.frames.resize(5);
  manifest.value_min = -1;
  manifest.value_max = 1;
  const TourContext from_manifest = TourContext::of(manifest);
  EXPECT_EQ(from_manifest.dims, context.dims);
  EXPECT_EQ(from_manifest.keyframes, 5u);
  EXPECT_EQ(from_manifest.value_range, context.value_range);
  manifest.value_max = -1;
  EXPECT_EQ(TourContext::of(manifest).value_range, (std::array<float, 2>{-1.5f, -0.5f}));
  // A single keyframe is fine too.
  const Tour one = Tour::default_for({{34, 34, 34}, 1, {0, 1}});
  EXPECT_DOUBLE_EQ(one.at(5).playhead, 0);
}

}  // namespace
}  // namespace volreel
