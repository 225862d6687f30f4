// tolerance_test.cpp: choosing ε (encoder/tolerance.hpp) — the order of its sources, the ε a
// dictionary is trained at when an encode is given none, rate control to a size target — and the
// names and figures around an encode: rate rules, codecs, mean bits, the summary's derived figures.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>

#include "analytic_series.hpp"
#include "dictionary_test_data.hpp"
#include "test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel {
namespace {

/// A small series on disk (blobs, 40×36×30, 3 frames) and its reader.
class SmallSeries : public ::testing::Test {
 protected:
  void SetUp() override {
    series_ = test::analytic_series(dir_.path(), datasets::AnalyticField::blobs, 3, "blobs");
    std::tie(coding_.value_min, coding_.value_max) = encoder::value_range(*series_, 0);
  }
  double range() const { return coding_.value_max - coding_.value_min; }

  test::TempDir dir_{"tolerance"};
  std::unique_ptr<datasets::SeriesReader> series_;
  encoder::CodingSettings coding_;
};

TEST_F(SmallSeries, ToleranceComesFromTheFirstSourceGiven) {
  auto file = dictionary::to_file(test::random_dictionary(64, 3), format::DictionaryTraining{});
  encoder::ToleranceRequest request;
  // Nothing asked and no training ε in the dictionary: the encoding default PSNR.
  auto choice = encoder::choose_tolerance(*series_, file, 0, coding_, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::default_psnr);
  EXPECT_DOUBLE_EQ(choice.tolerance,
                   dictionary::tolerance_for_psnr(dictionary::default_encoding_psnr, range()));
  // The ε the dictionary was trained at comes before the default.
  file.training.tolerance = 0.0123;
  choice = encoder::choose_tolerance(*series_, file, 0, coding_, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::dictionary_training);
  EXPECT_EQ(choice.tolerance, 0.0123);
  // A PSNR, then a tolerance, come before the dictionary's.
  request.psnr = 40;
  choice = encoder::choose_tolerance(*series_, file, 0, coding_, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::psnr);
  EXPECT_DOUBLE_EQ(choice.tolerance, dictionary::tolerance_for_psnr(40, range()));
  request.tolerance = 0.005;
  choice = encoder::choose_tolerance(*series_, file, 0, coding_, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::tolerance);
  EXPECT_EQ(choice.tolerance, 0.005);
  // Fixed rate needs none.
  auto fixed = coding_;
  fixed.fixed_sparsity = 3;
  choice = encoder::choose_tolerance(*series_, file, 0, fixed, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::fixed_rate);
  EXPECT_EQ(choice.tolerance, 0);
}

TEST_F(SmallSeries, ABitsPerVoxelTargetIsMetByTheRateSearch) {
  const auto d = test::random_dictionary(64, 5);
  const auto file = dictionary::to_file(d, format::DictionaryTraining{});
  const std::uint64_t dictionary_bytes = format::dictionary_file_size(64, 216, false);
  encoder::ToleranceRequest request;
  request.bps = 6;
  const auto choice =
      encoder::choose_tolerance(*series_, file, dictionary_bytes, coding_, 3, request);
  EXPECT_EQ(choice.source, encoder::ToleranceSource::bps);
  EXPECT_EQ(choice.tolerance, choice.rate_search.tolerance);
  EXPECT_GT(choice.rate_search.iterations, 1);
  EXPECT_NEAR(choice.rate_search.estimated_bps, 6, 0.03 * 6);
  // The same search called directly finds the same ε.
  const auto direct =
      encoder::search_tolerance(*series_, d, dictionary_bytes, coding_, 6, 3, 3, 0.03);
  EXPECT_EQ(direct.tolerance, choice.tolerance);
  // Below what the dictionary and manifest alone take: refused, naming --bps.
  request.bps = 0.01;
  try {
    encoder::choose_tolerance(*series_, file, dictionary_bytes, coding_, 3, request);
    ADD_FAILURE() << "a target below the dictionary's own bits was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--bps"), std::string::npos) << e.what();
  }
}

