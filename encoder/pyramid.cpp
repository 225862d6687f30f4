// pyramid.cpp: the levels of a frame's brick hierarchy (2×2×2 averages up to one root brick) and
// the stored voxels of one brick, its apron included, clamped to the level.
#include "volreel/encoder/pyramid.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string>

namespace volreel::encoder {

namespace {

std::size_t clamp_index(std::int64_t i, std::uint32_t n) {
  return static_cast<std::size_t>(std::clamp<std::int64_t>(i, 0, static_cast<std::int64_t>(n) - 1));
}

}  // namespace

void downsample_planes(const std::array<std::uint32_t, 3>& fine_dims,
                       const std::array<std::uint32_t, 3>& dims,
                       const std::function<const float*(std::size_t z)>& fine_plane,
                       std::size_t k_begin, std::size_t k_end, float* out,
                       const std::function<const float*(std::size_t z)>& fine_detail,
                       float* detail_out) {
  const std::size_t plane = std::size_t{dims[0]} * dims[1];
  for (std::size_t k = k_begin; k < k_end; ++k) {
    const std::size_t fz[2] = {clamp_index(2 * static_cast<std::int64_t>(k), fine_dims[2]),
                               clamp_index(2 * static_cast<std::int64_t>(k) + 1, fine_dims[2])};
    const float* fine_z[2] = {fine_plane(fz[0]), fine_plane(fz[1])};
    const float* detail_z[2] = {nullptr, nullptr};
    if (detail_out && fine_detail)
      detail_z[0] = fine_detail(fz[0]), detail_z[1] = fine_detail(fz[1]);
    float* coarse = out + (k - k_begin) * plane;
    float* detail = detail_out ? detail_out + (k - k_begin) * plane : nullptr;
    const auto ny = static_cast<std::ptrdiff_t>(dims[1]);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t jj = 0; jj < ny; ++jj) {
      const auto j = static_cast<std::uint32_t>(jj);
      for (std::uint32_t i = 0; i < dims[0]; ++i) {
        std::size_t at[8];
        double sum = 0;
        for (std::uint32_t c = 0; c < 8; ++c) {
          const std::size_t x = clamp_index(2 * std::int64_t{i} + (c & 1), fine_dims[0]);
          const std::size_t y = clamp_index(2 * std::int64_t{j} + ((c >> 1) & 1), fine_dims[1]);
          at[c] = y * fine_dims[0] + x;
          sum += static_cast<double>(fine_z[c >> 2][at[c]]);
        }
        const double mean = sum / 8;
        coarse[std::size_t{j} * dims[0] + i] = static_cast<float>(mean);
        if (!detail) continue;
        // The frame's voxels under this one differ from it by the finer voxels' own detail plus
        // the finer voxels' difference from their mean (each finer voxel covering as many).
        double squares = 0;
        for (std::uint32_t c = 0; c < 8; ++c) {
          const double d = static_cast<double>(fine_z[c >> 2][at[c]]) - mean;
          squares += d * d;
          if (detail_z[0]) squares += static_cast<double>(detail_z[c >> 2][at[c]]);
        }
        // Values near the float range's ends square past it: the detail saturates.
        detail[std::size_t{j} * dims[0] + i] =
            static_cast<float>(std::min(squares / 8, double{std::numeric_limits<float>::max()}));
      }
    }
  }
}

Pyramid build_pyramid(const Volume& frame, format::BrickShape shape) {
  Pyramid p;
  p.shape = shape;
  p.geometry = format::level_geometry(
      {static_cast<std::uint32_t>(frame.dims.x), static_cast<std::uint32_t>(frame.dims.y),
       static_cast<std::uint32_t>(frame.dims.z)},
      shape);
  const std::size_t levels = p.geometry.size();
  p.levels.resize(levels);
  p.levels[levels - 1] = frame.data;
  for (std::size_t l = levels - 1; l > 0; --l) {
    const auto& fine_dims = p.geometry[l].dims;
    const auto& dims = p.geometry[l - 1].dims;
    const std::vector<float>& fine = p.levels[l];
    std::vector<float>& coarse = p.levels[l - 1];
    coarse.resize(std::size_t{dims[0]} * dims[1] * dims[2]);
    const std::size_t fine_plane = std::size_t{fine_dims[0]} * fine_dims[1];
    downsample_planes(
        fine_dims, dims, [&](std::size_t z) { return fine.data() + z * fine_plane; }, 0, dims[2],
        coarse.data());
  }
  return p;
}

