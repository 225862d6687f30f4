// training.cpp: Algorithm 1 of MTV-Player (§3.1) — K-SVD refinement over the coreset hierarchy —
// the tolerance it trains at, and the provenance a dictionary file records of it.
#include "volreel/dictionary/training.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <string>

#include <omp.h>

#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/ksvd.hpp"
#include "volreel/format/memory.hpp"

namespace volreel::dictionary {

namespace {

/// Initial dictionary: distinct random samples of `first` (normalized), random Gaussian unit
/// vectors (zero-mean) for the atoms beyond its size. The paper's D ← [1, random, …, random]
/// starts with a constant atom; volreel's blocks are zero-mean (the mean is coded apart), so a
/// constant atom would never be used and is left out.
Eigen::MatrixXf initial_atoms(const Coreset& first, int m, int K, SplitMix64& rng) {
  Eigen::MatrixXf atoms(m, K);
  std::vector<std::size_t> pick(static_cast<std::size_t>(first.blocks.cols()));
  std::iota(pick.begin(), pick.end(), std::size_t{0});
  const std::size_t from_samples = std::min(pick.size(), static_cast<std::size_t>(K));
  for (std::size_t i = 0; i < from_samples; ++i)
    std::swap(pick[i], pick[i + rng.below(pick.size() - i)]);
  for (Eigen::Index k = 0; k < K; ++k) {
    if (static_cast<std::size_t>(k) < from_samples)
      atoms.col(k) = first.blocks.col(static_cast<Eigen::Index>(pick[static_cast<std::size_t>(k)]));
    else
      for (Eigen::Index r = 0; r < m; ++r) atoms(r, k) = static_cast<float>(rng.normal());
  }
  normalize_atoms(atoms);
  return atoms;
}

}  // namespace

TrainingResult train_dictionary(const CoresetHierarchy& coresets, const TrainingOptions& options,
                                const TrainingCallback& callback) {
  if (coresets.levels.empty() || coresets.largest().blocks.cols() == 0)
    throw InputError(
        "every block of the training frames is flat (constant): there is nothing to learn a "
        "dictionary from");
  if (options.atom_count < 1 || options.atom_count > 65536)
    throw InputError("atom count " + std::to_string(options.atom_count) + " is outside 1..65536");
  if (options.iterations < 1) throw InputError("iterations per level must be at least 1");
  {
    // What training holds besides the coresets' blocks: the K x K Gram matrix, the K
    // correlations of a batch of 256 blocks on each thread, and the residual of the largest
    // coreset (floats). Refused up front where that alone passes half the memory the process may
    // use (the pursuit's and the update's working sets come on top).
    const double k = options.atom_count;
    const double n = static_cast<double>(coresets.largest().blocks.cols());
    const double need = 4.0 * (k * k + k * 256.0 * omp_get_max_threads() +
                               static_cast<double>(coresets.largest().blocks.rows()) * n);
    const auto memory = static_cast<double>(format::detail::usable_memory_bytes());
    if (memory > 0 && need > memory / 2) {
      char text[384];
      std::snprintf(text, sizeof text,
                    "K = %d atoms: training needs about %.1f GB besides the training blocks (a K "
                    "x K Gram matrix, correlations and the residual of %.0f blocks), more than "
                    "half of the %.1f GB this process may use (the machine's memory or its "
                    "container's limit): choose fewer atoms or a smaller --coreset",
                    options.atom_count, need / 1e9, n, memory / 1e9);
      throw InputError(text);
    }
  }
  if (!(options.coarse_tolerance_factor >= 1))
    throw InputError("the coarse tolerance factor must be at least 1");
  const auto start = std::chrono::steady_clock::now();
  const auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const int m = coresets.block_size * coresets.block_size * coresets.block_size;
  const double blocks = coresets.population_blocks;
  SplitMix64 rng(options.seed ^ 0x6B5D1C7A3E2F9081ull);

  const int level_count = static_cast<int>(coresets.levels.size());
  const int first_level = options.flat ? level_count - 1 : 0;
  const int iterations = options.flat
                             ? (options.flat_iterations > 0 ? options.flat_iterations
                                                            : options.iterations * level_count)
                             : options.iterations;
  TrainingResult result;
  result.dictionary.block_size = coresets.block_size;
  // The first level may be empty only if the data is nearly all flat; start from the largest then.
  const Coreset& seed_level =
      coresets.levels[static_cast<std::size_t>(first_level)].blocks.cols() > 0
          ? coresets.levels[static_cast<std::size_t>(first_level)]
          : coresets.largest();
  Eigen::MatrixXf& atoms = result.dictionary.atoms;
  atoms = initial_atoms(seed_level, m, options.atom_count, rng);

  KsvdOptions ksvd;
  ksvd.coding = options.coding;
  ksvd.duplicate_threshold = options.duplicate_threshold;
  const auto progress_of = [&](const CodingStats& s) {
    TrainingProgress p;
    p.rms_error = std::sqrt(s.objective / (static_cast<double>(m) * blocks));
    p.mean_sparsity = s.weighted_atoms / blocks;
    p.fraction_met = std::max(0.0, 1.0 - s.weighted_unmet / blocks);
    return p;
  };
  // Algorithm 1, lines 4–12: for each level, N iterations of (batch-OMP, dictionary update).
  // Stages: hierarchical, one per level; flat, equal shares of the iterations on the largest level,
  // counted from the end so that the last iterations always run at ε.
  const int stages = level_count;
  int t = 0;  // iteration counted over the whole run
  if (!(options.convergence >= 0)) throw InputError("the convergence threshold must be at least 0");
  for (int level = first_level; level < level_count; ++level) {
    const Coreset& c = coresets.levels[static_cast<std::size_t>(level)];
    if (c.blocks.cols() == 0) continue;
    double previous_objective = 0;
    int previous_stage = -1, previous_atoms = -1;
    for (int it = 0; it < iterations; ++it, ++t) {
      const int stage =
          options.flat ? stages - 1 - (iterations - 1 - t) * stages / iterations : level;
      const double coarse =
          stages > 1 ? static_cast<double>(stages - 1 - stage) / (stages - 1) : 0.0;
      ksvd.coding.tolerance =
          options.coding.tolerance * std::pow(options.coarse_tolerance_factor, coarse);
      // The ramp never holds back the last stage, however few iterations came before it.
      const bool last_stage = stage == stages - 1;
      ksvd.coding.max_atoms = options.sparsity_ramp && !last_stage
                                  ? std::min(options.coding.max_atoms, t + 1)
                                  : options.coding.max_atoms;
      const KsvdIterationStats s = ksvd_iteration(atoms, c.blocks, c.weights, ksvd, rng);
      ++result.total_iterations;
      // The objective is measured by the coding step, before this iteration's update: stop when the
      // previous update (at the same ε and Smax) gained less than the threshold.
      const bool comparable = stage == previous_stage && ksvd.coding.max_atoms == previous_atoms;
      const bool converged =
          options.convergence > 0 && comparable && (options.flat ? last_stage : true) &&
          previous_objective - s.coded.objective < options.convergence * previous_objective;
      previous_objective = s.coded.objective;
      previous_stage = stage;
      previous_atoms = ksvd.coding.max_atoms;
      if (callback) {
        TrainingProgress p = progress_of(s.coded);
        p.level = level - first_level + 1;
        p.levels = level_count - first_level;
        p.iteration = it + 1;
        p.iterations = iterations;
        p.tolerance = ksvd.coding.tolerance;
        p.max_atoms = ksvd.coding.max_atoms;
        p.samples = static_cast<std::size_t>(c.blocks.cols());
        p.draws = c.draws;
        p.replaced_atoms = s.replaced_atoms;
        p.elapsed_seconds = elapsed();
        callback(p);
      }
      if (converged) break;
    }
  }
  result.seconds = elapsed();
  // The trained dictionary against the largest level (not counted in the training time).
  const Coreset& largest = coresets.largest();
  result.final_stats =
      progress_of(measure_coding(atoms, largest.blocks, largest.weights, options.coding));
  result.final_stats.level = result.final_stats.levels = level_count - first_level;
  result.final_stats.samples = static_cast<std::size_t>(largest.blocks.cols());
  result.final_stats.draws = largest.draws;
  result.final_stats.tolerance = options.coding.tolerance;
  result.final_stats.max_atoms = options.coding.max_atoms;
  result.final_stats.elapsed_seconds = elapsed();
  result.final_stats.final = true;
  if (callback) callback(result.final_stats);
  return result;
}

double training_tolerance(std::optional<double> tolerance, double psnr,
                          const CoresetHierarchy& coresets) {
  if (tolerance) {
    if (!(*tolerance > 0)) throw InputError("--tolerance must be positive");
    return *tolerance;
  }
  const double range = coresets.value_max - coresets.value_min;
  if (!(range > 0))
    throw InputError("the training frames are constant: give --tolerance explicitly");
  return tolerance_for_psnr(psnr, range);
}

format::DictionaryTraining training_provenance(const CoresetOptions& coreset,
                                               const TrainingOptions& training,
                                               const CoresetHierarchy& coresets,
                                               const TrainingResult& result) {
  format::DictionaryTraining t;
  t.tolerance = training.coding.tolerance;
  t.value_min = coresets.value_min;
  t.value_max = coresets.value_max;
  t.max_sparsity = static_cast<std::uint32_t>(training.coding.max_atoms);
  t.coreset_voxels = coreset.coreset_voxels;
  t.coreset_levels = static_cast<std::uint32_t>(coreset.levels);
  t.iterations = static_cast<std::uint32_t>(result.total_iterations);
  t.seed = training.seed;
  t.flat = training.flat;
  t.training_frames = static_cast<std::uint32_t>(coresets.frames.size());
  t.rms_error = result.final_stats.rms_error;
  t.mean_sparsity = result.final_stats.mean_sparsity;
  return t;
}

}  // namespace volreel::dictionary