// The rate search counts, at the ε it chose, the coded bricks of its sample's frames and those
// that kept the learned atoms: the figures of encodes of those frames at that ε.
TEST_F(SmallSeries, TheRateSearchCountsTheBricksThatKeptTheLearnedAtoms) {
  const auto d = dictionary::from_file(format::with_dct_atoms(dictionary::to_file(
      test::exemplar_dictionary(series_->read_frame(1), 48), format::DictionaryTraining{})));
  auto coding = coding_;
  coding.brick_size = 24;  // several bricks a frame
  const auto r = encoder::search_tolerance(*series_, d, 0, coding, 1.5, 3, 3, 0.03);
  coding.tolerance = r.tolerance;
  const encoder::FrameEncoder frames(&d, coding);
  std::size_t bricks = 0, split = 0;
  for (std::size_t t = 0; t < 3; ++t) {
    encoder::FrameStats stats;
    frames.encode(t, series_->read_frame(t), &stats);
    for (std::size_t n : stats.mean_bits_histogram) bricks += n;
    split += stats.split_bricks;
  }
  EXPECT_EQ(r.sample_frames, 3u);
  EXPECT_GT(bricks, 3u);
  EXPECT_EQ(r.sample_bricks, bricks);
  EXPECT_EQ(r.learned_bricks, bricks - split);
  EXPECT_GT(r.learned_bricks, 0u) << "the volume's own blocks pay in some bricks";
  EXPECT_LT(r.learned_bricks, bricks) << "and the basis alone in others";
}

// A sequence whose frames differ in cost: frames 0, 2 and 5 (the three evenly spaced samples of
// six) are a smooth field, frames 1, 3 and 4 white noise. The first sample misjudges the sequence
// by far; the check on the other frames finds it and searches again on all six, so that the
// estimate is the container's.
TEST(Tolerance, TheRateSearchChecksItsEpsilonOnOtherFrames) {
  test::TempDir dir("rate_check");
  datasets::AnalyticParams smooth, rough;
  smooth.field = datasets::AnalyticField::blobs;
  rough.field = datasets::AnalyticField::noise;
  smooth.dims = rough.dims = {36, 34, 30};
  smooth.frames = rough.frames = 6;
  {
    datasets::RawSeriesWriter w(dir / "series", smooth.dims, "mixed");
    std::vector<float> frame(smooth.dims.voxels());
    for (std::size_t t = 0; t < 6; ++t) {
      const bool noisy = t == 1 || t == 3 || t == 4;
      datasets::analytic_frame(noisy ? rough : smooth, t, frame);
      if (noisy)  // into the smooth frames' range, so that ε means the same in both
        for (float& v : frame) v = 0.5f + 0.1f * v;
      w.write_frame(t, static_cast<double>(t), frame);
    }
    w.finish();
  }
  const auto series = datasets::open_series(dir / "series");
  encoder::CodingSettings coding;
  std::tie(coding.value_min, coding.value_max) = encoder::value_range(*series, 0);
  const auto d = test::random_dictionary(64, 5);
  const std::uint64_t dictionary_bytes = format::dictionary_file_size(64, 216, false);
  const double target = 3;
  const auto r =
      encoder::search_tolerance(*series, d, dictionary_bytes, coding, target, 6, 3, 0.03);
  EXPECT_EQ(r.sample_frames, 6u);
  EXPECT_NEAR(r.estimated_bps, target, 0.03 * target);
  // The estimate is what the six frames cost at that ε, with the bytes besides them (here the
  // dictionary alone).
  coding.tolerance = r.tolerance;
  const encoder::FrameEncoder encoder(&d, coding);
  double bytes = 0, sampled = 0;
  for (std::size_t t = 0; t < 6; ++t) {
    const auto size = static_cast<double>(encoder.encode(t, series->read_frame(t)).size());
    bytes += size;
    if (t == 0 || t == 2 || t == 5) sampled += 2 * size;
  }
  const double voxels = 6.0 * static_cast<double>(series->info().dims.voxels());
  const double fixed = static_cast<double>(dictionary_bytes);
  EXPECT_LT(std::abs(8 * (bytes + fixed) / voxels - target), 0.05 * target);
  // The first sample alone would have been far off at that ε (several times the 3 % the search
  // aims at).
  EXPECT_GT(std::abs(sampled - bytes), 0.2 * bytes);
}

