// omp_test.cpp: batch-OMP recovers planted sparse codes exactly, agrees with a plain double
// precision OMP, and stops exactly when the residual meets ε or at Smax.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"

namespace {

using namespace volreel::dictionary;
using volreel::SplitMix64;

Eigen::MatrixXf random_dictionary(Eigen::Index m, Eigen::Index K, std::uint64_t seed) {
  SplitMix64 rng(seed);
  Eigen::MatrixXf D(m, K);
  for (Eigen::Index i = 0; i < D.size(); ++i) D.data()[i] = static_cast<float>(rng.normal());
  normalize_atoms(D);
  return D;
}

Eigen::MatrixXf random_signals(Eigen::Index m, Eigen::Index n, std::uint64_t seed) {
  SplitMix64 rng(seed);
  Eigen::MatrixXf Y(m, n);
  for (Eigen::Index i = 0; i < Y.size(); ++i) Y.data()[i] = static_cast<float>(rng.normal());
  for (Eigen::Index i = 0; i < n; ++i) Y.col(i).array() -= Y.col(i).mean();
  return Y;
}

double explicit_residual(const Eigen::MatrixXf& D, const Eigen::MatrixXf& Y, const SparseCodes& codes, std::size_t i) {
  Eigen::VectorXf approx(D.rows());
  reconstruct_block(D, codes, i, approx.data());
  return (Y.col(static_cast<Eigen::Index>(i)) - approx).cast<double>().squaredNorm();
}

TEST(BatchOmp, RecoversPlantedSupportAndCoefficients) {
  const Eigen::Index m = 216, K = 1024, n = 400;
  const int s = 4;
  const Eigen::MatrixXf D = random_dictionary(m, K, 1);
  SplitMix64 rng(2);
  Eigen::MatrixXf Y = Eigen::MatrixXf::Zero(m, n);
  std::vector<std::vector<std::pair<int, float>>> truth(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    std::set<int> support;
    while (static_cast<int>(support.size()) < s) support.insert(static_cast<int>(rng.below(K)));
    for (int k : support) {
      const float c = static_cast<float>((rng.uniform() < 0.5 ? -1 : 1) * rng.uniform(1.0, 2.0));
      Y.col(i) += c * D.col(k);
      truth[static_cast<std::size_t>(i)].emplace_back(k, c);
    }
  }
  // ε far below any coefficient's contribution (≥ 1), far above float rounding.
  BatchOmp omp(D, {.tolerance = 1e-3, .max_atoms = 15});
  SparseCodes codes;
  omp.encode(Y, codes);
  for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
    ASSERT_EQ(codes.count[i], s) << "block " << i;
    std::vector<std::pair<int, float>> found;
    for (int j = 0; j < s; ++j) found.emplace_back(codes.atoms_of(i)[j], codes.coefficients_of(i)[j]);
    std::sort(found.begin(), found.end());
    for (int j = 0; j < s; ++j) {
      ASSERT_EQ(found[static_cast<std::size_t>(j)].first, truth[i][static_cast<std::size_t>(j)].first) << "block " << i;
      EXPECT_NEAR(found[static_cast<std::size_t>(j)].second, truth[i][static_cast<std::size_t>(j)].second, 1e-4)
          << "block " << i;
    }
    EXPECT_LT(codes.residual_energy[i], 1e-5f * Y.col(static_cast<Eigen::Index>(i)).squaredNorm());  // float rounding
  }
}

TEST(BatchOmp, AgreesWithReferenceOmp) {
  const Eigen::Index m = 64, K = 200, n = 300;
  const Eigen::MatrixXf D = random_dictionary(m, K, 3);
  const Eigen::MatrixXf Y = random_signals(m, n, 4);
  const SparseCodingOptions options{.tolerance = 0.45, .max_atoms = 12};
  SparseCodes codes;
  BatchOmp(D, options).encode(Y, codes);
  int compared = 0;
  for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
    const ReferenceCode ref = reference_omp(D, Y.col(static_cast<Eigen::Index>(i)), options);
    // Only signals whose every greedy choice is clear-cut: float and double may break near-ties
    // differently, which says nothing about correctness.
    if (ref.min_selection_margin < 1e-3) continue;
    ++compared;
    ASSERT_EQ(codes.count[i], ref.atoms.size()) << "block " << i;
    for (std::size_t j = 0; j < ref.atoms.size(); ++j) {
      ASSERT_EQ(codes.atoms_of(i)[j], ref.atoms[j]) << "block " << i << " step " << j;
      EXPECT_NEAR(codes.coefficients_of(i)[j], ref.coefficients[j], 1e-4 * (1 + std::abs(ref.coefficients[j])));
    }
    EXPECT_NEAR(codes.residual_energy[i], ref.residual_energy, 1e-4 * static_cast<double>(Y.col(static_cast<Eigen::Index>(i)).squaredNorm()));
  }
  EXPECT_GT(compared, n * 8 / 10);
}

