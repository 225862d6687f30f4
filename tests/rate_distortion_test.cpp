// rate_distortion_test.cpp: the zfp codec honours its modes and the harness's bps, PSNR, CSV
// and plot are right for codecs whose output is known exactly.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/psnr/rate_distortion.hpp"

namespace vp = volreel::psnr;
namespace vd = volreel::datasets;
using volreel::Dims;

namespace {

/// Frames of an analytic field, held in memory.
class MemorySeries final : public vd::SeriesReader {
 public:
  MemorySeries(Dims dims, std::size_t frames) {
    info_.dims = dims;
    info_.frames = frames;
    info_.variable = "test";
    params_.field = vd::AnalyticField::blobs;
    params_.dims = dims;
    params_.frames = frames;
  }
  using vd::SeriesReader::read_frame;
  void read_frame(std::size_t t, std::span<float> out) const override {
    vd::analytic_frame(params_, t, out);
  }

 private:
  vd::AnalyticParams params_;
};

/// Stores every value as float32 (32 bps) but halves the amplitude: error known exactly.
class HalvingCodec final : public vp::FrameCodec {
 public:
  std::string family() const override { return "halving"; }
  std::string setting() const override { return "x0.5"; }
  void compress(Dims, std::span<const float> frame, std::vector<std::uint8_t>& stream) override {
    stream.resize(frame.size_bytes());
    std::memcpy(stream.data(), frame.data(), stream.size());
  }
  void decompress(Dims, std::span<const std::uint8_t> stream, std::span<float> out) override {
    std::memcpy(out.data(), stream.data(), stream.size());
    for (float& v : out) v *= 0.5f;
  }
  std::size_t shared_bytes() const override { return 1000; }
};

/// Another series' frames at half amplitude: what HalvingCodec decodes, as a whole series.
class HalvedSeries final : public vd::SeriesReader {
 public:
  HalvedSeries(const vd::SeriesReader& original, std::size_t frames) : original_(original) {
    info_ = original.info();
    info_.frames = frames;
  }
  using vd::SeriesReader::read_frame;
  void read_frame(std::size_t t, std::span<float> out) const override {
    original_.read_frame(t, out);
    for (float& v : out) v *= 0.5f;
  }

 private:
  const vd::SeriesReader& original_;
};

}  // namespace

TEST(ZfpCodec, FixedAccuracyMeetsTolerance) {
  const Dims d{20, 18, 16};
  MemorySeries series(d, 1);
  const auto frame = series.read_frame(0);
  for (double tol : {1e-1, 1e-3, 1e-5}) {
    auto codec = vp::make_zfp_accuracy(tol);
    std::vector<std::uint8_t> stream;
    std::vector<float> out(d.voxels());
    codec->compress(d, frame.data, stream);
    codec->decompress(d, stream, out);
    const auto e = vp::compare(frame.data, out);
    EXPECT_LE(e.max_abs_error, tol) << codec->setting();
    EXPECT_GT(e.max_abs_error, 0.0) << "lossy mode should lose something at " << tol;
  }
}

TEST(ZfpCodec, FixedRateGivesExactSize) {
  const Dims d{16, 16, 16};  // a whole number of 4^3 blocks
  MemorySeries series(d, 1);
  const auto frame = series.read_frame(0);
  for (double rate : {1.0, 4.0}) {
    auto codec = vp::make_zfp_rate(rate);
    std::vector<std::uint8_t> stream;
    codec->compress(d, frame.data, stream);
    EXPECT_EQ(stream.size(), static_cast<std::size_t>(rate * static_cast<double>(d.voxels()) / 8))
        << codec->setting();
  }
}

TEST(RateDistortion, HarnessFiguresAreExactForAKnownCodec) {
  const Dims d{16, 16, 12};
  MemorySeries series(d, 3);
  std::vector<std::unique_ptr<vp::FrameCodec>> codecs;
  codecs.push_back(std::make_unique<HalvingCodec>());
  codecs.push_back(vp::make_zfp_rate(2.0));
  vp::RdOptions options;
  options.ssim_frames = 2;
  const auto points = vp::run_rate_distortion(series, codecs, options);
  ASSERT_EQ(points.size(), 2u);
  const vp::RdPoint& halving = points[0].family == "halving" ? points[0] : points[1];
  const vp::RdPoint& zfp = points[0].family == "halving" ? points[1] : points[0];

  // Expected: every frame decoded at half amplitude, range over all three frames.
  vp::ErrorAccumulator expected;
  for (std::size_t t = 0; t < 3; ++t) {
    auto f = series.read_frame(t);
    auto half = f.data;
    for (float& v : half) v *= 0.5f;
    expected.add(f.data, half);
  }
  const double voxels = static_cast<double>(d.voxels()) * 3;
  EXPECT_EQ(halving.bytes, 3 * d.voxels() * 4 + 1000);
  EXPECT_DOUBLE_EQ(halving.bps, 8.0 * (3.0 * static_cast<double>(d.voxels()) * 4 + 1000) / voxels);
  EXPECT_NEAR(halving.psnr, expected.result().psnr, 1e-9);
  EXPECT_NEAR(halving.psnr - halving.psnr_zfp, 20 * std::log10(2.0), 1e-9);
  EXPECT_EQ(halving.ssim_frames, 2u);
  EXPECT_LT(halving.ssim, 1.0);
  EXPECT_GT(halving.ssim, 0.0);
  EXPECT_DOUBLE_EQ(zfp.bps, 2.0);
  EXPECT_GT(zfp.psnr, 20.0);
  EXPECT_GT(zfp.compress_mvoxels_per_s, 0.0);
}