// solve_for_bps on rate curves of known shape: power laws steeper and flatter than the slope it
// starts from, a staircase, a wobbling curve, and curves that level off before the target (every
// block as fine as the format allows; means alone).
TEST(Tolerance, TheBpsSolverFindsTheTargetInFewTrialsOrStopsAtTheClosest) {
  const auto solve = [](const std::function<double(double)>& bps_at, double target) {
    double slope = encoder::default_rate_slope;
    return encoder::solve_for_bps(bps_at, target, 1e-3, 1e-9, 1, 0.03, slope);
  };
  int most_trials = 0;
  for (double exponent : {0.25, 0.35, 0.5, 1.0, 2.0})
    for (double target : {0.25, 0.5, 1.0, 2.0, 4.0, 8.0}) {
      // 1 bps at ε = 10^-2.5 (the start, 10^-3, is off by a factor 10^(0.5·exponent)).
      const auto power = [&](double eps) { return std::pow(eps / 3.16e-3, -exponent); };
      const auto r = solve(power, target);
      EXPECT_NEAR(r.bps, target, 0.03 * target) << "exponent " << exponent;
      EXPECT_DOUBLE_EQ(r.bps, power(r.tolerance));
      most_trials = std::max(most_trials, r.trials);
      // Steps of 1/20 bps, and ±2 % wobbles: not smooth, still found.
      const auto stairs = [&](double eps) { return std::ceil(20 * power(eps)) / 20; };
      EXPECT_NEAR(solve(stairs, target).bps, target, 0.03 * target + 0.05);
      const auto wobble = [&](double eps) {
        return power(eps) * (1 + 0.02 * std::sin(40 * std::log(eps)));
      };
      const auto w = solve(wobble, target);
      EXPECT_NEAR(w.bps, target, 0.03 * target) << "exponent " << exponent;
      EXPECT_LE(w.trials, 12);
    }
  // Geometric bisection from a bracket of 10^-4..10^-2 took 7 to 16 trials on the suite.
  EXPECT_LE(most_trials, 8);
  // A curve that levels off at 3.6 bps below ε = 3·10^-5: 4 bps is out of reach. The solver
  // stops at the closest, without creeping down the flat stretch.
  const auto ceiling = [](double eps) { return std::min(3.6, 0.02 * std::pow(eps, -0.5)); };
  auto r = solve(ceiling, 4);
  EXPECT_DOUBLE_EQ(r.bps, 3.6);
  EXPECT_DOUBLE_EQ(r.tolerance, 1e-9) << "out of reach: the finest end of the range";
  EXPECT_LE(r.trials, 12);
  // Means alone above ε = 0.01: 0.2 bps, so 0.1 is out of reach the other way.
  const auto floor = [](double eps) { return std::max(0.2, 0.02 * std::pow(eps, -0.5)); };
  r = solve(floor, 0.1);
  EXPECT_DOUBLE_EQ(r.bps, 0.2);
  EXPECT_DOUBLE_EQ(r.tolerance, 1);
  EXPECT_LE(r.trials, 8);
  // A rate that jumps across the target's window (2.2 to 1.8 bps at ε = 10^-3.5), or moves in
  // steps of 0.2 bps: the closest trial, once the bracket is narrow, without using every trial.
  const auto jump = [](double eps) { return eps < 3.16e-4 ? 2.2 : 1.8; };
  r = solve(jump, 2);
  EXPECT_NEAR(std::abs(r.bps - 2), 0.2, 1e-12);
  EXPECT_LE(r.trials, 16) << "of " << encoder::max_rate_trials;
  const auto steps = [](double eps) { return std::ceil(5 * 0.02 * std::pow(eps, -0.5)) / 5; };
  r = solve(steps, 1.1);
  EXPECT_NEAR(std::abs(r.bps - 1.1), 0.1, 1e-9);
  EXPECT_LE(r.trials, 16);
  // Nothing coded at all (0 bps) above ε = 10^-2.5: too few bits, and it goes finer; with the
  // target just below that edge, the bracket's coarse end is a trial of 0 bps and it bisects.
  const auto nothing = [](double eps) { return eps > 3.16e-3 ? 0.0 : 0.02 * std::pow(eps, -0.5); };
  double slope = encoder::default_rate_slope;
  r = encoder::solve_for_bps(nothing, 1.0, 0.5, 1e-9, 1, 0.03, slope);
  EXPECT_NEAR(r.bps, 1.0, 0.03);
  slope = encoder::default_rate_slope;
  r = encoder::solve_for_bps(nothing, 0.38, 0.5, 1e-9, 1, 0.03, slope);
  EXPECT_NEAR(r.bps, 0.38, 0.03 * 0.38);
  EXPECT_LE(r.trials, 12);
  // Short steps from a steep slope (carried from an earlier search) across a stretch 6 % above
  // the target: the trials measure from the first until one lands far enough away to see the
  // stretch is flat, then the search steps off it.
  const auto shelf = [](double eps) {
    return eps < 3e-2 ? 1.06 : 1.06 * std::pow(eps / 3e-2, -0.5);
  };
  slope = -1 / encoder::min_rate_slope;
  r = encoder::solve_for_bps(shelf, 1.0, 1.1e-3, 1e-9, 1, 0.03, slope);
  EXPECT_NEAR(r.bps, 1.0, 0.03);
  EXPECT_LE(r.trials, 20);
  // A NaN ends the search and is not returned.
  int calls = 0;
  const auto broken = [&](double eps) {
    return ++calls > 1 ? std::numeric_limits<double>::quiet_NaN() : 0.02 * std::pow(eps, -0.5);
  };
  r = solve(broken, 4);
  EXPECT_EQ(r.trials, 2);
  EXPECT_FALSE(std::isnan(r.bps));
  EXPECT_DOUBLE_EQ(r.tolerance, 1e-3);
  calls = 1;  // NaN from the first trial on: no ε at all
  r = solve(broken, 4);
  EXPECT_EQ(r.trials, 1);
  EXPECT_EQ(r.tolerance, 0);
  for (double bad : {0.0, -1.0, std::numeric_limits<double>::infinity(),
                     std::numeric_limits<double>::quiet_NaN()})
    EXPECT_THROW(solve(ceiling, bad), std::invalid_argument) << bad;
  // Starting on the flat stretch with the target reachable: it leaves the stretch.
  slope = encoder::default_rate_slope;
  r = encoder::solve_for_bps(floor, 1.0, 0.5, 1e-9, 1, 0.03, slope);
  EXPECT_NEAR(r.bps, 1.0, 0.03);
  EXPECT_LT(slope, -0.4) << "the slope measured on the curve is handed back";
}

