// blobs_container.hpp: a small zfp container of moving blobs (datasets' analytic field), written
// into a folder, for the tests of the frame loops and the ray casters.
#pragma once

#include <cstddef>
#include <filesystem>

#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/encoder/encoder.hpp"

namespace volreel::test {

/// Writes the raw series dir/series and its zfp container dir/test.vreel (accuracy 1e-3).
inline void write_blobs_container(const std::filesystem::path& dir, Dims dims, std::size_t frames) {
  {
    datasets::AnalyticParams p;
    p.field = datasets::AnalyticField::blobs;
    p.dims = dims;
    p.frames = frames;
    datasets::RawSeriesWriter w(dir / "series", dims, "test");
    datasets::generate_analytic(p, w);
  }
  encoder::EncodeJob job;
  job.coding.codec = format::Codec::zfp;
  job.coding.zfp_accuracy = 1e-3;
  encoder::encode_series(*datasets::open_series(dir / "series"), dir / "test.vreel", job);
}

}  // namespace volreel::test