namespace {

/// extract_brick's voxels from the planes `plane(z)` returns of a level of size `dims`.
template <class Plane>
void extract_from_planes(format::BrickShape shape, const std::array<std::uint32_t, 3>& dims,
                         std::uint32_t x, std::uint32_t y, std::uint32_t z, const Plane& plane,
                         std::span<float> out) {
  if (out.size() != shape.voxels())
    throw std::logic_error("extract_brick: an output of " + std::to_string(out.size()) +
                           " values for a brick of " + std::to_string(shape.voxels()));
  const std::int64_t interior = shape.interior();
  const std::uint32_t brick_size = shape.size;
  const std::int64_t x0 = std::int64_t{x} * interior - 1, y0 = std::int64_t{y} * interior - 1,
                     z0 = std::int64_t{z} * interior - 1;
  std::size_t xs[format::max_brick_size];
  for (std::uint32_t a = 0; a < brick_size; ++a) xs[a] = clamp_index(x0 + a, dims[0]);
  for (std::uint32_t c = 0; c < brick_size; ++c) {
    const float* level_plane = plane(clamp_index(z0 + c, dims[2]));
    for (std::uint32_t b = 0; b < brick_size; ++b) {
      const std::size_t yy = clamp_index(y0 + b, dims[1]);
      const float* row = level_plane + yy * dims[0];
      float* dst = out.data() + (std::size_t{c} * brick_size + b) * brick_size;
      for (std::uint32_t a = 0; a < brick_size; ++a) dst[a] = row[xs[a]];
    }
  }
}

}  // namespace

void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out) {
  const auto& dims = pyramid.geometry[level].dims;
  const std::vector<float>& v = pyramid.levels[level];
  const std::size_t plane = std::size_t{dims[0]} * dims[1];
  extract_from_planes(
      pyramid.shape, dims, x, y, z, [&](std::size_t zz) { return v.data() + zz * plane; }, out);
}

PyramidWindow::PyramidWindow(std::vector<format::LevelGeometry> geometry, ReadPlanes read,
                             format::BrickShape shape, bool detail)
    : geometry_(std::move(geometry)),
      shape_(shape),
      detail_(detail),
      read_(std::move(read)),
      levels_(geometry_.size()) {}

namespace {

/// Floats a plane of `level` holds: its values, and its detail above the frame's level.
std::size_t plane_values(const std::vector<format::LevelGeometry>& geometry, std::size_t level,
                         bool detail) {
  const std::size_t plane_size = std::size_t{geometry[level].dims[0]} * geometry[level].dims[1];
  return detail && level + 1 < geometry.size() ? 2 * plane_size : plane_size;
}

}  // namespace

std::size_t PyramidWindow::stored_values(std::size_t level) const {
  return plane_values(geometry_, level, detail_);
}

double PyramidWindow::planes_bytes(const std::vector<format::LevelGeometry>& geometry,
                                   double planes, bool detail) {
  double bytes = 0;
  for (std::size_t level = 0; level < geometry.size(); ++level)
    bytes += planes * sizeof(float) * static_cast<double>(plane_values(geometry, level, detail));
  return bytes;
}

const float* PyramidWindow::detail(std::size_t level, std::size_t z) const {
  if (!detail_ || level + 1 == geometry_.size()) return nullptr;
  return plane(level, z) + std::size_t{geometry_[level].dims[0]} * geometry_[level].dims[1];
}

