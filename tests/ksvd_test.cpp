// ksvd_test.cpp: weighted approximate K-SVD never raises its objective in the update step, treats
// a weight of w like w copies of a sample, keeps atoms zero-mean and unit-norm, and Algorithm 1
// recovers a planted dictionary from volumes made of it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "dictionary_test_data.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/ksvd.hpp"
#include "volreel/dictionary/training.hpp"

namespace {

using namespace volreel;
using namespace volreel::dictionary;

/// n samples of m values, each a sparse combination of `sparsity` planted atoms plus noise.
Eigen::MatrixXf planted_samples(const Eigen::MatrixXf& D, Eigen::Index n, int sparsity,
                                double noise, std::uint64_t seed) {
  SplitMix64 rng(seed);
  Eigen::MatrixXf Y = Eigen::MatrixXf::Zero(D.rows(), n);
  for (Eigen::Index i = 0; i < n; ++i) {
    for (int s = 0; s < sparsity; ++s)
      Y.col(i) += static_cast<float>(rng.uniform(-3, 3)) *
                  D.col(static_cast<Eigen::Index>(rng.below(static_cast<std::uint64_t>(D.cols()))));
    for (Eigen::Index r = 0; r < D.rows(); ++r) Y(r, i) += static_cast<float>(noise * rng.normal());
    Y.col(i).array() -= Y.col(i).mean();
  }
  return Y;
}

/// How many planted atoms have a learned atom within `max_angle_deg` (sign ignored).
int recovered_atoms(const Eigen::MatrixXf& planted, const Eigen::MatrixXf& learned,
                    double max_angle_deg) {
  const Eigen::MatrixXf cosines = (planted.transpose() * learned).cwiseAbs();
  const double threshold = std::cos(max_angle_deg * 3.14159265358979 / 180);
  int found = 0;
  for (Eigen::Index k = 0; k < planted.cols(); ++k)
    if (static_cast<double>(cosines.row(k).maxCoeff()) > threshold) ++found;
  return found;
}

TEST(Ksvd, UpdateNeverRaisesTheWeightedObjective) {
  const Eigen::MatrixXf planted = test::planted_atoms(64, 48, 1);
  const Eigen::MatrixXf Y = planted_samples(planted, 1500, 3, 0.05, 2);
  SplitMix64 rng(3);
  std::vector<float> weights(static_cast<std::size_t>(Y.cols()));
  for (float& w : weights) w = static_cast<float>(rng.uniform(0.2, 5.0));
  Eigen::MatrixXf atoms = test::planted_atoms(64, 48, 99);  // unrelated start
  KsvdOptions options;
  options.coding = {.tolerance = 0.08, .max_atoms = 8};
  std::vector<double> objectives;
  for (int it = 0; it < 15; ++it) {
    const KsvdIterationStats s = ksvd_iteration(atoms, Y, weights, options, rng);
    EXPECT_LE(s.objective_updated, s.coded.objective * (1 + 1e-5)) << "iteration " << it;
    objectives.push_back(s.coded.objective);
    for (Eigen::Index k = 0; k < atoms.cols(); ++k) {
      ASSERT_NEAR(atoms.col(k).norm(), 1.0f, 1e-4f) << "atom " << k;
      ASSERT_NEAR(atoms.col(k).mean(), 0.0f, 1e-5f) << "atom " << k;
    }
  }
  // Over the iterations the coded objective falls a long way (sparse coding is greedy, so single
  // iterations may tick up slightly after atoms are replaced).
  EXPECT_LT(objectives.back(), 0.2 * objectives.front());
  for (std::size_t i = 1; i < objectives.size(); ++i)
    EXPECT_LT(objectives[i], objectives[i - 1] * 1.1) << i;
}

TEST(Ksvd, FixedSparsityObjectiveDecreasesMonotonically) {
  // With ε = 0 every sample uses exactly Smax atoms, so OMP's supports only change when it finds
  // better ones; without atom replacement the objective must fall at every step (within rounding).
  const Eigen::MatrixXf planted = test::planted_atoms(27, 30, 4);
  const Eigen::MatrixXf Y = planted_samples(planted, 800, 2, 0.02, 5);
  const std::vector<float> weights(static_cast<std::size_t>(Y.cols()), 1.0f);
  Eigen::MatrixXf atoms = test::planted_atoms(27, 30, 6);
  KsvdOptions options;
  options.coding = {.tolerance = 0, .max_atoms = 2};
  options.replace_atoms = false;
  SplitMix64 rng(7);
  double previous = std::numeric_limits<double>::infinity();
  int increases = 0;
  for (int it = 0; it < 10; ++it) {
    const KsvdIterationStats s = ksvd_iteration(atoms, Y, weights, options, rng);
    EXPECT_LE(s.objective_updated, s.coded.objective * (1 + 1e-5));
    if (s.coded.objective > previous * (1 + 1e-3)) ++increases;
    previous = s.objective_updated;
  }
  EXPECT_LE(increases, 1);
}

TEST(Ksvd, IntegerWeightsEqualRepeatedSamples) {
  const Eigen::MatrixXf planted = test::planted_atoms(27, 20, 8);
  const Eigen::MatrixXf Y = planted_samples(planted, 200, 2, 0.05, 9);
  SplitMix64 wrng(10);
  std::vector<float> weights(static_cast<std::size_t>(Y.cols()));
  Eigen::Index expanded_count = 0;
  for (float& w : weights) {
    w = static_cast<float>(1 + wrng.below(3));
    expanded_count += static_cast<Eigen::Index>(w);
  }
  Eigen::MatrixXf expanded(Y.rows(), expanded_count);
  Eigen::Index at = 0;
  for (Eigen::Index i = 0; i < Y.cols(); ++i)
    for (int c = 0; c < static_cast<int>(weights[static_cast<std::size_t>(i)]); ++c)
      expanded.col(at++) = Y.col(i);
  const std::vector<float> ones(static_cast<std::size_t>(expanded_count), 1.0f);

  KsvdOptions options;
  options.coding = {.tolerance = 0.1, .max_atoms = 4};
  options.replace_atoms = false;
  Eigen::MatrixXf a = test::planted_atoms(27, 20, 11), b = a;
  SplitMix64 rng_a(12), rng_b(12);
  for (int it = 0; it < 3; ++it) {
    const auto sa = ksvd_iteration(a, Y, weights, options, rng_a);
    const auto sb = ksvd_iteration(b, expanded, ones, options, rng_b);
    EXPECT_NEAR(sa.coded.objective, sb.coded.objective, 1e-4 * sb.coded.objective);
    EXPECT_NEAR(sa.objective_updated, sb.objective_updated, 1e-4 * sb.objective_updated);
  }
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-3f);
  // Without the weights the result differs: the test can tell weighted from unweighted.
  Eigen::MatrixXf c = test::planted_atoms(27, 20, 11);
  SplitMix64 rng_c(12);
  const std::vector<float> unit(weights.size(), 1.0f);
  for (int it = 0; it < 3; ++it) ksvd_iteration(c, Y, unit, options, rng_c);
  EXPECT_GT((a - c).cwiseAbs().maxCoeff(), 1e-2f);
}

