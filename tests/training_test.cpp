// training_test.cpp: what surrounds Algorithm 1 (dictionary/training.hpp) — the ε training runs at
// (a tolerance given, or a PSNR over the training frames' range) and the provenance a dictionary
// file records, each field from the options, the hierarchy or the result.
#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "dictionary_test_data.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/dictionary/training.hpp"

namespace {

using namespace volreel;
using namespace volreel::dictionary;

CoresetHierarchy wavy_hierarchy(CoresetOptions& co) {
  co.coreset_voxels = 216 * 1500;
  co.levels = 2;
  co.seed = 7;
  return build_coreset_hierarchy(
      std::vector<Volume>{test::wavy_volume({36, 36, 24}, 3), test::wavy_volume({36, 36, 24}, 4)},
      co);
}

TEST(Training, ToleranceIsTheOneGivenElseThePsnrsOverTheTrainingRange) {
  CoresetOptions co;
  const CoresetHierarchy h = wavy_hierarchy(co);
  const double range = h.value_max - h.value_min;
  ASSERT_GT(range, 0);
  EXPECT_EQ(training_tolerance(0.03, default_training_psnr, h), 0.03);
  EXPECT_DOUBLE_EQ(training_tolerance(std::nullopt, default_training_psnr, h),
                   tolerance_for_psnr(default_training_psnr, range));
  EXPECT_DOUBLE_EQ(training_tolerance(std::nullopt, 40, h), tolerance_for_psnr(40, range));
  EXPECT_THROW(training_tolerance(0.0, 50, h), InputError);
  EXPECT_THROW(training_tolerance(-1.0, 50, h), InputError);
  CoresetHierarchy constant = h;
  constant.value_max = constant.value_min;
  EXPECT_THROW(training_tolerance(std::nullopt, 50, constant), InputError);
  EXPECT_EQ(training_tolerance(0.03, 50, constant), 0.03);  // a tolerance needs no range
}

TEST(Training, ProvenanceRecordsTheOptionsTheHierarchyAndTheResult) {
  CoresetOptions co;
  const CoresetHierarchy h = wavy_hierarchy(co);
  for (bool flat : {false, true}) {
    TrainingOptions to;
    to.atom_count = 24;
    to.coding = {.tolerance = 0.05, .max_atoms = 9};
    to.iterations = 2;
    to.flat = flat;
    to.seed = 11;
    const TrainingResult r = train_dictionary(h, to);
    const format::DictionaryTraining t = training_provenance(co, to, h, r);
    EXPECT_EQ(t.tolerance, 0.05);
    EXPECT_EQ(t.max_sparsity, 9u);
    EXPECT_EQ(t.coreset_voxels, co.coreset_voxels);
    EXPECT_EQ(t.coreset_levels, 2u);
    EXPECT_EQ(t.seed, 11u);
    EXPECT_EQ(t.flat, flat);
    EXPECT_EQ(t.value_min, h.value_min);
    EXPECT_EQ(t.value_max, h.value_max);
    EXPECT_EQ(t.training_frames, h.frames.size());
    EXPECT_EQ(t.iterations, static_cast<std::uint32_t>(r.total_iterations));
    EXPECT_EQ(t.rms_error, r.final_stats.rms_error);
    EXPECT_EQ(t.mean_sparsity, r.final_stats.mean_sparsity);
  }
}

}  // namespace
