// tolerance.hpp: rate control — the tolerance ε of variable rate for a target size in bits per
// voxel, by trial encodes of sample frames.
#pragma once

#include <cstddef>
#include <cstdint>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/encoder/coding_settings.hpp"

namespace volreel::encoder {

/// Rate control for --bps: ε such that the container's bps, estimated from `sample_frames` evenly
/// spaced frames (encoded in memory) plus the dictionary, is within `relative` of target_bps.
/// Returns ε and the estimated bps.
struct RateSearch {
  double tolerance = 0, estimated_bps = 0;
  int iterations = 0;
};
RateSearch search_tolerance(const datasets::SeriesReader& series,
                            const dictionary::Dictionary& dictionary,
                            std::uint64_t dictionary_bytes, CodingSettings settings,
                            double target_bps, std::size_t frames, std::size_t sample_frames = 3,
                            double relative = 0.03, const Progress& progress = {});

}  // namespace volreel::encoder