TEST(Ksvd, ReplacesUnusedAndDuplicateAtoms) {
  const Eigen::MatrixXf planted = test::planted_atoms(27, 20, 13);
  const Eigen::MatrixXf Y = planted_samples(planted, 400, 2, 0.05, 14);
  const std::vector<float> weights(static_cast<std::size_t>(Y.cols()), 1.0f);
  Eigen::MatrixXf atoms = test::planted_atoms(27, 20, 15);
  atoms.col(5) = atoms.col(3);  // a duplicate
  SplitMix64 rng(16);
  KsvdOptions options;
  options.coding = {.tolerance = 0.05, .max_atoms = 6};
  const KsvdIterationStats s = ksvd_iteration(atoms, Y, weights, options, rng);
  EXPECT_GE(s.replaced_atoms, 1);
  const Eigen::MatrixXf gram = atoms.transpose() * atoms;
  for (Eigen::Index i = 0; i < gram.rows(); ++i)
    for (Eigen::Index j = 0; j < i; ++j)
      EXPECT_LT(std::abs(gram(i, j)), 0.99f + 1e-4f) << i << "," << j;
}

class PlantedDictionary : public ::testing::TestWithParam<bool> {};

TEST_P(PlantedDictionary, TrainingRecoversMostAtoms) {
  // Volumes whose 4³ blocks are 3-sparse in 48 planted atoms plus noise of 0.02 per value (the
  // signal is about 0.4 per value), trained at ε just above the noise with Smax = 4. Over seeds
  // 1–8 this recovers 39–46 of the 48 atoms within 5 degrees, but K-SVD can land in a poor local
  // minimum (34 seen), so the test takes the median of three seeds. (With Smax far above the
  // true sparsity, error-constrained K-SVD settles for denser codes and finds about 30: see
  // training.hpp.)
  const int M = 4;
  const Eigen::MatrixXf planted = test::planted_atoms(64, 48, 21);
  std::vector<Volume> volumes;
  for (int t = 0; t < 2; ++t)
    volumes.push_back(test::planted_volume({64, 64, 64}, M, planted, 3, 0.02,
                                           30 + static_cast<std::uint64_t>(t)));
  CoresetOptions co;
  co.block_size = M;
  co.coreset_voxels = 6144 * 64;
  co.levels = 3;
  co.seed = 22;
  const CoresetHierarchy h = build_coreset_hierarchy(volumes, co);
  TrainingOptions to;
  to.atom_count = 48;
  to.coding = {.tolerance = 0.025, .max_atoms = 4};
  to.iterations = 10;
  to.flat = GetParam();
  std::vector<int> found;
  std::vector<TrainingProgress> reports;
  for (std::uint64_t seed : {23u, 24u, 25u}) {
    to.seed = seed;
    reports.clear();
    const TrainingResult r =
        train_dictionary(h, to, [&](const TrainingProgress& p) { reports.push_back(p); });
    found.push_back(recovered_atoms(planted, r.dictionary.atoms, 5.0));
    EXPECT_GE(found.back(), 24) << "seed " << seed << ": under half of the planted atoms";
    EXPECT_LT(r.final_stats.mean_sparsity, 4.0) << "seed " << seed;
  }
  std::sort(found.begin(), found.end());
  EXPECT_GE(found[1], 36) << "median of 3 seeds: planted atoms found within 5 degrees, of 48";
  // A random dictionary is nowhere near: the angle test can fail.
  EXPECT_LE(recovered_atoms(planted, test::planted_atoms(64, 48, 99), 5.0), 1);
  // Progress: one report per iteration (flat: 4 × 10 on the largest level, the same count as
  // 4 levels × 10), levels from small to large, the schedule ending at ε and Smax, then the final.
  ASSERT_EQ(reports.size(), 4u * 10u + 1u);
  for (std::size_t i = 1; i + 1 < reports.size(); ++i)
    EXPECT_GE(reports[i].samples, reports[i - 1].samples);
  EXPECT_EQ(reports.front().max_atoms, 1);
  EXPECT_NEAR(reports.front().tolerance, 0.05, 1e-12);  // coarse_tolerance_factor 2
  EXPECT_EQ(reports[reports.size() - 2].max_atoms, 4);
  EXPECT_NEAR(reports[reports.size() - 2].tolerance, 0.025, 1e-12);
  EXPECT_TRUE(reports.back().final);
}

