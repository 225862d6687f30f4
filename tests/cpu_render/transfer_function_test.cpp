// transfer_function_test.cpp: tables from control points, presets, the JSON form and its errors,
// opacity correction, and the histogram visibility test (against format::histogram_bin).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>
#include <vector>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel {
namespace {

using cpu_render::ControlPoint;
using cpu_render::TransferFunction;

TEST(CpuRenderTransferFunction, InterpolatesControlPoints) {
  // Range [0, 10] with 11 entries: entry i at value i.
  const TransferFunction tf({{2, 0, 0, 0, 0}, {6, 1, 0.5f, 0, 0.8f}}, 0, 10, 11);
  ASSERT_EQ(tf.entry_count(), 11);
  EXPECT_FLOAT_EQ(tf.table()[0][3], 0);     // below the first point: clamped
  EXPECT_FLOAT_EQ(tf.table()[4][0], 0.5f);  // halfway from 2 to 6
  EXPECT_FLOAT_EQ(tf.table()[4][3], 0.4f);
  EXPECT_FLOAT_EQ(tf.table()[9][1], 0.5f);  // above the last point: clamped
  EXPECT_FLOAT_EQ(tf.lookup(5)[0], 0.75f);
  EXPECT_FLOAT_EQ(tf.lookup(4.5f)[3], 0.5f);  // between entries 4 and 5
  EXPECT_FLOAT_EQ(tf.lookup(-100)[3], 0);
  EXPECT_FLOAT_EQ(tf.lookup(100)[3], 0.8f);
  EXPECT_FLOAT_EQ(tf.lookup(NAN)[3], 0);
  // Equal values make a step.
  const TransferFunction step({{0, 0, 0, 0, 0}, {5, 0, 0, 0, 0}, {5, 1, 1, 1, 1}, {10, 1, 1, 1, 1}},
                              0, 10, 11);
  EXPECT_FLOAT_EQ(step.table()[4][3], 0);
  EXPECT_FLOAT_EQ(step.table()[5][3], 1);
}

TEST(CpuRenderTransferFunction, Presets) {
  for (const auto& name : TransferFunction::preset_names()) {
    const auto tf = TransferFunction::preset(name, -2, 3);
    EXPECT_EQ(tf.entry_count(), 256) << name;
    EXPECT_FLOAT_EQ(tf.lo(), -2);
    EXPECT_FLOAT_EQ(tf.hi(), 3);
    float max_alpha = 0;
    for (const auto& e : tf.table())
      for (float c : e) {
        ASSERT_GE(c, 0) << name;
        ASSERT_LE(c, 1) << name;
      }
    for (const auto& e : tf.table()) max_alpha = std::max(max_alpha, e[3]);
    if (name == "transparent")
      EXPECT_EQ(max_alpha, 0);
    else
      EXPECT_GT(max_alpha, 0.1f) << name;
  }
  EXPECT_FLOAT_EQ(TransferFunction::preset("grayscale", 0, 1, 0.5f).table().back()[3], 0.1f);
  EXPECT_THROW(TransferFunction::preset("nope", 0, 1), InputError);
  EXPECT_THROW(TransferFunction::preset("fire", 1, 1), InputError);
}

TEST(CpuRenderTransferFunction, JsonRoundTrip) {
  const TransferFunction tf({{-1, 0.1f, 0.2f, 0.3f, 0}, {0.5f, 1, 0, 0.25f, 0.5f}}, -2, 2, 300);
  const auto json = tf.to_json();
  EXPECT_EQ(TransferFunction::from_json(json, {0, 1}), tf);
  // Through text as well.
  EXPECT_EQ(TransferFunction::from_json(nlohmann::json::parse(json.dump()), {0, 1}), tf);
  // A preset round-trips through its points.
  const auto fire = TransferFunction::from_json({{"preset", "fire"}, {"opacity", 0.5}}, {-3, 4});
  EXPECT_EQ(fire, TransferFunction::preset("fire", -3, 4, 0.5f));
  EXPECT_EQ(TransferFunction::from_json(fire.to_json(), {0, 1}), fire);
  // Points without a range span their values.
  const auto pts = TransferFunction::from_json(
      nlohmann::json::parse(R"({"points": [[2, 0, 0, 0, 0], [4, 1, 1, 1, 1]]})"), {0, 1});
  EXPECT_FLOAT_EQ(pts.lo(), 2);
  EXPECT_FLOAT_EQ(pts.hi(), 4);
}

/// The message of the InputError from_json throws, or "" if it does not throw.
std::string json_error(const std::string& text) {
  try {
    TransferFunction::from_json(nlohmann::json::parse(text), {0, 1}, "tf.json");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(CpuRenderTransferFunction, JsonErrorsNameTheField) {
  const auto expect = [](const std::string& text, const std::string& needle) {
    const std::string message = json_error(text);
    EXPECT_NE(message.find(needle), std::string::npos)
        << "input " << text << " gave \"" << message << "\", expected it to mention " << needle;
  };
  expect(R"([1, 2])", "tf.json: expected a JSON object");
  expect(R"({})", "expected a \"preset\" or \"points\"");
  expect(R"({"preset": "fire", "points": []})", "not both");
  expect(R"({"preset": "lava"})", "tf.json.preset: expected one of grayscale");
  expect(R"({"preset": 3})", "tf.json.preset");
  expect(R"({"preset": "fire", "range": [1, 0]})", "tf.json.range: expected lo < hi");
  expect(R"({"preset": "fire", "range": [0]})", "tf.json.range: expected [lo, hi]");
  expect(R"({"preset": "fire", "colour": 1})", "unknown field \"colour\"");
  expect(R"({"preset": "fire", "entries": 1})", "tf.json.entries");
  expect(R"({"preset": "fire", "entries": 2.5})", "tf.json.entries: expected an integer");
  expect(R"({"points": []})", "tf.json.points: expected a non-empty array");
  expect(R"({"points": [[0, 0, 0, 0]]})", "tf.json.points[0]: expected [value, r, g, b, a]");
  expect(R"({"points": [[0, 0, 0, 0, 0], [1, 2, 0, 0, 0]]})", "tf.json.points[1][1] (r)");
  expect(R"({"points": [[0, 0, 0, 0, 0], [1, 0, 0, 0, "a"]]})", "tf.json.points[1][4] (a)");
  expect(R"({"points": [[1, 0, 0, 0, 0], [0, 0, 0, 0, 0]]})",
         "tf.json.points[1][0] (value): expected values in increasing order");
  expect(R"({"points": [[0, 0, 0, 0, 0]], "opacity": 2})", "presets only");
  // Beyond a float's range: named where it was written, not as an infinite range.
  expect(R"({"points": [[-1e40, 0, 0, 0, 0], [1e40, 0, 0, 0, 0]]})",
         "tf.json.points[0][0] (value): expected a number in [");
  expect(R"({"preset": "fire", "range": [-1, 1e39]})", "tf.json.range[1]: expected a number in [");
  EXPECT_EQ(json_error(R"({"preset": "fire"})"), "");
}

TEST(CpuRenderTransferFunction, OpacityCorrection) {
  const TransferFunction tf({{0, 1, 1, 1, 0.5f}}, 0, 1, 2);
  EXPECT_FLOAT_EQ(tf.opacity_corrected(2).table()[0][3], 0.75f);  // 1 − 0.5²
  EXPECT_FLOAT_EQ(tf.opacity_corrected(0.5).table()[0][3], float(1 - std::sqrt(0.5)));
  EXPECT_FLOAT_EQ(tf.opacity_corrected(1).table()[0][3], 0.5f);
  EXPECT_FLOAT_EQ(tf.opacity_corrected(2).table()[0][0], 1.0f);  // colour unchanged
  const TransferFunction opaque({{0, 1, 1, 1, 1}}, 0, 1, 2);
  EXPECT_FLOAT_EQ(opaque.opacity_corrected(0.1).table()[0][3], 1.0f);
}

TEST(CpuRenderTransferFunction, VisibleBins) {
  // Opaque only for values in [5, 7.5] of [0, 10]; histogram over [0, 10]: 64 bins of 0.15625.
  const TransferFunction tf(
      {{4.9f, 1, 1, 1, 0}, {5, 1, 1, 1, 1}, {7.5f, 1, 1, 1, 1}, {7.6f, 1, 1, 1, 0}}, 0, 10, 1024);
  const std::uint64_t mask = tf.visible_bins(0, 10);
  for (std::uint32_t b = 0; b < 64; ++b) {
    const double bin_lo = b * 10.0 / 64, bin_hi = (b + 1) * 10.0 / 64;
    if (bin_hi < 4.8 || bin_lo > 7.7) {
      EXPECT_FALSE(mask >> b & 1) << "bin " << b;
    }
    if (bin_lo >= 5 && bin_hi <= 7.5) {
      EXPECT_TRUE(mask >> b & 1) << "bin " << b;
    }
  }
  EXPECT_FALSE(tf.visible(std::uint64_t{1} << 5, 0, 10));
  EXPECT_TRUE(tf.visible(std::uint64_t{1} << 40, 0, 10));
  EXPECT_EQ(TransferFunction::preset("transparent", 0, 1).visible_bins(0, 1), 0u);
  // Values beyond the histogram's range fall in bins 0 and 63.
  const TransferFunction edges(
      {{0, 1, 1, 1, 1}, {1, 1, 1, 1, 0}, {9, 1, 1, 1, 0}, {10, 1, 1, 1, 1}}, 0, 10, 256);
  const std::uint64_t m2 = edges.visible_bins(2, 8);  // TF visible only outside [1, 9]
  EXPECT_TRUE(m2 & 1);
  EXPECT_TRUE(m2 >> 63 & 1);
  EXPECT_FALSE(m2 >> 32 & 1);
}

TEST(CpuRenderTransferFunction, VisibleBinsNeverHideAVisibleValue) {
  // Conservative: any value the TF makes visible lies in a visible bin (format::histogram_bin).
  SplitMix64 rng(7);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<ControlPoint> points;
    float v = static_cast<float>(rng.uniform(-2, 0));
    for (int i = 0; i < 6; ++i) {
      const float a = rng.uniform() < 0.5 ? 0.0f : static_cast<float>(rng.uniform());
      points.push_back({v, 1, 1, 1, a});
      v += static_cast<float>(rng.uniform(0, 1));
    }
    const TransferFunction tf(points, points.front().value, points.back().value,
                              trial % 2 ? 256 : 1000);
    const float lo = static_cast<float>(rng.uniform(-2, 0)),
                hi = lo + static_cast<float>(rng.uniform(0.5, 4));
    const std::uint64_t mask = tf.visible_bins(lo, hi);
    for (int i = 0; i < 2000; ++i) {
      const float x = static_cast<float>(rng.uniform(double(lo) - 1, double(hi) + 1));
      if (tf.lookup(x)[3] > 0) {
        ASSERT_TRUE(mask >> format::histogram_bin(x, lo, hi) & 1)
            << "value " << x << " visible, bin " << format::histogram_bin(x, lo, hi) << " hidden";
      }
    }
  }
}

TEST(CpuRenderTransferFunction, VisibleHull) {
  using Tf = TransferFunction;
  EXPECT_EQ(Tf::histogram_hull(0), 0u);
  EXPECT_EQ(Tf::histogram_hull(0b10100), 0b11100u);
  EXPECT_EQ(Tf::histogram_hull(1), 1u);
  EXPECT_EQ(Tf::histogram_hull(std::uint64_t{1} << 63 | 1), ~std::uint64_t{0});
  // Visible only around value 6.4 of [0, 10]: bin 40 (and its neighbours, conservatively).
  const Tf tf({{6.2f, 1, 1, 1, 0}, {6.4f, 1, 1, 1, 1}, {6.6f, 1, 1, 1, 0}}, 0, 10, 1024);
  const auto bit = [](int b) { return std::uint64_t{1} << b; };
  EXPECT_TRUE(tf.visible_hull(bit(10) | bit(50), 0, 10));  // 40 lies between
  EXPECT_FALSE(tf.visible(bit(10) | bit(50), 0, 10));      // though neither bin is visible
  EXPECT_FALSE(tf.visible_hull(bit(10), 0, 10));
  EXPECT_FALSE(tf.visible_hull(bit(45) | bit(50), 0, 10));
  EXPECT_FALSE(tf.visible_hull(0, 0, 10));
}

TEST(CpuRenderTransferFunction, Blend) {
  const TransferFunction a({{0, 0, 0, 0, 0}}, 0, 1, 4), b({{0, 1, 1, 1, 1}}, 2, 3, 4);
  const auto m = TransferFunction::blend(a, b, 0.25f);
  EXPECT_FLOAT_EQ(m.lo(), 0.5f);
  EXPECT_FLOAT_EQ(m.hi(), 1.5f);
  EXPECT_FLOAT_EQ(m.table()[2][3], 0.25f);
  EXPECT_EQ(TransferFunction::blend(a, b, 0), a);
  EXPECT_EQ(TransferFunction::blend(a, b, 1), b);
}

/// Mean extinction −ln(1 − α) per voxel of ray over `values`.
double mean_extinction(const TransferFunction& tf, const std::vector<float>& values) {
  double sum = 0;
  for (float v : values) sum -= std::log1p(-std::min(double(tf.lookup(v)[3]), 0.999999));
  return sum / static_cast<double>(values.size());
}

TEST(CpuRenderTransferFunction, QuantilesShowBothLongTailsAndClearTheBulk) {
  // A signed field with heavy tails on both sides (turbulence pressure-like).
  SplitMix64 rng(5);
  std::vector<float> values(200000);
  for (float& v : values) v = static_cast<float>(rng.normal() * (rng.uniform() < 0.1 ? 4 : 1));
  const TransferFunction tf = TransferFunction::from_quantiles(values, -20, 20);
  EXPECT_FLOAT_EQ(tf.lookup(0.0f)[3], 0.0f) << "the bulk is clear";
  EXPECT_GT(tf.lookup(-8.0f)[3], 0.3f) << "the low tail shows";
  EXPECT_GT(tf.lookup(8.0f)[3], 0.1f) << "the high tail shows";
  EXPECT_GT(tf.lookup(-8.0f)[2], tf.lookup(-8.0f)[0]) << "low: blue";
  EXPECT_GT(tf.lookup(8.0f)[0], tf.lookup(8.0f)[2]) << "high: red";
}

TEST(CpuRenderTransferFunction, QuantilesFadeATailThatIsOnlyTheBulksEdge) {
  // A magnitude (vorticity-like: the values near 0 are the quiet bulk) and a field of blobs over
  // a noisy background: only the long upper tail is a structure.
  SplitMix64 rng(7);
  std::vector<float> magnitude(100000), blobs(100000);
  for (float& v : magnitude) v = static_cast<float>(-std::log(1 - rng.uniform()));  // exponential
  for (std::size_t i = 0; i < blobs.size(); ++i)
    blobs[i] = static_cast<float>(i % 50 == 0 ? rng.uniform(0.2, 1.0) : 0.001 * rng.normal());
  for (const auto& [name, values, lo, hi] : {std::tuple{"magnitude", &magnitude, 0.0f, 15.0f},
                                             std::tuple{"blobs", &blobs, -0.01f, 1.0f}}) {
    const TransferFunction tf = TransferFunction::from_quantiles(*values, lo, hi);
    for (float v : {lo, lo + 0.001f * (hi - lo)})
      EXPECT_FLOAT_EQ(tf.lookup(v)[3], 0.0f) << name << ": the short lower tail is clear at " << v;
    EXPECT_GT(tf.lookup(hi)[3], 0.2f) << name << ": the long upper tail shows";
  }
}

TEST(CpuRenderTransferFunction, QuantilesBoundTheAverageRaysOpticalDepth) {
  // Tails everywhere (noise): without a bound, a 600-voxel ray would keep under 2 % of the light.
  SplitMix64 rng(9);
  std::vector<float> values(100000);
  for (float& v : values) v = static_cast<float>(rng.normal());
  const TransferFunction free = TransferFunction::from_quantiles(values, -6, 6);
  EXPECT_GT(mean_extinction(free, values) * 600, 4.0);
  const TransferFunction bounded = TransferFunction::from_quantiles(values, -6, 6, 600);
  EXPECT_NEAR(mean_extinction(bounded, values) * 600, 2.0, 0.05);
  EXPECT_GT(bounded.lookup(-5)[3], 0.0f) << "the tails still show";
  // A short path needs no scaling.
  const TransferFunction short_path = TransferFunction::from_quantiles(values, -6, 6, 1);
  EXPECT_EQ(short_path, free);
}

}  // namespace
}  // namespace volreel
