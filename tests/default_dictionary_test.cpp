// default_dictionary_test.cpp: the dictionary an encode trains when it is given none
// (encoder/default_dictionary.hpp) — K chosen by the estimated container size, each K reported,
// the provenance of the one kept — on a tiny generated series.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <tuple>
#include <vector>

#include "analytic_series.hpp"
#include "test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/encoder.hpp"

namespace volreel {
namespace {

class DefaultDictionary : public ::testing::Test {
 protected:
  void SetUp() override {
    series_ = test::analytic_series(dir_.path(), datasets::AnalyticField::blobs, 3, "blobs");
    options_.coding.value_min = 0;
    options_.coding.value_max = 1.5;
    options_.tolerance = 0.01;
    options_.candidate_atoms = {64, 32};
    options_.sample_frames = 2;
    options_.coreset.coreset_voxels = 216 * 2000;
    options_.coreset.levels = 2;
  }

  test::TempDir dir_{"default-dictionary"};
  std::unique_ptr<datasets::SeriesReader> series_;
  encoder::DefaultDictionaryOptions options_;
};

TEST_F(DefaultDictionary, KeepsTheSizeThatGivesTheSmallestContainer) {
  std::vector<encoder::DictionaryCandidate> reported;
  const auto chosen = encoder::train_default_dictionary(
      *series_, options_, {},
      [&](const encoder::DictionaryCandidate& c) { reported.push_back(c); });
  ASSERT_EQ(chosen.candidates.size(), 2u);
  ASSERT_EQ(reported.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) {
    const auto& c = chosen.candidates[i];
    EXPECT_EQ(c.atoms, options_.candidate_atoms[i]);
    EXPECT_EQ(reported[i].atoms, c.atoms);
    EXPECT_EQ(reported[i].estimated_bytes, c.estimated_bytes);
    // Atoms stored in binary16, as the container stores them, and the frames' bytes on top.
    EXPECT_EQ(c.dictionary_bytes, static_cast<double>(format::dictionary_file_size(
                                      static_cast<std::uint64_t>(c.atoms), 216, true)));
    EXPECT_GT(c.estimated_bytes, c.dictionary_bytes);
  }
  const auto best = std::min_element(
      chosen.candidates.begin(), chosen.candidates.end(),
      [](const auto& a, const auto& b) { return a.estimated_bytes < b.estimated_bytes; });
  EXPECT_EQ(chosen.dictionary.atom_count(), best->atoms);
  EXPECT_EQ(chosen.dictionary.block_length(), 216);
  // The provenance records how it was trained.
  EXPECT_EQ(chosen.training.tolerance, options_.tolerance);
  EXPECT_EQ(chosen.training.coreset_voxels, options_.coreset.coreset_voxels);
  EXPECT_EQ(chosen.training.coreset_levels, 2u);
  EXPECT_EQ(chosen.training.training_frames, 3u);
  EXPECT_GT(chosen.training.iterations, 0u);
  EXPECT_FALSE(chosen.training.flat);
  // The dictionary codes the series' frames: a frame encoder accepts it.
  auto coding = options_.coding;
  coding.tolerance = options_.tolerance;
  EXPECT_GT(
      encoder::FrameEncoder(&chosen.dictionary, coding).encode(0, series_->read_frame(0)).size(),
      0u);
}

TEST_F(DefaultDictionary, TheDctBasisAloneIsACandidate) {
  options_.candidate_atoms = {32, 0};
  const auto chosen = encoder::train_default_dictionary(*series_, options_);
  ASSERT_EQ(chosen.candidates.size(), 2u);
  const auto& dct = chosen.candidates[1];
  EXPECT_EQ(dct.atoms, 0);
  EXPECT_EQ(dct.dictionary_bytes, static_cast<double>(format::dictionary_file_size(0, 216)));
  EXPECT_GT(dct.estimated_bytes, dct.dictionary_bytes);
  const bool dct_smaller = dct.estimated_bytes < chosen.candidates[0].estimated_bytes;
  EXPECT_EQ(chosen.dct_only, dct_smaller);
  EXPECT_EQ(chosen.dictionary.atom_count(), dct_smaller ? 0 : 32);
}

TEST_F(DefaultDictionary, ASizeWhoseDictionaryAloneCannotWinIsNotTrained) {
  // By default the DCT basis comes first, then the learned sizes from the smallest: each estimate
  // can rule out the larger dictionaries after it.
  EXPECT_EQ(encoder::DefaultDictionaryOptions{}.candidate_atoms,
            (std::vector<int>{0, 128, 256, 512, 1024}));
  // The DCT basis first: its estimate (tens of kB for this series at this ε) is far below the
  // dictionary file of 2048 atoms (over 800 kB), which is then not trained; 16 atoms still are.
  options_.tolerance = 0.0005;
  options_.candidate_atoms = {0, 2048, 16};
  std::vector<encoder::DictionaryCandidate> reported;
  const auto chosen = encoder::train_default_dictionary(
      *series_, options_, {},
      [&](const encoder::DictionaryCandidate& c) { reported.push_back(c); });
  ASSERT_EQ(chosen.candidates.size(), 3u);
  ASSERT_EQ(reported.size(), 3u);
  const auto& dct = chosen.candidates[0];
  const auto& large = chosen.candidates[1];
  const auto& small = chosen.candidates[2];
  EXPECT_FALSE(dct.skipped);
  EXPECT_TRUE(large.skipped);
  EXPECT_TRUE(reported[1].skipped);
  EXPECT_EQ(large.atoms, 2048);
  EXPECT_EQ(large.best_bytes, dct.estimated_bytes);
  EXPECT_GE(large.dictionary_bytes, large.best_bytes);
  EXPECT_EQ(large.estimated_bytes, 0);
  EXPECT_EQ(large.train_seconds, 0);
  EXPECT_FALSE(small.skipped) << "the DCT basis's estimate " << dct.estimated_bytes;  // 16: 7 kB
  EXPECT_GT(small.estimated_bytes, small.dictionary_bytes);
  EXPECT_NE(chosen.dictionary.atom_count(), 2048);
}

// A noise field, which no learned atom codes much better than the basis: each larger dictionary
// adds more bytes than it saves, and after two rising estimates in a row the next sizes are not
// trained.
TEST(DefaultDictionarySizes, SizesAfterTwoRisingEstimatesAreNotTrained) {
  test::TempDir dir("default-dictionary-noise");
  const auto series =
      test::analytic_series(dir.path(), datasets::AnalyticField::noise, 2, "noise", {36, 36, 36});
  encoder::DefaultDictionaryOptions options;
  std::tie(options.coding.value_min, options.coding.value_max) = encoder::value_range(*series, 0);
  options.tolerance = 0.001 * (options.coding.value_max - options.coding.value_min);
  options.candidate_atoms = {0, 16, 24, 32, 40};  // dictionaries far smaller than the frames
  options.sample_frames = 2;
  options.coreset.coreset_voxels = 216 * 2000;
  options.coreset.levels = 2;
  std::vector<encoder::DictionaryCandidate> reported;
  const auto chosen = encoder::train_default_dictionary(
      *series, options, {}, [&](const encoder::DictionaryCandidate& c) { reported.push_back(c); });
  ASSERT_EQ(chosen.candidates.size(), 5u);
  ASSERT_EQ(reported.size(), 5u);
  const auto& c = chosen.candidates;
  // The premise: the estimate rises from the basis to 16 atoms and from 16 to 24.
  ASSERT_FALSE(c[1].skipped || c[2].skipped);
  ASSERT_GT(c[1].estimated_bytes, c[0].estimated_bytes);
  ASSERT_GT(c[2].estimated_bytes, c[1].estimated_bytes);
  for (std::size_t i = 3; i < 5; ++i) {
    EXPECT_TRUE(c[i].skipped) << c[i].atoms;
    EXPECT_TRUE(c[i].past_minimum) << c[i].atoms;
    EXPECT_TRUE(reported[i].past_minimum) << c[i].atoms;
    EXPECT_EQ(c[i].best_bytes, c[0].estimated_bytes);
    EXPECT_EQ(c[i].estimated_bytes, 0);
    EXPECT_LT(c[i].dictionary_bytes, c[i].best_bytes) << "not ruled out by its size";
  }
  EXPECT_TRUE(chosen.dct_only);
  // One rise is not enough: with 16 atoms alone before them, 32 and 40 are trained.
  options.candidate_atoms = {0, 16, 32, 40};
  const auto again = encoder::train_default_dictionary(*series, options);
  ASSERT_EQ(again.candidates.size(), 4u);
  EXPECT_FALSE(again.candidates[2].skipped);
}

TEST_F(DefaultDictionary, AGivenSizeIsTrainedWithoutEstimates) {
  options_.atoms = 32;
  const auto chosen = encoder::train_default_dictionary(*series_, options_);
  ASSERT_EQ(chosen.candidates.size(), 1u);
  EXPECT_EQ(chosen.candidates[0].atoms, 32);
  EXPECT_EQ(chosen.candidates[0].estimated_bytes, 0);
  EXPECT_EQ(chosen.dictionary.atom_count(), 32);
}

TEST_F(DefaultDictionary, ChoosingNeedsACandidateAndASampleFrame) {
  options_.candidate_atoms.clear();
  EXPECT_THROW(encoder::train_default_dictionary(*series_, options_), InputError);
  options_.candidate_atoms = {32};
  options_.sample_frames = 0;
  EXPECT_THROW(encoder::train_default_dictionary(*series_, options_), InputError);
}

}  // namespace
}  // namespace volreel