// The manifest the rate search counts before anything is coded is, to within a few bytes a frame
// (the frames' sizes and checksums have other digits), the one encode_series writes.
TEST(Tolerance, TheManifestIsEstimatedAsItWillBeWritten) {
  test::TempDir dir("manifest-estimate");
  for (const std::size_t frames : {std::size_t{1}, std::size_t{5}}) {
    const auto series = test::analytic_series(dir / ("s" + std::to_string(frames)),
                                              datasets::AnalyticField::blobs, frames, "blobs");
    format::write_dictionary_file(dir / "dct.bin", format::dct_dictionary(6, "test"));
    encoder::EncodeJob job;
    std::tie(job.coding.value_min, job.coding.value_max) = encoder::value_range(*series, 0);
    job.coding.tolerance = 0.004;
    job.dictionary_file = dir / "dct.bin";
    job.max_keyframe_gap = 4;
    job.provenance = {{"program", "volreel test"}, {"arguments", "encode s --bps 1"}};
    const auto out = dir / ("c" + std::to_string(frames) + ".vreel");
    encoder::encode_series(*series, out, job);
    const auto written = static_cast<double>(std::filesystem::file_size(out / "manifest.json"));
    const auto estimate = static_cast<double>(
        encoder::estimated_manifest_bytes(series->info(), frames, job.coding, job.max_keyframe_gap,
                                          job.provenance, format::Container(out).atoms().count));
    EXPECT_NEAR(estimate, written, 16.0 * static_cast<double>(frames) + 16) << frames << " frames";
    // Series named alike (the Python module's spooled frames take the process's id): the same
    // estimate, whatever the CRC of the manifest's text, a decimal number of 1 to 10 digits.
    std::set<std::uint64_t> estimates;
    for (int variant = 0; variant < 40; ++variant) {
      datasets::SeriesInfo info = series->info();
      info.source = "raw series /tmp/.c.vreel.frames-" + std::to_string(10000 + variant) + "-0";
      estimates.insert(encoder::estimated_manifest_bytes(info, frames, job.coding,
                                                         job.max_keyframe_gap, job.provenance,
                                                         format::Container(out).atoms().count));
    }
    EXPECT_EQ(estimates.size(), 1u) << frames << " frames";
  }
}

