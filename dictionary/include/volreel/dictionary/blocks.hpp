// blocks.hpp: cutting a volume into M×M×M blocks, the unit of sparse coding (MTV-Player §3.1):
// each block becomes a zero-mean vector of m = M³ values; its mean is kept apart.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "volreel/datasets/volume.hpp"

namespace volreel::dictionary {

/// The grid of M³ blocks over a volume. Block (i, j, k) covers voxels [iM, iM+M) × [jM, jM+M) ×
/// [kM, kM+M); where a dimension is not a multiple of M the last block reads past the edge by
/// replicating the edge voxel. Blocks are numbered x fastest; values inside a block x fastest.
class BlockGrid {
 public:
  BlockGrid(Dims dims, int block_size);

  Dims dims() const { return dims_; }
  int block_size() const { return block_size_; }
  /// m = M³, values per block.
  int block_length() const { return block_size_ * block_size_ * block_size_; }
  /// Blocks along x, y, z.
  std::int64_t blocks_x() const { return nx_; }
  std::int64_t blocks_y() const { return ny_; }
  std::int64_t blocks_z() const { return nz_; }
  std::size_t block_count() const { return static_cast<std::size_t>(nx_ * ny_ * nz_); }

  /// Copies block b of `volume` (dims().voxels() values) into out (m values), subtracts the
  /// block's mean from them and returns that mean.
  float extract(std::span<const float> volume, std::size_t b, float* out) const;
  /// Writes mean + values (m values) into the voxels of block b that lie inside `volume`.
  void store(std::span<float> volume, std::size_t b, float mean, const float* values) const;

 private:
  Dims dims_;
  int block_size_;
  std::int64_t nx_, ny_, nz_;
};

/// Every block of `volume` as a column of `blocks` (resized to m × block_count; zero-mean) with
/// its mean in `means`. Parallel (OpenMP) over blocks.
void extract_blocks(const BlockGrid& grid, std::span<const float> volume, Eigen::MatrixXf& blocks,
                    std::vector<float>& means);

}  // namespace volreel::dictionary
