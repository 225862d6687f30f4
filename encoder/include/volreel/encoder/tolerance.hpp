// tolerance.hpp: choosing ε, the tolerance of variable rate — given, from a PSNR, from a target
// size in bits per voxel (rate control: trial encodes of sample frames), or the ε the dictionary
// was trained at.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/coding_settings.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel::encoder {

/// Rate control for --bps: ε such that the container's bps, estimated from `sample_frames` evenly
/// spaced frames (encoded in memory, one at a time) plus `fixed_bytes` (the container's files
/// besides its frames: the dictionary and the manifest, estimated_manifest_bytes), is within
/// `relative` of
/// target_bps; then checked on as many other frames, and searched again on all of them where the
/// estimate misses (at most rate_check_rounds times). Returns ε and the estimated bps.
struct RateSearch {
  double tolerance = 0, estimated_bps = 0;
  int iterations = 0;             ///< trial encodes of the sample
  std::size_t sample_frames = 0;  ///< frames in the final estimate
  /// Coded bricks (ksvd, not constant) of the final sample's frames at ε, and of those the ones
  /// that kept the learned atoms (CodingSettings::split_bricks; without a split, every one).
  std::size_t sample_bricks = 0, learned_bricks = 0;
};
inline constexpr int rate_check_rounds = 2;

/// The search behind search_tolerance, on any bps(ε) that falls as ε grows: ε such that
/// |bps(ε) − target| ≤ relative·target, from `start`, within [min_tolerance, max_tolerance]. In
/// ln ε against ln bps, which is close to a line, it steps along the slope (at first `slope`, then
/// that of its last two trials; at most a factor max_rate_step in ε a step) until the target is
/// bracketed, then closes in by regula falsi (the Illinois variant, which moves both ends). So the
/// trials stay near the target: those far below it cost little and those far above it, which cost
/// most, are not run. Returns the closest trial, or where the target is out of reach (bps still
/// on one side of it at min_tolerance or max_tolerance) that end of the range; `slope` is left at
/// the last one measured (the start of a later search near the same ε). A trial of 0 bps counts
/// as too few bits; a NaN one ends the search and is never returned (a first trial of NaN leaves
/// tolerance 0).
/// Throws std::invalid_argument unless target_bps is positive and finite and
/// 0 < min_tolerance ≤ max_tolerance < ∞.
struct BpsSolution {
  double tolerance = 0, bps = 0;
  int trials = 0;
};
/// d ln bps / d ln ε before any is measured; only the first step's length depends on it (the
/// suite's members measure −0.3 to −0.6 between 0.5 and 8 bps).
inline constexpr double default_rate_slope = -0.5;
/// Measured slopes are kept within [−1/min_rate_slope, −min_rate_slope]: a flat stretch (the rate
/// barely moving) does not send the next step to the end of the range.
inline constexpr double min_rate_slope = 0.1;
inline constexpr double max_rate_step = 16;
inline constexpr int max_rate_trials = 30;
/// Trials closer than this in ln ε do not measure a slope (a jump in the rate between them
/// would read as a cliff).
inline constexpr double min_slope_spacing = 0.05;
/// A bracket narrower than this in ln ε (1 % in ε, where a smooth rate curve moves by about
/// 0.5 %) holds a jump in the rate across the target's window: the search ends with the closest.
inline constexpr double min_bracket = 0.01;
BpsSolution solve_for_bps(const std::function<double(double)>& bps_at, double target_bps,
                          double start, double min_tolerance, double max_tolerance, double relative,
                          double& slope, const Progress& progress = {});
/// encode skips the whole dictionary's pursuit (CodingSettings::learned_pursuit) where the rate
/// search's sample kept the learned atoms in none of its bricks, if that sample is every frame or
/// at least this many bricks: none in 30 bounds the share of bricks where they would pay by 10 %
/// at 95 % confidence (the rule of three, 3/n).
inline constexpr std::size_t min_skip_sample_bricks = 30;
RateSearch search_tolerance(const datasets::SeriesReader& series,
                            const dictionary::Dictionary& dictionary, std::uint64_t fixed_bytes,
                            CodingSettings settings, double target_bps, std::size_t frames,
                            std::size_t sample_frames = 3, double relative = 0.03,
                            const Progress& progress = {});

/// What ε is asked to be: at most one of tolerance, psnr and bps is set (none: the dictionary's
/// training ε, else dictionary::default_encoding_psnr).
struct ToleranceRequest {
  std::optional<double> tolerance;     ///< ε itself, data units
  std::optional<double> psnr;          ///< dB: ε = range·10^(−psnr/20)
  std::optional<double> bps;           ///< the whole container's bits per voxel (> 0)
  std::size_t rate_sample_frames = 3;  ///< bps: frames encoded per trial
  double rate_relative = 0.03;         ///< bps: how close to the target the search stops
};

/// Where choose_tolerance took ε from.
enum class ToleranceSource { fixed_rate, tolerance, psnr, bps, dictionary_training, default_psnr };

struct ToleranceChoice {
  double tolerance = 0;  ///< ε, data units (0 at fixed rate)
  ToleranceSource source = ToleranceSource::default_psnr;
  RateSearch rate_search;  ///< source bps: the search that found ε
};

/// ε for coding the first `frames` frames of `series` with `settings` (value range set) against
/// `dictionary`, as the container will store it (`fixed_bytes`: its file's size and the
/// manifest's, as search_tolerance takes them): none at
/// fixed rate (settings.fixed_sparsity > 0); else, in this order, request.tolerance,
/// request.psnr over the value range, request.bps by search_tolerance, the tolerance the
/// dictionary was trained at, and dictionary::default_encoding_psnr. Throws InputError where
/// search_tolerance does (a target below what the dictionary and manifest alone take).
ToleranceChoice choose_tolerance(const datasets::SeriesReader& series,
                                 const format::DictionaryFile& dictionary,
                                 std::uint64_t fixed_bytes, const CodingSettings& settings,
                                 std::size_t frames, const ToleranceRequest& request,
                                 const Progress& progress = {});

/// The range that PSNR targets and the tolerance search scale ε by: max − min, or for a constant
/// series (max = min, every brick a constant) max(1, |value|), so that ε stays positive.
double tolerance_range(double value_min, double value_max);

/// The smallest ε a PSNR target leads to, against the range (2^-40, about 241 dB): finer than a
/// float32 value holds, and far below the finest steps a payload stores (a brick's coefficients
/// to 2^-16 of its largest), so a smaller ε would change nothing but underflow the arithmetic.
inline constexpr double smallest_relative_tolerance = 0x1p-40;

/// ε for a PSNR target of `psnr_db` over `value_range`: dictionary::tolerance_for_psnr, at least
/// smallest_relative_tolerance of the range.
double tolerance_for_psnr_target(double psnr_db, double value_range);

/// ε at which to train a dictionary for the encode when none is given, over `value_range` (max −
/// min of the frames): request.tolerance, else request.psnr, else (also for a bps target, which
/// needs a dictionary to search with) dictionary::default_encoding_psnr.
double tolerance_to_train_at(const ToleranceRequest& request, double value_range);

}  // namespace volreel::encoder
