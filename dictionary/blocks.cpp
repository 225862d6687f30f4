// blocks.cpp: block extraction with edge replication, and the inverse for reconstruction.
#include "volreel/dictionary/blocks.hpp"

#include <algorithm>
#include <string>

namespace volreel::dictionary {

BlockGrid::BlockGrid(Dims dims, int block_size) : dims_(dims), block_size_(block_size) {
  if (block_size < 1 || block_size > 64)
    throw InputError("block size " + std::to_string(block_size) + " is outside 1..64");
  if (dims.x < 1 || dims.y < 1 || dims.z < 1)
    throw InputError("cannot cut an empty volume " + to_string(dims) + " into blocks");
  nx_ = (dims.x + block_size - 1) / block_size;
  ny_ = (dims.y + block_size - 1) / block_size;
  nz_ = (dims.z + block_size - 1) / block_size;
}

float BlockGrid::extract(std::span<const float> volume, std::size_t b, float* out) const {
  const auto bi = static_cast<std::int64_t>(b);
  const std::int64_t M = block_size_;
  const std::int64_t x0 = bi % nx_ * M, y0 = bi / nx_ % ny_ * M, z0 = bi / (nx_ * ny_) * M;
  double sum = 0;
  float* o = out;
  for (std::int64_t k = 0; k < M; ++k) {
    const std::int64_t z = std::min(z0 + k, dims_.z - 1);
    for (std::int64_t j = 0; j < M; ++j) {
      const std::int64_t y = std::min(y0 + j, dims_.y - 1);
      const float* row = volume.data() + dims_.index(0, y, z);
      if (x0 + M <= dims_.x) {
        for (std::int64_t i = 0; i < M; ++i) *o++ = row[x0 + i];
      } else {
        for (std::int64_t i = 0; i < M; ++i) *o++ = row[std::min(x0 + i, dims_.x - 1)];
      }
    }
  }
  const auto m = static_cast<std::size_t>(block_length());
  for (std::size_t i = 0; i < m; ++i) sum += static_cast<double>(out[i]);
  const auto mean = static_cast<float>(sum / static_cast<double>(m));
  for (std::size_t i = 0; i < m; ++i) out[i] -= mean;
  return mean;
}

void BlockGrid::store(std::span<float> volume, std::size_t b, float mean,
                      const float* values) const {
  const auto bi = static_cast<std::int64_t>(b);
  const std::int64_t M = block_size_;
  const std::int64_t x0 = bi % nx_ * M, y0 = bi / nx_ % ny_ * M, z0 = bi / (nx_ * ny_) * M;
  for (std::int64_t k = 0; k < M; ++k)
    for (std::int64_t j = 0; j < M; ++j)
      for (std::int64_t i = 0; i < M; ++i) {
        const float v = mean + values[(k * M + j) * M + i];
        if (x0 + i < dims_.x && y0 + j < dims_.y && z0 + k < dims_.z)
          volume[dims_.index(x0 + i, y0 + j, z0 + k)] = v;
      }
}

void extract_blocks(const BlockGrid& grid, std::span<const float> volume, Eigen::MatrixXf& blocks,
                    std::vector<float>& means) {
  const auto count = static_cast<std::int64_t>(grid.block_count());
  blocks.resize(grid.block_length(), count);
  means.resize(static_cast<std::size_t>(count));
#pragma omp parallel for schedule(static)
  for (std::int64_t b = 0; b < count; ++b)
    means[static_cast<std::size_t>(b)] =
        grid.extract(volume, static_cast<std::size_t>(b), blocks.col(b).data());
}

}  // namespace volreel::dictionary
