// volreel_codecs.hpp: volreel's codecs (variable rate, fixed rate, zfp bricks in the container) as
// FrameCodecs of the rate-distortion harness.
#pragma once

#include <memory>
#include <vector>

#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/psnr/rate_distortion.hpp"

namespace volreel::cli {

struct VolreelSweep {
  std::vector<double> relative_tolerances;  ///< variable rate: ε / value range
  /// Variable rate with the Lagrangian rule, once per factor (family "volreel variable-rate")
  std::vector<double> lagrangian_factors = {encoder::CodingSettings{}.lagrangian_factor};
  bool tolerance_rule = false;  ///< also with the ε rule (family "volreel variable-rate eps-rule")
  std::vector<int> fixed_sparsities;  ///< fixed rate: S
  std::vector<double>
      zfp_relative_accuracies;  ///< zfp per brick in the container: accuracy / range
  /// Every ksvd row: the pursuit, and (variable rate, Lagrangian rule) the level factor.
  dictionary::AtomSelection selection = encoder::CodingSettings{}.selection;
  double level_tolerance_factor = encoder::CodingSettings{}.level_tolerance_factor;
  double level_detail_ratio = encoder::CodingSettings{}.level_detail_ratio;
  /// Variable rate: the coefficient step as a multiple of ε (as volreel encode --coef-step).
  double coef_step_factor = encoder::CodingSettings{}.coef_step_factor;
  /// Stored voxels per brick axis of every row (volreel encode --brick-size; never 0 here).
  std::uint32_t brick_size = format::default_brick_size;
};

/// Codecs that encode each frame into an in-memory frame file and decode it with the CPU decoder.
/// dictionary_bytes: the dictionary file's size, counted once in bps.
std::vector<std::unique_ptr<psnr::FrameCodec>> make_volreel_sweep(
    std::shared_ptr<const dictionary::Dictionary> dictionary, std::size_t dictionary_bytes,
    double value_min, double value_max, const VolreelSweep& sweep);

}  // namespace volreel::cli
