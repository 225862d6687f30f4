// training.hpp: Algorithm 1 of MTV-Player (§3.1): dictionary refinement by weighted K-SVD over the
// coreset hierarchy, from the smallest level to the largest; or, for comparison, on the largest
// level only ("flat").
//
// Two continuation schedules are added to the paper's algorithm (both on by default, both the same
// in flat and hierarchical mode, so the comparison isolates the coreset hierarchy):
//  - Coarse-to-fine tolerance: stage s = 0..L (one stage per level; in flat mode, equal shares of
//    the iterations on the largest level) codes with ε_s = ε · F^((L−s)/L), F =
//    coarse_tolerance_factor, so the smallest coresets learn the dominant structure and the last
//    stage runs at ε itself.
//  - Sparsity ramp: iteration t (counted from 0 over the whole run) codes with at most
//    min(Smax, t + 1) atoms per block, so training starts as gain-shape vector quantization; the
//    last stage always codes with Smax.
// Error-constrained K-SVD started from data samples otherwise settles in poor local minima where
// blocks use many weak atoms: with Smax far above the true sparsity, the schedules recover many
// more planted atoms than plain K-SVD (docs/benchmarks.md has the figures, and the schedules'
// effect on turbulence; bench train, --coarse-tolerance 1 --no-sparsity-ramp to compare).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>

#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel::dictionary {

/// Algorithm 1's parameters.
struct TrainingOptions {
  int atom_count = 1024;       ///< K
  SparseCodingOptions coding;  ///< ε and Smax, the same as for encoding
  int iterations = 8;          ///< N: K-SVD iterations per coreset level
  /// Train on the largest coreset only, for comparison; then the iteration count is
  /// flat_iterations, or (0) N times the number of levels — the same number of iterations.
  bool flat = false;
  int flat_iterations = 0;
  double duplicate_threshold = 0.99;
  double coarse_tolerance_factor = 2;  ///< F ≥ 1: ε of the first stage over ε of the last (1: off)
  bool sparsity_ramp = true;           ///< limit atoms per block to t + 1 in iteration t
  /// Convergence: a stage ends before its N iterations when an iteration lowered the weighted
  /// objective by less than this fraction (0: always N). Hierarchical levels after the first
  /// start from a dictionary that already fits, so they converge in few iterations; flat mode
  /// applies the same test, in its last stage only (its earlier stages are the schedule's).
  double convergence = 0;
  std::uint64_t seed = 1;
};

/// Reported after every iteration; rates are estimates over all blocks of the training frames
/// (flat blocks included, which need no atoms and meet ε).
struct TrainingProgress {
  int level = 0, levels = 0;          ///< 1-based level in this run, and how many run
  int iteration = 0, iterations = 0;  ///< 1-based iteration within the level
  double tolerance = 0;               ///< ε this iteration coded with (the schedule's)
  int max_atoms = 0;                  ///< Smax this iteration coded with (the schedule's)
  std::size_t samples = 0;            ///< distinct blocks in the level
  std::size_t draws = 0;              ///< draws the level holds (C_l / M³)
  double rms_error = 0;               ///< sqrt(Σ w‖r‖² / (m · blocks)), data units
  double mean_sparsity = 0;           ///< atoms per block
  double fraction_met = 0;            ///< blocks that met ε
  int replaced_atoms = 0;
  double elapsed_seconds = 0;  ///< since training started
  bool final = false;          ///< the closing evaluation on the largest level
};
using TrainingCallback = std::function<void(const TrainingProgress&)>;

struct TrainingResult {
  Dictionary dictionary;
  TrainingProgress final_stats;  ///< the trained dictionary coded against the largest level
  double seconds = 0;            ///< training time (the coreset is built before)
  int total_iterations = 0;
};

/// Algorithm 1: D ← random samples of the first level used (random unit vectors where it has
/// fewer than K), then for every level from the smallest to the largest, N K-SVD iterations.
/// Throws InputError if the largest level is empty (every training block flat) or on bad options.
TrainingResult train_dictionary(const CoresetHierarchy& coresets, const TrainingOptions& options,
                                const TrainingCallback& callback = {});

/// ε for training on `coresets`: `tolerance` when given, else tolerance_for_psnr(psnr) over the
/// value range of the training frames. Throws InputError if the tolerance given is not positive,
/// or if none is given and the training frames are constant.
double training_tolerance(std::optional<double> tolerance, double psnr,
                          const CoresetHierarchy& coresets);

/// What the dictionary file records of its training (format::DictionaryTraining): ε, Smax, the
/// coreset's size and levels, seed and flat mode from the options; the value range and frame
/// count from the hierarchy; iterations, RMS error and atoms per block from the result.
format::DictionaryTraining training_provenance(const CoresetOptions& coreset,
                                               const TrainingOptions& training,
                                               const CoresetHierarchy& coresets,
                                               const TrainingResult& result);

}  // namespace volreel::dictionary
