// stream_test_util.hpp: small containers and indexes for the stream scheduler's tests, encoded
// with zfp (no dictionary to train) from volreel's analytic fields.
#pragma once

#include <array>
#include <filesystem>
#include <vector>

#include "../test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::test {

inline encoder::CodingSettings zfp_coding() {
  encoder::CodingSettings s;
  s.codec = format::Codec::zfp;
  s.zfp_accuracy = 1e-3;
  s.value_min = -1;
  s.value_max = 1;
  return s;
}

/// Writes DIR/NAME.vreel: `frames` frames of an analytic field of `dims`, zfp-coded, every node
/// stored at every step unless max_keyframe_gap > 1.
inline std::filesystem::path make_container(
    const std::filesystem::path& dir, Dims dims, std::size_t frames,
    datasets::AnalyticField field = datasets::AnalyticField::blobs,
    std::uint32_t max_keyframe_gap = 1) {
  datasets::AnalyticParams p;
  p.field = field;
  p.dims = dims;
  p.frames = frames;
  {
    datasets::RawSeriesWriter w(dir / "series", dims, "test");
    datasets::generate_analytic(p, w);
  }
  const auto series = datasets::open_series(dir / "series");
  encoder::EncodeJob job;
  job.coding = zfp_coding();
  job.max_keyframe_gap = max_keyframe_gap;
  const auto out = dir / "test.vreel";
  encoder::encode_series(*series, out, job);
  return out;
}

/// An index of `frames` time steps that all share one frame encoded in memory (no files: for
/// tests of priorities and selection that do no I/O).
inline stream::SpatialIndex make_index(Dims dims, std::size_t frames,
                                       std::uint32_t brick_size = format::default_brick_size) {
  datasets::AnalyticParams p;
  p.dims = dims;
  p.frames = 4;
  Volume v(dims);
  datasets::analytic_frame(p, 0, v.data);
  encoder::CodingSettings coding = zfp_coding();
  coding.brick_size = brick_size;
  const auto bytes = encoder::FrameEncoder(nullptr, coding).encode(0, v);
  const format::FrameView view(bytes, "memory.vrf");
  const std::array<std::uint32_t, 3> d{static_cast<std::uint32_t>(dims.x),
                                       static_cast<std::uint32_t>(dims.y),
                                       static_cast<std::uint32_t>(dims.z)};
  stream::SpatialIndexBuilder b(d, frames, format::BrickShape{brick_size});
  for (std::uint32_t t = 0; t < frames; ++t) b.add_frame(t, view, "memory.vrf");
  return std::move(b).build();
}

/// A camera close enough that every visible node refines to the finest level.
inline player::OrbitCamera close_camera(Dims dims) {
  return player::OrbitCamera::framing(
      {static_cast<double>(dims.x), static_cast<double>(dims.y), static_cast<double>(dims.z)}, 256,
      256);
}

}  // namespace volreel::test
