// coreset.hpp: the coreset hierarchy that dictionary training runs on (MTV-Player §3.1): weighted
// block samples of sizes C, C/2, …, C/2^L drawn in one streaming pass over frames chosen by Halton
// sampling in time.
//
// Sampling, precisely:
//  1. Frames: the base-2 Halton (van der Corput) sequence h_1 = 1/2, 1/4, 3/4, 1/8, … picks frame
//     floor(h_i·T) (repeats skipped) until the chosen frames hold ≥ frame_factor·C voxels (the
//     paper's 16) or every frame is chosen.
//  2. Blocks: each M³ block y_b of a chosen frame (mean removed) has energy e_b = ‖y_b‖². There are
//     n = floor(C / M³) sample slots; each slot holds one independent draw from the distribution
//     p_b = e_b / E, E = Σ e_b over all blocks of the chosen frames (sampling with replacement,
//     probability proportional to energy, so flat blocks — e_b = 0 — are never kept; they need
//     no atoms anyway). A slot draws once per frame f: a block of f by the inverse of f's
//     cumulative energies at u·E_f (E_f = Σ e_b over f), with the key −ln(1 − u')/E_f, an
//     exponential variable of rate E_f; it keeps the draw with the smallest key. The smallest of
//     independent exponentials of rates E_f falls on frame f with probability E_f / E, so the slot
//     holds block b with probability e_b / E. u and u' are hashes of (seed, frame, slot), so the
//     draw does not depend on the order the frames are visited in nor on the process that visits
//     them: processes draw from their own frames (CoresetDraw) and merging keeps each slot's
//     smaller key, which gives the draw of one process over all frames. Memory: n·M³ floats = C.
//  3. Levels: the slots are independent, so the first n_l = n / 2^(L−l) slots are themselves a
//     sample of size n_l; level l ∈ [0, L] takes them, merges slots that hold the same block, and
//     gives each distinct block the Hansen–Hurwitz weight w = (copies) · E / (n_l · e_b). Then
//     Σ w·f(y) is an unbiased estimate of Σ_b f(y_b) over all blocks of the chosen frames, and
//     exact for f = energy: Σ w‖y‖² = E.
// Deterministic for a given seed (the parallel parts are per block and order-independent).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"

namespace volreel::dictionary {

struct CoresetOptions {
  int block_size = 6;                         ///< M
  std::uint64_t coreset_voxels = 16'000'000;  ///< C: voxels in the largest level (C/M³ block slots)
  int levels = 6;                             ///< L: halvings below C, giving L + 1 levels
  double frame_factor = 16;  ///< choose frames until they hold ≥ frame_factor·C voxels
  std::uint64_t seed = 1;
  /// Frames to choose from (empty: all frames of the series). The bench uses it to hold frames out.
  std::vector<std::size_t> candidate_frames;
};

/// One level: distinct zero-mean blocks with their weights.
struct Coreset {
  Eigen::MatrixXf blocks;      ///< m × n, zero-mean columns
  std::vector<float> weights;  ///< n, positive
  std::size_t draws = 0;       ///< slots this level took (≥ n; duplicates merged)
};

struct CoresetHierarchy {
  int block_size = 6;
  std::vector<Coreset> levels;          ///< [0] the smallest (C/2^L) … [L] the largest (C)
  std::vector<std::size_t> frames;      ///< frames the blocks were drawn from, in Halton order
  double population_blocks = 0;         ///< blocks in those frames, flat ones included
  double population_energy = 0;         ///< E = Σ e_b over those blocks
  double value_min = 0, value_max = 0;  ///< value range over those frames

  const Coreset& largest() const { return levels.back(); }
};

/// The frames Halton sampling picks from `candidates` (in that order) until they hold at least
/// min_voxels voxels of voxels_per_frame each (all of them if there are too few).
std::vector<std::size_t> halton_frames(const std::vector<std::size_t>& candidates,
                                       std::size_t voxels_per_frame, double min_voxels);

/// A coreset draw over some frames (coreset.hpp, step 2), to be merged with draws over others;
/// finish() gives the hierarchy of every frame drawn from.
class CoresetDraw {
 public:
  explicit CoresetDraw(const CoresetOptions& options);  ///< InputError on bad options
  ~CoresetDraw();
  CoresetDraw(CoresetDraw&&) noexcept;
  CoresetDraw& operator=(CoresetDraw&&) noexcept;
  /// Draws from frame t (its index in the series: the draw depends on it).
  void add_frame(std::size_t t, std::span<const float> volume, Dims dims);
  /// Takes the other draw's frames: each slot keeps the smaller key.
  void merge(const CoresetDraw& other);
  /// The draw as bytes (to send to another process), and back with the same options.
  std::vector<std::byte> to_bytes() const;
  static CoresetDraw from_bytes(std::span<const std::byte> bytes, const CoresetOptions& options);
  /// The levels (step 3); `frames` of the result is left empty.
  CoresetHierarchy finish(int levels) const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

/// The frames of the series the hierarchy is drawn from (Halton sampling, step 1).
std::vector<std::size_t> coreset_frames(const datasets::SeriesReader& series,
                                        const CoresetOptions& options);
/// A draw over `frames` of the series (a share of coreset_frames() when processes draw together).
CoresetDraw draw_coreset(const datasets::SeriesReader& series, const CoresetOptions& options,
                         std::span<const std::size_t> frames, const Progress& progress = {});

/// Builds the hierarchy in one pass over the chosen frames. Throws InputError if C is smaller
/// than 2^L blocks or a frame cannot be read; the levels are empty if every block is flat.
CoresetHierarchy build_coreset_hierarchy(const datasets::SeriesReader& series,
                                         const CoresetOptions& options,
                                         const Progress& progress = {});

/// The same from volumes already in memory (all of them are used; no frame selection).
CoresetHierarchy build_coreset_hierarchy(const std::vector<Volume>& frames,
                                         const CoresetOptions& options);

/// A warning (empty: none) where the hierarchy's largest level holds too few distinct blocks for
/// `atoms` atoms: fewer than two a atom. K-SVD fits an atom to the blocks that use it, so most
/// atoms would keep their start and still cost their bytes in every container.
std::string too_few_blocks_warning(const CoresetHierarchy& hierarchy, int atoms);

}  // namespace volreel::dictionary
