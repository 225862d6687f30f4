// pyramid.cpp: the levels of a frame's brick hierarchy (2×2×2 averages up to one root brick) and
// the stored voxels of one brick, its apron included, clamped to the level.
#include "volreel/encoder/pyramid.hpp"

#include <algorithm>

namespace volreel::encoder {

using format::brick_interior;
using format::brick_size;

namespace {

std::size_t clamp_index(std::int64_t i, std::uint32_t n) {
  return static_cast<std::size_t>(std::clamp<std::int64_t>(i, 0, static_cast<std::int64_t>(n) - 1));
}

}  // namespace

Pyramid build_pyramid(const Volume& frame) {
  Pyramid p;
  p.geometry = format::level_geometry({static_cast<std::uint32_t>(frame.dims.x),
                                       static_cast<std::uint32_t>(frame.dims.y),
                                       static_cast<std::uint32_t>(frame.dims.z)});
  const std::size_t levels = p.geometry.size();
  p.levels.resize(levels);
  p.levels[levels - 1] = frame.data;
  for (std::size_t l = levels - 1; l > 0; --l) {
    const auto& fine_dims = p.geometry[l].dims;
    const auto& dims = p.geometry[l - 1].dims;
    const std::vector<float>& fine = p.levels[l];
    std::vector<float>& coarse = p.levels[l - 1];
    coarse.resize(std::size_t{dims[0]} * dims[1] * dims[2]);
    const auto nz = static_cast<std::ptrdiff_t>(dims[2]);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < nz; ++k)
      for (std::uint32_t j = 0; j < dims[1]; ++j)
        for (std::uint32_t i = 0; i < dims[0]; ++i) {
          double sum = 0;
          for (std::uint32_t c = 0; c < 8; ++c) {
            const std::size_t x = clamp_index(2 * std::int64_t{i} + (c & 1), fine_dims[0]);
            const std::size_t y = clamp_index(2 * std::int64_t{j} + ((c >> 1) & 1), fine_dims[1]);
            const std::size_t z = clamp_index(2 * k + (c >> 2), fine_dims[2]);
            sum += static_cast<double>(fine[(z * fine_dims[1] + y) * fine_dims[0] + x]);
          }
          coarse[(static_cast<std::size_t>(k) * dims[1] + j) * dims[0] + i] =
              static_cast<float>(sum / 8);
        }
  }
  return p;
}

void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out) {
  const auto& dims = pyramid.geometry[level].dims;
  const std::vector<float>& v = pyramid.levels[level];
  const std::int64_t x0 = std::int64_t{x} * brick_interior - 1,
                     y0 = std::int64_t{y} * brick_interior - 1,
                     z0 = std::int64_t{z} * brick_interior - 1;
  std::size_t xs[brick_size];
  for (std::uint32_t a = 0; a < brick_size; ++a) xs[a] = clamp_index(x0 + a, dims[0]);
  for (std::uint32_t c = 0; c < brick_size; ++c) {
    const std::size_t zz = clamp_index(z0 + c, dims[2]);
    for (std::uint32_t b = 0; b < brick_size; ++b) {
      const std::size_t yy = clamp_index(y0 + b, dims[1]);
      const float* row = v.data() + (zz * dims[1] + yy) * dims[0];
      float* dst = out.data() + (std::size_t{c} * brick_size + b) * brick_size;
      for (std::uint32_t a = 0; a < brick_size; ++a) dst[a] = row[xs[a]];
    }
  }
}

}  // namespace volreel::encoder
