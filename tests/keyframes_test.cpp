// keyframes_test.cpp: sparse keyframes end to end (encoder/keyframes.hpp, format/time_step.hpp):
// a node constant in time stores its brick at the ends of a stretch only, a field linear in time
// keeps its two ends, every time step decodes within the codec's bound, a resumed encode writes
// the same bytes, and readers refuse frames whose nodes' keyframes are missing or out of place.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>

#include "frame_edit.hpp"
#include "keyframe_series.hpp"
#include "test_util.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/encoder/series_encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel {
namespace {

namespace fs = std::filesystem;

constexpr Dims dims{70, 40, 40};  // finest grid 3×2×2 under a root
constexpr std::size_t frames = 9;

encoder::EncodeJob zfp_job(std::uint32_t gap, double accuracy = 1e-3) {
  encoder::EncodeJob job;
  job.coding.codec = format::Codec::zfp;
  job.coding.zfp_accuracy = accuracy;
  job.max_keyframe_gap = gap;
  return job;
}

encoder::EncodeJob ksvd_job(const fs::path& dir, std::uint32_t gap) {
  const fs::path dict = dir / "dct.bin";
  format::write_dictionary_file(dict, format::dct_dictionary(6, "test"));
  encoder::EncodeJob job;
  job.coding.codec = format::Codec::ksvd;
  job.coding.tolerance = 2e-3;
  job.dictionary_file = dict;
  job.max_keyframe_gap = gap;
  return job;
}

/// Whether node (level, x, y, z) has a brick at each time step.
std::vector<bool> stored_steps(const format::Container& c, format::NodePosition p) {
  std::vector<bool> out;
  for (std::size_t t = 0; t < c.frame_count(); ++t) {
    const format::FrameFile f = c.open_frame(t);
    const std::uint32_t i = f.view().find_node(p);
    out.push_back(i != format::no_node_index && f.view().has_brick(i));
  }
  return out;
}

/// The largest difference between each decoded time step (as the player draws it) and the series.
double largest_error(const format::Container& c, const datasets::SeriesReader& series) {
  format::TimeStepDecoder steps(c);
  std::vector<float> want(dims.voxels()), got(dims.voxels());
  double worst = 0;
  for (std::size_t t = 0; t < c.frame_count(); ++t) {
    series.read_frame(t, want);
    steps.decode(t, c.manifest().levels - 1, got);
    for (std::size_t i = 0; i < got.size(); ++i)
      worst = std::max(worst, std::abs(static_cast<double>(got[i]) - static_cast<double>(want[i])));
  }
  return worst;
}

TEST(Keyframes, AStillRegionStoresItsBricksAtTheEndsOnly) {
  test::TempDir dir("keyframes-still");
  test::write_keyframe_series(dir.path() / "series", dims, frames);
  const auto series = datasets::open_series(dir.path() / "series");
  const auto summary = encoder::encode_series(*series, dir.path() / "k.vreel", zfp_job(8));
  const format::Container c(dir.path() / "k.vreel");
  EXPECT_EQ(c.manifest().max_keyframe_gap, 8u);
  const std::uint32_t finest = c.manifest().levels - 1;
  std::vector<bool> ends(frames, false);
  ends.front() = ends.back() = true;
  for (std::uint32_t z = 0; z < 2; ++z)
    for (std::uint32_t y = 0; y < 2; ++y) {
      // Grid column 0 (voxels up to x = 34 with its apron) never changes: no brick in between.
      EXPECT_EQ(stored_steps(c, {finest, 0, y, z}), ends) << "still node " << y << " " << z;
      // Column 2 changes faster than interpolation follows: a brick at every step.
      EXPECT_EQ(stored_steps(c, {finest, 2, y, z}), std::vector<bool>(frames, true));
    }
  EXPECT_GT(summary.nodes_interpolated, 0u);
  EXPECT_LE(largest_error(c, *series), 1e-3 + 1e-6);
  // The same series with every brick stored is larger.
  const auto dense = encoder::encode_series(*series, dir.path() / "d.vreel", zfp_job(1));
  EXPECT_EQ(dense.nodes_interpolated, 0u);
  EXPECT_LT(summary.container_bytes, dense.container_bytes);
  EXPECT_TRUE(format::verify_container(dir.path() / "k.vreel").empty());
}

class LinearInTime : public ::testing::TestWithParam<format::Codec> {};

TEST_P(LinearInTime, KeepsItsTwoEnds) {
  test::TempDir dir("keyframes-linear");
  test::write_keyframe_series(dir.path() / "series", dims, frames, true);
  const auto series = datasets::open_series(dir.path() / "series");
  const encoder::EncodeJob job =
      GetParam() == format::Codec::zfp ? zfp_job(8) : ksvd_job(dir.path(), 8);
  encoder::encode_series(*series, dir.path() / "k.vreel", job);
  const format::Container c(dir.path() / "k.vreel");
  // Every node: its bricks at steps 0 and 8, interpolated between.
  for (std::size_t t = 0; t < frames; ++t) {
    const format::FrameFile f = c.open_frame(t);
    EXPECT_EQ(f.view().brick_count(), t == 0 || t + 1 == frames ? f.view().node_count() : 0u)
        << "step " << t;
  }
  if (GetParam() == format::Codec::zfp) {
    EXPECT_LE(largest_error(c, *series), 1e-3 + 1e-6);
  }
}

INSTANTIATE_TEST_SUITE_P(Codecs, LinearInTime,
                         ::testing::Values(format::Codec::zfp, format::Codec::ksvd),
                         [](const auto& param) {
                           return param.param == format::Codec::zfp ? "zfp" : "ksvd";
                         });

TEST(Keyframes, EveryTimeStepHoldsThePointwiseBound) {
  // ksvd with --max-error: every value of every step, interpolated or not, within the bound.
  test::TempDir dir("keyframes-bound");
  test::write_keyframe_series(dir.path() / "series", dims, frames);
  const auto series = datasets::open_series(dir.path() / "series");
  encoder::EncodeJob job = ksvd_job(dir.path(), 4);
  job.coding.tolerance = 4e-3;
  job.coding.max_error = 5e-3;
  const auto summary = encoder::encode_series(*series, dir.path() / "k.vreel", job);
  EXPECT_GT(summary.nodes_interpolated, 0u);
  const format::Container c(dir.path() / "k.vreel");
  EXPECT_LE(largest_error(c, *series), 5e-3);
  EXPECT_LE(summary.delivered.max_abs_error, 5e-3);
  // Stretches of 4 steps: 0-4 and 4-8 store every node at 0, 4 and 8.
  EXPECT_EQ(c.open_frame(4).view().brick_count(), c.open_frame(4).view().node_count());
}

TEST(Keyframes, AResumedEncodeWritesTheSameFrames) {
  test::TempDir dir("keyframes-resume");
  test::write_keyframe_series(dir.path() / "series", dims, frames);
  const auto series = datasets::open_series(dir.path() / "series");
  const fs::path out = dir.path() / "k.vreel";
  encoder::encode_series(*series, out, zfp_job(4));
  std::vector<std::vector<std::byte>> before;
  for (std::size_t t = 0; t < frames; ++t)
    before.push_back(test::read_bytes(out / format::frame_file_name(t)));
  fs::remove(out / format::frame_file_name(6));  // an interrupted second stretch
  encoder::EncodeJob job = zfp_job(4);
  job.resume = true;
  const auto summary = encoder::encode_series(*series, out, job);
  EXPECT_EQ(summary.skipped, frames - 1);
  for (std::size_t t = 0; t < frames; ++t)
    EXPECT_EQ(test::read_bytes(out / format::frame_file_name(t)), before[t]) << "frame " << t;
  EXPECT_TRUE(format::verify_container(out).empty());
}

class KeyframeReader : public ::testing::Test {
 protected:
  void SetUp() override {
    test::write_keyframe_series(dir.path() / "series", dims, frames);
    const auto series = datasets::open_series(dir.path() / "series");
    encoder::encode_series(*series, out, zfp_job(8));
  }
  /// The container's manifest with max_keyframe_gap set to `gap` (checksum recomputed).
  void set_gap(std::uint32_t gap) {
    nlohmann::json j = format::manifest_to_json(format::Container(out).manifest());
    j["max_keyframe_gap"] = gap;
    std::ofstream(out / "manifest.json") << format::manifest_text(j);
  }
  std::string decode_error(std::size_t t) {
    try {
      const format::Container c(out);
      format::TimeStepDecoder steps(c);
      steps.decode(t, c.manifest().levels - 1);
    } catch (const format::FormatError& e) {
      return e.what();
    }
    return "";
  }
  test::TempDir dir{"keyframes-reader"};
  fs::path out = dir.path() / "k.vreel";
};

TEST_F(KeyframeReader, AMissingKeyframeIsNamed) {
  fs::remove(out / format::frame_file_name(8));
  const std::string e = decode_error(4);
  EXPECT_NE(e.find("000008.vrf"), std::string::npos) << e;
  EXPECT_FALSE(format::verify_container(out).empty());
}

TEST_F(KeyframeReader, AGapLongerThanTheManifestAllowsIsRefused) {
  set_gap(2);
  const std::string e = decode_error(4);
  EXPECT_NE(e.find("without a brick stored within 1 time steps"), std::string::npos) << e;
  EXPECT_NE(e.find("000004.vrf"), std::string::npos) << e;
}

TEST_F(KeyframeReader, WithoutGapsEveryFrameMustStoreEveryNode) {
  set_gap(1);
  const format::Container c(out);
  try {
    c.open_frame(4);
    FAIL() << "a frame without every brick was accepted";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("max_keyframe_gap 1"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(c.open_frame(0));
}

TEST_F(KeyframeReader, BricksOutOfNodeOrderAreRefused) {
  const fs::path path = out / format::frame_file_name(4);
  const std::vector<std::byte> good = test::read_bytes(path);
  format::FrameHeader h;
  std::memcpy(&h, good.data(), sizeof h);
  ASSERT_LT(h.brick_count, h.node_count);
  // The first node with a brick claims another index.
  for (std::uint32_t i = 0; i < h.node_count; ++i) {
    format::Node n;
    std::memcpy(&n, good.data() + h.node_table_offset + 16 * i, 16);
    if (n.brick == format::no_brick) continue;
    std::vector<std::byte> bad = good;
    const std::uint32_t wrong = n.brick + 1;
    std::memcpy(bad.data() + h.node_table_offset + 16 * i, &wrong, 4);
    test::reseal_frame(bad);
    try {
      format::FrameView view(bad, path);
      FAIL() << "accepted";
    } catch (const format::FormatError& e) {
      EXPECT_NE(std::string(e.what()).find("brick index"), std::string::npos) << e.what();
    }
    break;
  }
}

}  // namespace
}  // namespace volreel