TEST(RateDistortion, ADecodedSeriesMeasuresAsTheSameFrameCodec) {
  const Dims d{16, 16, 12};
  MemorySeries series(d, 3);
  std::vector<std::unique_ptr<vp::FrameCodec>> codecs;
  codecs.push_back(std::make_unique<HalvingCodec>());
  vp::RdOptions options;
  options.ssim_frames = 2;
  const vp::RdPoint framewise = vp::run_rate_distortion(series, codecs, options).at(0);
  vp::RdPoint whole;
  whole.bytes = framewise.bytes;
  vp::measure_decoded_series(series, HalvedSeries(series, 3), options, whole);
  EXPECT_EQ(whole.frames, 3u);
  EXPECT_DOUBLE_EQ(whole.bps, framewise.bps);
  EXPECT_DOUBLE_EQ(whole.psnr, framewise.psnr);
  EXPECT_DOUBLE_EQ(whole.psnr_zfp, framewise.psnr_zfp);
  EXPECT_DOUBLE_EQ(whole.max_abs_error, framewise.max_abs_error);
  EXPECT_DOUBLE_EQ(whole.ssim, framewise.ssim);
  EXPECT_GT(whole.decompress_mvoxels_per_s, 0.0);
  // A decoded series with fewer frames, or other dimensions, is refused by name.
  EXPECT_THROW(vp::measure_decoded_series(series, HalvedSeries(series, 2), options, whole),
               volreel::InputError);
  MemorySeries other(Dims{16, 16, 8}, 3);
  EXPECT_THROW(vp::measure_decoded_series(series, other, options, whole), volreel::InputError);
}

TEST(RateDistortion, CsvAndPlotAreWritten) {
  volreel::test::TempDir dir("rd");
  MemorySeries series(Dims{12, 12, 12}, 2);
  const auto codecs = vp::make_zfp_sweep(2.0);
  EXPECT_EQ(codecs.size(), 21u);
  vp::RdOptions options;
  options.ssim_frames = 0;
  const auto points = vp::run_rate_distortion(series, codecs, options);
  vp::write_rd_csv(dir / "rd.csv", points);
  std::ifstream csv(dir / "rd.csv");
  std::string line;
  int rows = 0;
  std::getline(csv, line);
  EXPECT_EQ(line.rfind("codec,setting,frames,bytes,bps,psnr_db", 0), 0u);
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, 21);
  std::ostringstream table;
  vp::print_rd_table(table, points);
  EXPECT_NE(table.str().find("zfp fixed-rate"), std::string::npos);

  // PSNR rises with rate within each family.
  for (std::size_t i = 1; i < points.size(); ++i) {
    if (points[i].family == points[i - 1].family) {
      EXPECT_GT(points[i].psnr, points[i - 1].psnr - 1e-9) << points[i].setting;
    }
  }

  vp::write_rd_plot(dir / "rd.png", points, "test");
  std::ifstream png(dir / "rd.png", std::ios::binary);
  char magic[8] = {};
  png.read(magic, 8);
  EXPECT_EQ(std::memcmp(magic, "\x89PNG\r\n\x1a\n", 8), 0) << "rd.png is not a PNG";
  EXPECT_FALSE(std::filesystem::exists(dir / "rd.png.gp"));
}

namespace {

vp::RdPoint rd_point(const std::string& family, double bps, double psnr) {
  vp::RdPoint p;
  p.family = family;
  p.setting = "s";
  p.bps = bps;
  p.psnr = psnr;
  return p;
}

}  // namespace

