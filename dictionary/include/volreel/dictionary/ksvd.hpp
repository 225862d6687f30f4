// ksvd.hpp: weighted approximate K-SVD (Rubinstein, Zibulevsky, Elad 2008, "Approximate K-SVD";
// with sample weights as in MTV-Player §3.1). Algorithm 1 on top of it is in training.hpp.
//
// The objective is the paper's equation (1): Σ_i w_i ‖y_i − Dγ_i‖², γ_i from error-constrained
// batch-OMP (tolerance ε, see omp.hpp). One iteration:
//  1. Sparse coding of every sample with the current dictionary (batch-OMP).
//  2. For every atom k, in a random order: with I = the samples that use k, g = their
//     coefficients on k and E = the residuals of I with atom k's contribution added back,
//       d ← E·W·g / ‖E·W·g‖   (the weighted least-squares atom for fixed g, W = diag(w_I)),
//       g ← Eᵀ·d             (the best coefficients for that atom),
//     and the residuals of I become E − d·gᵀ. Each step can only lower Σ w‖r‖², so the
//     objective after step 2 is never above the one after step 1. Atoms stay zero-mean (E's
//     columns are zero-mean) and unit-norm.
//  3. Atoms no sample uses, and atoms within `duplicate_threshold` (|cos|) of an earlier atom, are
//     replaced by the (normalized) samples with the largest weighted error w_i‖r_i‖², as RZE08's
//     "cleardict" does.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"

namespace volreel::dictionary {

struct KsvdOptions {
  SparseCodingOptions coding;
  double duplicate_threshold = 0.99;  ///< |d_iᵀd_j| above which the later atom is replaced
  bool replace_atoms = true;          ///< step 3 on or off
};

/// Sparse coding statistics, weighted (Σ over samples of w_i times the quantity).
struct CodingStats {
  double objective = 0;       ///< Σ w‖y − Dγ‖²
  double weighted_atoms = 0;  ///< Σ w·(atoms used)
  double weighted_unmet = 0;  ///< Σ w over samples whose residual is above m·ε² (Smax reached)
  double weight_sum = 0;      ///< Σ w
};

struct KsvdIterationStats {
  CodingStats coded;             ///< after step 1, with the dictionary the iteration started from
  double objective_updated = 0;  ///< Σ w‖r‖² after step 2 (same supports), before step 3
  int unused_atoms = 0;
  int replaced_atoms = 0;  ///< unused + duplicates that were replaced
};

/// Sparse-codes samples (m × n) and measures the weighted statistics.
CodingStats measure_coding(const Eigen::MatrixXf& atoms, const Eigen::MatrixXf& samples,
                           std::span<const float> weights, const SparseCodingOptions& coding);

/// One weighted approximate K-SVD iteration (steps 1–3 above) on samples (m × n, zero-mean) with
/// positive weights; atoms (m × K) are updated in place. rng orders the atom updates.
KsvdIterationStats ksvd_iteration(Eigen::MatrixXf& atoms, const Eigen::MatrixXf& samples,
                                  std::span<const float> weights, const KsvdOptions& options,
                                  SplitMix64& rng);

}  // namespace volreel::dictionary
