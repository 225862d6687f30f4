// trilinear.hpp (private to volreel::cpu_render): trilinear interpolation in a dense grid, the one
// sampler shared by the atlas (CpuAtlas::sample) and the dense reference renderer.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

namespace volreel::cpu_render::detail {

/// Value of the grid (nx·ny·nz values, x fastest) at voxel-index coordinates (x, y, z) — voxel i
/// at coordinate i — clamped to [0, n − 1] on each axis (edge replication).
inline float trilinear(const float* grid, std::uint32_t nx, std::uint32_t ny, std::uint32_t nz,
                       float x, float y, float z) {
  // 1. Clamp to the grid, split into a voxel and a fraction.
  const auto split = [](float c, std::uint32_t n, std::uint32_t& i0, std::uint32_t& i1, float& w) {
    const float hi = static_cast<float>(n - 1);
    c = c > 0 ? (c < hi ? c : hi) : 0.0f;  // NaN -> 0
    const float f = std::floor(c);
    i0 = static_cast<std::uint32_t>(f);
    i1 = std::min(i0 + 1, n - 1);
    w = c - f;
  };
  std::uint32_t x0, x1, y0, y1, z0, z1;
  float wx, wy, wz;
  split(x, nx, x0, x1, wx);
  split(y, ny, y0, y1, wy);
  split(z, nz, z0, z1, wz);
  // 2. Eight neighbours, interpolated along x, then y, then z.
  const auto at = [&](std::uint32_t i, std::uint32_t j, std::uint32_t k) {
    return grid[(std::size_t{k} * ny + j) * nx + i];
  };
  const auto lerp = [](float a, float b, float w) { return a + (b - a) * w; };
  const float c00 = lerp(at(x0, y0, z0), at(x1, y0, z0), wx);
  const float c10 = lerp(at(x0, y1, z0), at(x1, y1, z0), wx);
  const float c01 = lerp(at(x0, y0, z1), at(x1, y0, z1), wx);
  const float c11 = lerp(at(x0, y1, z1), at(x1, y1, z1), wx);
  return lerp(lerp(c00, c10, wy), lerp(c01, c11, wy), wz);
}

}  // namespace volreel::cpu_render::detail