TEST(BatchOmp, StopsAtToleranceWithTheFewestAtoms) {
  const Eigen::Index m = 216, K = 512, n = 300;
  const Eigen::MatrixXf D = random_dictionary(m, K, 5);
  const Eigen::MatrixXf Y = random_signals(m, n, 6);  // RMS ≈ 1 per value
  // Residual after s greedy steps, for every s: ε = 0 runs with Smax = s follow the same path.
  std::vector<SparseCodes> prefix(16);
  for (int s = 1; s <= 15; ++s) BatchOmp(D, {.tolerance = 0, .max_atoms = s}).encode(Y, prefix[static_cast<std::size_t>(s)]);
  for (double tolerance : {0.95, 0.9, 0.85}) {
    const SparseCodingOptions options{.tolerance = tolerance, .max_atoms = 15};
    SparseCodes codes;
    BatchOmp(D, options).encode(Y, codes);
    const double target = static_cast<double>(m) * tolerance * tolerance;
    int stopped_early = 0;
    for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
      const double residual = explicit_residual(D, Y, codes, i);
      EXPECT_NEAR(codes.residual_energy[i], residual, 1e-4 * target) << "block " << i;
      const int c = codes.count[i];
      if (c < options.max_atoms) {
        ++stopped_early;
        EXPECT_LE(residual, target * (1 + 1e-5)) << "block " << i;
      }
      // One atom fewer would not have met ε: OMP stopped at the first step that did.
      const double before = c > 1 ? static_cast<double>(prefix[static_cast<std::size_t>(c - 1)].residual_energy[i])
                                  : static_cast<double>(Y.col(static_cast<Eigen::Index>(i)).squaredNorm());
      if (c >= 1) {
        EXPECT_GT(before, target * (1 - 1e-5)) << "block " << i << " used " << c << " atoms";
      }
    }
    EXPECT_GT(stopped_early, 0) << "tolerance " << tolerance;
  }
}

TEST(BatchOmp, StopsAtMaxAtoms) {
  const Eigen::Index m = 64, K = 256, n = 100;
  const Eigen::MatrixXf D = random_dictionary(m, K, 7);
  const Eigen::MatrixXf Y = random_signals(m, n, 8);
  for (int smax : {1, 5, 15}) {
    SparseCodes codes;
    BatchOmp(D, {.tolerance = 0, .max_atoms = smax}).encode(Y, codes);
    for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
      ASSERT_EQ(codes.count[i], smax);
      std::set<int> distinct(codes.atoms_of(i), codes.atoms_of(i) + smax);
      EXPECT_EQ(static_cast<int>(distinct.size()), smax);
    }
  }
}

TEST(BatchOmp, ZeroBlocksNeedNoAtomsAndBadOptionsAreRefused) {
  const Eigen::MatrixXf D = random_dictionary(27, 40, 9);
  SparseCodes codes;
  BatchOmp(D, {.tolerance = 0, .max_atoms = 5}).encode(Eigen::MatrixXf::Zero(27, 3), codes);
  for (std::size_t i = 0; i < 3; ++i) EXPECT_EQ(codes.count[i], 0);
  EXPECT_THROW(BatchOmp(D, {.tolerance = -1, .max_atoms = 5}), std::invalid_argument);
  EXPECT_THROW(BatchOmp(D, {.tolerance = 0, .max_atoms = 0}), std::invalid_argument);
  EXPECT_THROW(BatchOmp(D, {.tolerance = 0, .max_atoms = 28}), std::invalid_argument);
}

TEST(BatchOmp, ToleranceAndPsnr) {
  EXPECT_NEAR(tolerance_for_psnr(60, 2.0), 2e-3, 1e-12);
  EXPECT_NEAR(psnr_for_tolerance(2e-3, 2.0), 60, 1e-9);
}

}  // namespace