TEST(RateDistortion, PsnrAtBpsInterpolatesWithinOneFamilyOnly) {
  // Out of order, with a lossless setting (infinite PSNR) and a second family in between.
  const std::vector<vp::RdPoint> points = {
      rd_point("a", 0.8, 48), rd_point("b", 0.3, 90), rd_point("a", 0.2, 40),
      rd_point("a", 32, std::numeric_limits<double>::infinity()), rd_point("a", 0.4, 44)};
  EXPECT_NEAR(*vp::psnr_at_bps(points, "a", 0.3), 42.0, 1e-12);
  EXPECT_NEAR(*vp::psnr_at_bps(points, "a", 0.4), 44.0, 1e-12);
  EXPECT_NEAR(*vp::psnr_at_bps(points, "a", 0.6), 46.0, 1e-12);
  EXPECT_NEAR(*vp::psnr_at_bps(points, "a", 0.2), 40.0, 1e-12);
  EXPECT_NEAR(*vp::psnr_at_bps(points, "a", 0.8), 48.0, 1e-12);
  // Never extrapolated: below the first setting, above the last finite one, or another family.
  EXPECT_FALSE(vp::psnr_at_bps(points, "a", 0.19));
  EXPECT_FALSE(vp::psnr_at_bps(points, "a", 1.0));
  EXPECT_FALSE(vp::psnr_at_bps(points, "c", 0.3));
  EXPECT_NEAR(*vp::psnr_at_bps(points, "b", 0.3), 90.0, 1e-12);
  EXPECT_FALSE(vp::psnr_at_bps(points, "b", 0.31));
  // Two settings at the same bps: the better one.
  const std::vector<vp::RdPoint> tied = {rd_point("t", 0.5, 41), rd_point("t", 0.5, 43),
                                         rd_point("t", 0.7, 45)};
  EXPECT_NEAR(*vp::psnr_at_bps(tied, "t", 0.5), 43.0, 1e-12);
  EXPECT_NEAR(*vp::psnr_at_bps(tied, "t", 0.6), 44.0, 1e-12);
}

TEST(RateDistortion, EqualBpsTableComparesWithVariableRate) {
  const std::string ref = "volreel variable-rate";
  const std::string long_name = "volreel variable-rate eps-rule";  // longer than the default column
  const std::vector<vp::RdPoint> points = {rd_point("zfp fixed-accuracy", 0.2, 40),
                                           rd_point("zfp fixed-accuracy", 0.8, 46),
                                           rd_point(ref, 0.3, 50),
                                           rd_point(ref, 0.5, 52),
                                           rd_point(long_name, 0.3, 47.5),
                                           rd_point(long_name, 0.5, 49.5)};
  const std::vector<double> bps = {0.3, 0.4, 0.6};
  const vp::EqualBpsTable t = vp::equal_bps_table(points, bps);
  ASSERT_EQ(t.families.size(), 3u);
  EXPECT_EQ(t.families[0], ref);
  EXPECT_EQ(t.reference, ref);
  ASSERT_EQ(t.psnr.size(), 3u);
  EXPECT_NEAR(*t.psnr[1][0], 51.0, 1e-12);
  EXPECT_NEAR(*t.psnr[1][1], 42.0, 1e-12);
  EXPECT_FALSE(t.psnr[2][0]);
  EXPECT_NEAR(*t.psnr[2][1], 44.0, 1e-12);

  std::ostringstream text;
  vp::print_equal_bps_table(text, t);
  const std::string s = text.str();
  EXPECT_NE(s.find("41.00 ( +9.00)"), std::string::npos) << s;  // 0.3 bps: 50 - 41
  EXPECT_NE(s.find("42.00 ( +9.00)"), std::string::npos) << s;  // 0.4 bps: 51 - 42
  EXPECT_NE(s.find("44.00"), std::string::npos) << s;
  EXPECT_EQ(s.find("44.00 ("), std::string::npos) << s;  // 0.6 bps: no variable rate to compare
  EXPECT_NE(s.find(long_name), std::string::npos) << s;  // names are never cut
  EXPECT_NE(s.find("48.50 ( +2.50)"), std::string::npos) << s;

  const volreel::test::TempDir dir("equal_bps");
  vp::write_equal_bps_csv(dir / "e.csv", t);
  std::ifstream csv(dir / "e.csv");
  std::string line, all;
  std::getline(csv, line);
  EXPECT_EQ(line, "bps,codec,psnr_db,reference,reference_minus_codec_db");
  int rows = 0;
  while (std::getline(csv, line)) ++rows, all += line + '\n';
  EXPECT_EQ(rows, 9);
  EXPECT_NE(all.find("0.4,\"zfp fixed-accuracy\",42,\"volreel variable-rate\",9\n"),
            std::string::npos)
      << all;
  EXPECT_NE(all.find("0.6,\"volreel variable-rate\",,\"volreel variable-rate\",\n"),
            std::string::npos)
      << all;
  EXPECT_FALSE(std::filesystem::exists(dir / "e.csv.tmp"));

  // Without volreel's variable rate there is nothing to compare with.
  const std::vector<vp::RdPoint> zfp_only(points.begin(), points.begin() + 2);
  const vp::EqualBpsTable z = vp::equal_bps_table(zfp_only, bps);
  EXPECT_TRUE(z.reference.empty());
  ASSERT_EQ(z.families.size(), 1u);
  std::ostringstream ztext;
  vp::print_equal_bps_table(ztext, z);
  EXPECT_EQ(ztext.str().find("(+"), std::string::npos) << ztext.str();
  EXPECT_NE(ztext.str().find("44.00\n"), std::string::npos) << ztext.str();
}
