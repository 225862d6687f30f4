// render_truth.hpp: the ground truth `volreel render --compare SERIES` measures each frame
// against — the original series rendered at the frame's continuous playhead by the CPU reference
// renderer, the two frames around it blended.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <map>
#include <memory>
#include <string>

#include "commands.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"

namespace volreel::cli {

/// The original series at a continuous playhead: frames ⌊p⌋ and ⌊p⌋ + 1 (two kept in memory).
class GroundTruth {
 public:
  GroundTruth(const std::string& path, const ReaderOptions& reader, const format::Manifest& m)
      : series_(open(path, reader)) {
    const auto& info = series_->info();
    if (info.dims.x != m.dims[0] || info.dims.y != m.dims[1] || info.dims.z != m.dims[2])
      throw InputError("--compare " + path + ": the series is " + to_string(info.dims) +
                       ", the container " + std::to_string(m.dims[0]) + "x" +
                       std::to_string(m.dims[1]) + "x" + std::to_string(m.dims[2]));
    if (info.frames < m.frames.size())
      throw InputError("--compare " + path + ": the series has " + std::to_string(info.frames) +
                       " frames, the container " + std::to_string(m.frames.size()));
    geometry_ = cpu_render::VolumeGeometry::of(m.dims, m.shape());
  }

  /// The reference image at `playhead`: the finest level of both neighbouring frames, blended.
  cpu_render::RgbaImage render(double playhead, std::size_t keyframes,
                               const player::OrbitCamera& camera,
                               const cpu_render::TransferFunction& tf,
                               const cpu_render::RenderOptions& options) {
    const double p = std::clamp(playhead, 0.0, static_cast<double>(keyframes - 1));
    const auto t0 = static_cast<std::size_t>(std::floor(p));
    const std::size_t t1 = std::min(t0 + 1, keyframes - 1);
    const auto f = static_cast<float>(p - static_cast<double>(t0));
    const std::uint32_t finest = geometry_.levels - 1;
    for (auto it = cache_.begin(); it != cache_.end();)
      it = it->first == t0 || it->first == t1 ? std::next(it) : cache_.erase(it);
    const auto level = [&](std::size_t t) {
      return cpu_render::DenseLevel{geometry_.dims, frame(t).data, finest};
    };
    return cpu_render::render_reference(level(t0), level(t1), f, geometry_, camera, tf, options);
  }

 private:
  /// The series, its errors named as --compare's.
  static std::unique_ptr<datasets::SeriesReader> open(const std::string& path,
                                                      const ReaderOptions& reader) {
    try {
      return datasets::open_series(path, reader.to_open_options());
    } catch (const InputError& e) {
      throw InputError("--compare: " + std::string(e.what()));
    }
  }

  const Volume& frame(std::size_t t) {
    auto it = cache_.find(t);
    if (it != cache_.end()) return it->second;
    return cache_.emplace(t, series_->read_frame(t)).first->second;
  }
  std::unique_ptr<datasets::SeriesReader> series_;
  cpu_render::VolumeGeometry geometry_;
  std::map<std::size_t, Volume> cache_;
};

}  // namespace volreel::cli
