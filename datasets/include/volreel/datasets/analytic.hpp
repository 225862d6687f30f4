// analytic.hpp: small deterministic time-varying fields for tests and quick experiments.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "volreel/datasets/volume.hpp"

namespace volreel::datasets {

class RawSeriesWriter;

enum class AnalyticField {
  blobs,     ///< Gaussian blobs of different sizes moving on closed paths through the box
  rotating,  ///< a banded pattern rotating about the z axis, with a slowly pulsing radial term
  noise,     ///< smooth value noise (4 octaves) from volreel's PRNG, drifting in time
  plume,     ///< a turbulent plume rising into a still, stratified box (still regions beside
             ///< active ones)
};
/// "blobs" | "rotating" | "noise" | "plume"; throws InputError otherwise.
AnalyticField parse_analytic_field(const std::string& name);
std::string to_string(AnalyticField field);

struct AnalyticParams {
  AnalyticField field = AnalyticField::blobs;
  Dims dims{64, 64, 64};
  std::size_t frames = 16;
  std::uint64_t seed = 1;
};

/// Frame t of the field, values in about [-1, 1], into out (dims.voxels() values). Depends only
/// on the parameters and t, never on other frames.
void analytic_frame(const AnalyticParams& params, std::size_t t, std::span<float> out);

/// Write every frame through writer and finish it; timestamps are t / frames.
void generate_analytic(const AnalyticParams& params, RawSeriesWriter& writer,
                       const Progress& progress = {});

}  // namespace volreel::datasets