double PyramidWindow::brick_detail(std::size_t level, std::uint32_t x, std::uint32_t y,
                                   std::uint32_t z) const {
  if (!detail_ || level + 1 == geometry_.size()) return 0;
  const auto& dims = geometry_[level].dims;
  const std::uint32_t interior = shape_.interior(), cell[3] = {x, y, z};
  std::uint32_t begin[3], end[3];
  for (int a = 0; a < 3; ++a) {
    const std::uint32_t n = dims[static_cast<std::size_t>(a)];
    begin[a] = std::min(interior * cell[a], n);
    end[a] = std::min(begin[a] + interior, n);
  }
  double sum = 0;
  std::size_t count = 0;
  for (std::uint32_t k = begin[2]; k < end[2]; ++k) {
    const float* d = detail(level, k);
    for (std::uint32_t j = begin[1]; j < end[1]; ++j)
      for (std::uint32_t i = begin[0]; i < end[0]; ++i, ++count)
        sum += static_cast<double>(d[std::size_t{j} * dims[0] + i]);
  }
  return count > 0 ? sum / static_cast<double>(count) : 0.0;
}

const float* PyramidWindow::plane(std::size_t level, std::size_t z) const {
  const Level& v = levels_[level];
  if (z < v.begin || z >= v.end)
    throw std::logic_error("PyramidWindow: plane " + std::to_string(z) + " of level " +
                           std::to_string(level) + " is not in the window [" +
                           std::to_string(v.begin) + ", " + std::to_string(v.end) + ")");
  return v.planes[z - v.begin].data();
}

void PyramidWindow::append_planes(std::size_t level, std::size_t end) {
  Level& v = levels_[level];
  end = std::min(end, planes(level));
  const auto& dims = geometry_[level].dims;
  const std::size_t plane_size = std::size_t{dims[0]} * dims[1], stored = stored_values(level);
  for (; v.end < end; ++v.end) {
    std::vector<float> p;
    if (!v.spare.empty()) {
      p = std::move(v.spare.back());
      v.spare.pop_back();
    }
    p.resize(stored);
    if (level + 1 == geometry_.size())
      read_(v.end, v.end + 1, p);
    else
      downsample_planes(
          geometry_[level + 1].dims, dims, [&](std::size_t z) { return plane(level + 1, z); },
          v.end, v.end + 1, p.data(), [&](std::size_t z) { return detail(level + 1, z); },
          detail_ ? p.data() + plane_size : nullptr);
    v.planes.push_back(std::move(p));
    bytes_ += stored * sizeof(float);
    peak_bytes_ = std::max(peak_bytes_, bytes_);
  }
}

void PyramidWindow::advance(std::size_t finest_end) {
  const std::size_t finest = geometry_.size() - 1;
  append_planes(finest, finest_end);
  for (std::size_t l = finest; l-- > 0;) {
    // Coarse plane k averages finer planes 2k and 2k + 1 (clamped to the finer level).
    const std::size_t fine_end = levels_[l + 1].end;
    append_planes(l, fine_end == planes(l + 1) ? planes(l) : fine_end / 2);
  }
}

void PyramidWindow::release(std::size_t level, std::size_t begin) {
  Level& v = levels_[level];
  // The next coarser plane still to be averaged reads finer planes from 2·end on.
  if (level > 0 && levels_[level - 1].end < planes(level - 1))
    begin = std::min(begin, 2 * levels_[level - 1].end);
  begin = std::min(begin, v.end);
  const std::size_t stored = stored_values(level);
  for (; v.begin < begin; ++v.begin) {
    // A released plane's storage serves the next plane appended (the window's planes are always
    // about one brick's worth, so one spare is enough).
    if (v.spare.empty()) v.spare.push_back(std::move(v.planes.front()));
    v.planes.pop_front();
    bytes_ -= stored * sizeof(float);
  }
}

void PyramidWindow::extract_brick(std::size_t level, std::uint32_t x, std::uint32_t y,
                                  std::uint32_t z, std::span<float> out) const {
  extract_from_planes(
      shape_, geometry_[level].dims, x, y, z, [&](std::size_t zz) { return plane(level, zz); },
      out);
}

}  // namespace volreel::encoder