TEST(Training, ConvergenceEndsALevelWhenTheObjectiveStopsFalling) {
  // The same planted data; each level stops at the first iteration whose coding step (at the
  // same ε and Smax as the one before) shows the previous update gained under 2 %.
  const int M = 4;
  const Eigen::MatrixXf planted = test::planted_atoms(64, 48, 21);
  std::vector<Volume> volumes{test::planted_volume({64, 64, 64}, M, planted, 3, 0.02, 30)};
  CoresetOptions co;
  co.block_size = M;
  co.coreset_voxels = 6144 * 64;
  co.levels = 3;
  co.seed = 22;
  const CoresetHierarchy h = build_coreset_hierarchy(volumes, co);
  TrainingOptions to;
  to.atom_count = 48;
  to.coding = {.tolerance = 0.025, .max_atoms = 4};
  to.iterations = 10;
  to.seed = 23;
  to.convergence = 0.02;
  std::vector<TrainingProgress> reports;
  const TrainingResult r =
      train_dictionary(h, to, [&](const TrainingProgress& p) { reports.push_back(p); });
  ASSERT_FALSE(reports.empty());
  reports.pop_back();  // the final evaluation
  EXPECT_LT(r.total_iterations, 4 * 10) << "no level converged early";
  EXPECT_EQ(static_cast<std::size_t>(r.total_iterations), reports.size());
  const auto objective = [](const TrainingProgress& p) { return p.rms_error * p.rms_error; };
  for (std::size_t i = 0; i < reports.size(); ++i) {
    const bool last_of_level = i + 1 == reports.size() || reports[i + 1].level != reports[i].level;
    const bool comparable = i > 0 && reports[i - 1].level == reports[i].level &&
                            reports[i - 1].max_atoms == reports[i].max_atoms;
    if (!comparable) {
      EXPECT_TRUE(!last_of_level || reports[i].iteration == reports[i].iterations)
          << "level " << reports[i].level << " ended without a comparable pair of iterations";
      continue;
    }
    const double gain =
        (objective(reports[i - 1]) - objective(reports[i])) / objective(reports[i - 1]);
    if (last_of_level && reports[i].iteration < reports[i].iterations) {
      EXPECT_LT(gain, to.convergence)
          << "level " << reports[i].level << " ended while still improving";
    } else if (!last_of_level) {
      EXPECT_GE(gain, to.convergence)
          << "level " << reports[i].level << " went on after converging";
    }
  }
  EXPECT_GE(recovered_atoms(planted, r.dictionary.atoms, 5.0), 24);
}

INSTANTIATE_TEST_SUITE_P(HierarchicalAndFlat, PlantedDictionary, ::testing::Values(false, true),
                         [](const auto& test_info) {
                           return test_info.param ? "Flat" : "Hierarchical";
                         });

}  // namespace