TEST(Tolerance, ADictionaryIsTrainedAtTheToleranceOrPsnrAskedElseTheEncodingDefault) {
  encoder::ToleranceRequest request;
  EXPECT_DOUBLE_EQ(encoder::tolerance_to_train_at(request, 2.0),
                   dictionary::tolerance_for_psnr(dictionary::default_encoding_psnr, 2.0));
  request.bps = 0.4;  // the search needs a dictionary first: it is trained at the default
  EXPECT_DOUBLE_EQ(encoder::tolerance_to_train_at(request, 2.0),
                   dictionary::tolerance_for_psnr(dictionary::default_encoding_psnr, 2.0));
  request.bps.reset();
  request.psnr = 42;
  EXPECT_DOUBLE_EQ(encoder::tolerance_to_train_at(request, 2.0),
                   dictionary::tolerance_for_psnr(42, 2.0));
  request.tolerance = 0.07;
  EXPECT_EQ(encoder::tolerance_to_train_at(request, 2.0), 0.07);
}

TEST(CodingNames, RoundTripAndBadNamesNameTheirOption) {
  for (auto rule : {encoder::VariableRateRule::lagrangian, encoder::VariableRateRule::tolerance})
    EXPECT_EQ(encoder::rate_rule_from_name(encoder::rate_rule_name(rule)), rule);
  EXPECT_STREQ(encoder::rate_rule_name(encoder::VariableRateRule::lagrangian), "lagrangian");
  for (auto codec : {format::Codec::ksvd, format::Codec::zfp})
    EXPECT_EQ(encoder::codec_from_name(encoder::codec_name(codec)), codec);
  EXPECT_EQ(encoder::mean_bits_from_text("auto"), -1);
  EXPECT_EQ(encoder::mean_bits_from_text("0"), 0);
  EXPECT_EQ(encoder::mean_bits_from_text("12"), 12);
  const auto message = [](auto&& call) {
    try {
      call();
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message([] { encoder::rate_rule_from_name("rd"); }).find("--rate-rule"),
            std::string::npos);
  EXPECT_NE(message([] { encoder::codec_from_name("jpeg"); }).find("--codec"), std::string::npos);
  for (const char* bad : {"16", "-1", "7x", ""})
    EXPECT_NE(message([&] { encoder::mean_bits_from_text(bad); }).find("--mean-bits"),
              std::string::npos)
        << "'" << bad << "'";
}

TEST(EncodeSummary, DerivedFigures) {
  encoder::EncodeSummary s;
  EXPECT_EQ(s.quantization_loss_db(), 0);  // nothing sparse-coded
  s.unquantized_squared_error = 2;
  s.quantized_squared_error = 4;
  EXPECT_NEAR(s.quantization_loss_db(), 10 * std::log10(2.0), 1e-12);
  // The finest level's own codes in bps: only when every frame's bytes were counted.
  EXPECT_FALSE(s.finest_owned_codes_bps());
  s.container_bytes = 1000;
  s.bps = 0.5;
  s.breakdown.finest_owned_codes = 400;
  ASSERT_TRUE(s.finest_owned_codes_bps());
  EXPECT_DOUBLE_EQ(*s.finest_owned_codes_bps(), 0.2);
  s.skipped = 1;
  EXPECT_FALSE(s.finest_owned_codes_bps());
}

}  // namespace
}  // namespace volreel
