// detail.hpp: what the encoder's source files share — brick coding (brick_coding.cpp) used by the
// frame encoder, timing, and the sample frames of size estimates (tolerance_search.cpp); not part
// of the public interface.
#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder::detail {

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

/// How a brick's codes are quantized.
struct QuantizeOptions {
  bool refit = true;  ///< sequential least-squares refit (see quantize_block)
  /// The atoms are orthonormal (dictionary::BatchOmp::orthonormal): the refit would give each
  /// coefficient back unchanged, so it is skipped.
  bool orthonormal_atoms = false;
  double target_energy =
      -1;  ///< m·ε²: extend the pursuit while the quantized error exceeds it (< 0: never)
  /// > 0: extend the pursuit while a value of the block is off by more than this (data units),
  /// and code the brick again with half the coefficient step if a block still misses it.
  double max_abs_error = 0;
  int max_atoms = 15;
  std::uint32_t band_split = 0;  ///< the payload's band split (format::KsvdPayloadParts)
  /// The atoms are the dictionary's from band_split on (the DCT basis after the learned atoms),
  /// indexed from 0: the payload takes the split flag (format::KsvdPayloadParts::from_split).
  bool from_split = false;
  /// The brick's n³ block weights of the Lagrangian rule (null: 1 each), for
  /// BrickQuantization::weighted_error.
  const float* block_weights = nullptr;
  /// The step of the quantized coefficients (data units; never finer than the brick's largest
  /// coefficient / 2^16). 0: the brick's largest coefficient / 2^(fixed_coef_bits − 1).
  double coef_step = 0;
  int coef_bits = -1;  ///< ≥ 1: every brick's step is its largest coefficient / 2^coef_bits
  std::uint32_t fixed_coef_bits = 8;  ///< signed bits of the largest value where there is no step
  /// The largest step of a brick's quantized block means: each brick takes the fewest bits
  /// (0..15) whose step over its means' range is at most this. 0: always 12 bits.
  double mean_step = 0;
  int mean_bits = -1;  ///< ≥ 0: every brick takes exactly this many mean bits (overrides mean_step)
  /// The brick's box word of coded blocks (brick_decode.h, vr_box_word; 0: every block): the
  /// blocks outside are not coded and decode to the payload's mean_bias.
  std::uint32_t box = 0;
  /// Quantize the brick's blocks on all threads (OpenMP): for callers that code fewer bricks at
  /// once than there are threads. The payload is the same either way.
  bool parallel_blocks = false;
};

/// A constant brick's payload: its one value (4 bytes).
std::vector<std::byte> constant_payload(float v);

/// Copies the n³ blocks of a brick of `shape` into n³ columns of `columns` (m × n³, zero-mean)
/// and their means into `means`.
void brick_to_blocks(format::BrickShape shape, const float* brick, float* columns, float* means);

/// Share of each of the n³ blocks of brick (x, y, z) of `shape` of a level of size `dims` that
/// the decoder reads: voxels of the brick's interior (stored index 1..size − 2 on each axis)
/// inside the level.
void owned_block_shares(format::BrickShape shape, std::uint32_t x, std::uint32_t y, std::uint32_t z,
                        const std::array<std::uint32_t, 3>& dims, float* shares);

/// The shares as weights of the Lagrangian rule: at least 1/216 (one voxel) for a block that
/// holds any of the level's own voxels, so that as ε → 0 every such block is still coded up to
/// Smax; 0 for a block of padding alone (past the volume's edge, never drawn): its mean only.
void owned_block_weights(format::BrickShape shape, std::uint32_t x, std::uint32_t y,
                         std::uint32_t z, const std::array<std::uint32_t, 3>& dims, float* weights);

/// What quantize_brick adds up over the bricks it codes.
struct BrickQuantization {
  double squared_error = 0;   ///< of the quantized blocks (all n³ of each brick)
  double weighted_error = 0;  ///< the same, each block's weighed by QuantizeOptions::block_weights
  std::size_t codes = 0;
  std::size_t blocks_over_bound = 0;  ///< blocks that missed max_abs_error even at 16 bits
};

/// Quantizes one brick's sparse codes (blocks first_block .. first_block + n³ − 1 of `codes`) into
/// its ksvd payload (brick_decode.h's layout); see brick_coding.cpp for the steps. Adds to
/// *result.
std::vector<std::byte> quantize_brick(format::BrickShape shape, const float* columns,
                                      const float* means, const dictionary::SparseCodes& codes,
                                      std::size_t first_block, const Eigen::MatrixXf& atoms,
                                      const QuantizeOptions& options, BrickQuantization* result);

/// A brick of `shape` as a zfp fixed-accuracy stream, padded to a multiple of 4 bytes (never 4
/// bytes, which would read as a constant brick). Throws std::runtime_error if zfp fails.
std::vector<std::byte> zfp_payload(format::BrickShape shape, const float* brick, double accuracy);

/// The indices of `count` frames of the first `frames`, evenly spaced (the middle one if count is
/// 1), in increasing order.
std::vector<std::size_t> evenly_spaced_indices(std::size_t frames, std::size_t count);

/// Refuses (InputError) a dictionary whose atoms are not 6³ blocks, the blocks of volreel's
/// bricks; `where` names it in the message ("d.bin: ", or empty).
void require_brick_blocks(std::uint32_t block_size, const std::string& where);

/// Those frames read into memory: the samples that size estimates encode.
std::vector<Volume> evenly_spaced_frames(const datasets::SeriesReader& series, std::size_t frames,
                                         std::size_t count);

/// Frames of fewer bricks (all levels) than this many per thread are coded side by side
/// (for_each_side_by_side): a frame's serial parts — reading, extraction, packing, the bricks
/// left when the others are done — leave threads idle when a few bricks share them.
constexpr std::size_t side_by_side_bricks_per_thread = 4;

/// The bricks of a frame of `dims` in bricks of `shape`, all levels of its octree.
std::uint64_t frame_bricks(const Dims& dims, format::BrickShape shape);

/// What the encoder holds per frame of a stretch with keyframe gaps: the frame and the original
/// voxels of every brick of its octree.
double stretch_bytes_per_frame(const Dims& dims, format::BrickShape shape);

/// Whether frames of `dims` in bricks of `shape` are coded side by side, one thread each (a few
/// bricks a frame, and more than one thread).
bool frames_side_by_side(const Dims& dims, format::BrickShape shape);

/// How many frames are coded side by side at once: one per thread.
std::size_t side_by_side_frames();

/// How many frames the encoder codes ahead of its stretches, side by side (4 a thread, so that the
/// threads end together), where `memory` bytes hold them and the stretch of gap + 1 frames, each
/// frame counted twice its stretch_bytes_per_frame (its coding's buffers); fewer than 2: none.
std::size_t side_by_side_batch(const Dims& dims, format::BrickShape shape, std::uint32_t gap,
                               std::uint64_t memory);

/// fn(0) … fn(n − 1), the calls shared among the threads, each on one (the OpenMP regions inside
/// run on the calling thread alone; n = 1: fn(0) with all threads). Rethrows the first exception
/// after every call has ended.
void for_each_side_by_side(std::size_t n, const std::function<void(std::size_t)>& fn);

}  // namespace volreel::encoder::detail
