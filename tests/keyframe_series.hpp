// keyframe_series.hpp: a series whose regions change in time in three ways, for the tests of
// sparse keyframes: voxels x ≤ 35 are constant in time (the finest bricks of grid column 0, their
// aprons included, never change), voxels x ≥ 36 change nonlinearly (a pattern travelling fast
// enough that interpolating two steps misses the one between), and `linear` makes every voxel
// instead a + t·b, linear in time.
#pragma once

#include <cmath>
#include <cstddef>
#include <filesystem>
#include <vector>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"

namespace volreel::test {

inline float keyframe_series_value(std::size_t x, std::size_t y, std::size_t z, std::size_t t,
                                   bool linear) {
  const double fx = static_cast<double>(x), fy = static_cast<double>(y),
               fz = static_cast<double>(z), ft = static_cast<double>(t);
  const double still = 0.5 * std::sin(0.21 * fx) * std::cos(0.17 * fy) + 0.01 * fz;
  if (linear) return static_cast<float>(still + 0.05 * ft * std::cos(0.13 * fx + 0.11 * fz));
  if (x <= 35) return static_cast<float>(still);
  return static_cast<float>(0.5 * std::sin(0.25 * fx + 1.3 * ft) * std::cos(0.2 * fy - 0.7 * ft));
}

/// Writes the series into dir (RawSeriesWriter).
inline void write_keyframe_series(const std::filesystem::path& dir, Dims dims, std::size_t frames,
                                  bool linear = false) {
  datasets::RawSeriesWriter w(dir, dims, "test");
  std::vector<float> v(dims.voxels());
  for (std::size_t t = 0; t < frames; ++t) {
    std::size_t i = 0;
    for (std::size_t z = 0; z < static_cast<std::size_t>(dims.z); ++z)
      for (std::size_t y = 0; y < static_cast<std::size_t>(dims.y); ++y)
        for (std::size_t x = 0; x < static_cast<std::size_t>(dims.x); ++x)
          v[i++] = keyframe_series_value(x, y, z, t, linear);
    w.write_frame(t, static_cast<double>(t), v);
  }
  w.finish();
}

}  // namespace volreel::test
