// encode_report.hpp: what `volreel encode` prints about the tolerance it chose and about the
// encode it ran (times, quantization loss, where the bytes went, atoms and mean bits).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "volreel/encoder/encoder.hpp"

namespace volreel::cli {

/// How ε was chosen (choice) and what it means under the coding's rate rule. target_bps and
/// sample_frames: the --bps search's target and frames per trial; range: max − min of the
/// values; atoms: K of the dictionary.
void print_tolerance_choice(const encoder::ToleranceChoice& choice,
                            const encoder::CodingSettings& coding, double target_bps, double range,
                            std::uint32_t atoms);

/// The encode's times, quantization loss, byte breakdown, histograms and totals (written to
/// `out`).
/// psnr_target: the --psnr of the encode (0: none), reported as met or missed; bps_target: the
/// --bps (0: none), a warning when the container lands more than encoder::bps_tolerance from it;
/// a --max-error (coding.max_error) that blocks miss, a warning. Returns whether a target was
/// missed (encoder::missed_targets; a warning printed for each).
bool print_encode_summary(const encoder::EncodeSummary& summary,
                          const encoder::CodingSettings& coding, const std::string& out,
                          double psnr_target = 0, double bps_target = 0);

}  // namespace volreel::cli
