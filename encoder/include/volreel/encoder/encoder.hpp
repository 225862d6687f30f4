// encoder.hpp: one frame -> a frame file (MTV-Player §3.2): the brick hierarchy (34³ interiors
// with a 1-voxel apron, coarser levels averaging 2×2×2 voxels — Cesium patent [0031] — up to one
// root brick), sparse coding of each brick's 6³ blocks against the dictionary with quantization
// (or zfp per brick), node table with bottom-up histograms; and a whole series -> a container.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::encoder {

namespace detail {
struct QuantizeOptions;
}

/// How variable rate chooses the number of atoms of each block (both driven by ε).
enum class VariableRateRule {
  /// Rate-distortion optimal (Lagrangian): add the next atom while it lowers the block's squared
  /// error by at least lagrangian_factor·m·ε² (m = 216 values). Every code costs the same 16 bits,
  /// so this gives every block the same distortion-per-bit slope, which minimises the total
  /// squared error (hence maximises PSNR) for the total size: smooth blocks get few atoms, rough
  /// blocks many.
  lagrangian,
  /// Add atoms until the block's RMS error is at most ε (equal error per block; the paper's rule).
  tolerance,
};

/// How bricks are coded.
struct CodingSettings {
  format::Codec codec = format::Codec::ksvd;
  double tolerance = 0;  ///< ksvd variable rate: ε (data units), see VariableRateRule
  VariableRateRule rule = VariableRateRule::lagrangian;
  /// Lagrangian rule: the minimum gain of an atom, as a fraction of m·ε² (> 0). Only the product
  /// with ε² matters, so this sets what ε means: at 0.25, on turbulence-128 between 0.26 and
  /// 0.6 bps, the PSNR at a given ε is about that of the ε rule and above 20·log10(range/ε), so
  /// that --psnr keeps its meaning (the ε rule's bound per block no longer holds).
  double lagrangian_factor = 0.25;
  /// Lagrangian rule: weigh each block's atom gains by the share of its voxels that the decoder
  /// takes from it (its brick's interior, inside the level). The rest are the apron, a copy of a
  /// neighbour's interior coded there, and padding outside the volume: a block of padding only
  /// weighs as one voxel (1/216), so it gets atoms only where they are 216 times cheaper.
  bool weight_owned_voxels = true;
  /// Lagrangian rule: the levels above the finest are coded to ε·F^d, d levels up (their atom
  /// gains weigh 1/F^(2d), their means' step grows by F^d). A coarse level is drawn only where its
  /// voxels, 2^d times as wide, are too small on screen for the finer one to matter, and it already
  /// differs from the full-resolution data by its downsampling: on turbulence-128 by 2.5·ε one level
  /// up and 5.2·ε two up (ε = 0.018, RMS against the full-resolution frame). At F = 2 the coding
  /// error grows with that difference and stays below it; the coarse levels' share of the bytes
  /// falls from 24 % to 14 % (10 % smaller containers, the finest level unchanged), and bench stream's
  /// image PSNR is unchanged on a fast link and higher on slow ones, where smaller coarse bricks
  /// arrive sooner. 1: every level to ε. (Measured for d ≤ 2: turbulence-128 has three levels;
  /// on a self-similar field the downsampling difference keeps doubling per level.) The ε rule and
  /// fixed rate ignore it.
  double level_tolerance_factor = 2.0;
  int fixed_sparsity =
      0;               ///< ksvd fixed rate: exactly min(S, needed) atoms per block (0: variable)
  int max_atoms = 15;  ///< Smax ≤ 15 (4-bit field)
  /// ksvd: which atom each pursuit step adds (both rates). ORMP (the atom that lowers the block's
  /// squared error most) needs fewer atoms than OMP (the most correlated one) for the same error;
  /// see dictionary::AtomSelection for the measured gain.
  dictionary::AtomSelection selection = dictionary::AtomSelection::error;
  /// ksvd: the bits b of each brick's quantized block means (format/SPEC.md, word 4). -1: variable
  /// rate gives each brick the fewest bits (0..12) whose step over the span of its block means is
  /// at most mean_step_factor·ε_l (ε_l: the brick's level's tolerance, see level_tolerance_factor),
  /// fixed rate (no ε) 12 bits; 0..12: every brick exactly b bits.
  int mean_bits = -1;
  /// The mean step as a fraction of ε. A mean off by e adds 216·e² to its block's squared error,
  /// so halving the step gains 13.5·step² for one more bit per block; the Lagrangian rule buys
  /// 0.25·216·ε² per 16-bit code, and the two slopes are equal at a step of ε/2. Measured on
  /// turbulence-128 (8 frames, ε = 0.0897 and 0.0224): against the PSNR that ε buys for the same
  /// bytes, 0.25, 0.35, 0.7 and 1 all lose to 0.5 (by 0.05 to 0.3 dB).
  double mean_step_factor = 0.5;
  double zfp_accuracy = 0;  ///< zfp fixed-accuracy tolerance (data units)
  /// Quantize coefficients one at a time, re-solving the least-squares fit of the block's later
  /// coefficients against the error of the ones already quantized ("quantize inside the pursuit").
  bool refit_quantization = true;
  /// Variable rate, ε rule: while a block's quantized error exceeds ε, add the atom most correlated with
  /// the quantized residual (up to Smax) and quantize again ("quantization inside the pursuit").
  /// Off by default: on turbulence it recovers 0.26 dB of the quantization loss for 6.7 % more
  /// bytes (about neutral at equal bps) and halves the encoding speed.
  bool extend_pursuit = false;
  /// Choose each brick's 6-bit coefficient interval by least squared error (clipping up to 8
  /// extreme coefficients at either end) instead of [min, max].
  bool optimize_interval = true;
  double value_min = 0, value_max = 0;  ///< the sequence's value range, for node histograms
};

/// The levels of a frame's brick hierarchy as dense volumes: [0] the root level … [L−1] the frame.
struct Pyramid {
  std::vector<format::LevelGeometry> geometry;
  std::vector<std::vector<float>> levels;
};
/// Level l−1 voxel (i,j,k) = mean of level-l voxels (2i+a, 2j+b, 2k+c), a,b,c ∈ {0,1}, indices
/// clamped to the level (edge replication where a size is odd).
Pyramid build_pyramid(const Volume& frame);
/// Stored voxels of brick (x, y, z) of level l into out (36³, x fastest): level voxel
/// (34x − 1 + a, 34y − 1 + b, 34z − 1 + c) for a, b, c in [0, 36), clamped to the level.
void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out);

/// Where a frame file's bytes go. The parts from frame_tables to zfp_streams sum to the file's
/// size; the last three are shares of the payload parts.
struct ByteBreakdown {
  std::size_t frame_tables = 0;     ///< header, level table, node table, brick offsets
  std::size_t constant_bricks = 0;  ///< 4-byte values
  std::size_t brick_headers = 0;    ///< ksvd: 20 bytes per coded brick (dequantization, mean bits)
  std::size_t block_entries = 0;    ///< ksvd: 4 + b bits per block (b-bit mean, 4-bit sparsity)
  std::size_t codes = 0;            ///< ksvd: 2 bytes per code (10-bit atom, 6-bit value)
  std::size_t alignment = 0;        ///< ksvd: payloads padded to a multiple of 4 bytes
  std::size_t zfp_streams = 0;      ///< zfp bricks
  std::size_t coarse_levels = 0;    ///< payload bytes of the levels above the finest
  /// Payload bytes in proportion to the stored voxels that are aprons or padding (outside the
  /// level), brick by brick: an estimate of what the brick layout costs.
  double aprons_and_padding = 0;
  /// Code bytes of the finest level, each block's weighted by the share of its voxels that are
  /// the level's own (interior, inside the volume): all a frame would cost if block means, tables,
  /// coarse levels, aprons and padding were free, at the same codes.
  double finest_owned_codes = 0;
  ByteBreakdown& operator+=(const ByteBreakdown& o);
  std::size_t total() const {
    return frame_tables + constant_bricks + brick_headers + block_entries + codes + alignment +
           zfp_streams;
  }
};

struct FrameStats {
  std::size_t bricks = 0, constant_bricks = 0, empty_nodes = 0;
  std::size_t blocks = 0, codes = 0;  ///< coded blocks and coefficients (ksvd)
  std::size_t bytes = 0;
  double seconds = 0;
  double seconds_pyramid = 0, seconds_bricks = 0, seconds_omp = 0,
         seconds_quantize = 0;  ///< parts of seconds
  /// Squared error summed over every value of every coded block (all levels, aprons included):
  /// of the unquantized sparse approximation, and of what the payload decodes to. Their ratio is
  /// the PSNR lost to quantization: 10·log10(quantized / unquantized).
  double unquantized_squared_error = 0, quantized_squared_error = 0;
  ByteBreakdown breakdown;
  std::array<std::size_t, 16> sparsity_histogram{};  ///< coded blocks (ksvd) by atom count
  std::array<std::size_t, 13> mean_bits_histogram{};  ///< coded bricks (ksvd) by mean bits
};

/// Encodes frames with fixed settings and dictionary; safe to use from one thread at a time
/// (it parallelizes inside with OpenMP).
class FrameEncoder {
 public:
  /// dictionary: required for ksvd (K ≤ 1024, M = 6). Throws InputError on bad settings.
  FrameEncoder(const dictionary::Dictionary* dictionary, CodingSettings settings);
  /// Frame t -> the frame file's bytes.
  std::vector<std::byte> encode(std::size_t t, const Volume& frame,
                                FrameStats* stats = nullptr) const;
  /// One stored brick (36³ values, x fastest) -> its payload: a 4-byte constant, a ksvd payload
  /// or a zfp stream (the same coding encode() applies to every brick).
  std::vector<std::byte> encode_brick(std::span<const float> brick) const;
  const CodingSettings& settings() const { return settings_; }
  /// The Lagrangian rule's minimum atom gain, lagrangian_factor·m·ε² (data units²); 0 for the
  /// other rules and codecs.
  double atom_gain_threshold() const;

 private:
  const dictionary::Dictionary* dictionary_;
  CodingSettings settings_;
  std::shared_ptr<const dictionary::BatchOmp> omp_;
  detail::QuantizeOptions quantize_options() const;
};

/// The whole series into a container.
struct EncodeJob {
  CodingSettings coding;                  ///< value range filled in by encode_series if both are 0
  std::filesystem::path dictionary_file;  ///< ksvd: copied into the container as dictionary.bin
  /// ksvd: store the atoms in the container as binary16 (half the dictionary's bytes) and code
  /// against the rounded atoms, so the decoder's atoms are the encoder's. On turbulence-128 (K =
  /// 1024, 64 frames) this saves 0.026 bps and changes the PSNR by less than 0.01 dB.
  bool half_atoms = true;
  bool resume = false;                    ///< keep frames already written and valid
  bool overwrite = false;                 ///< replace an existing complete container
  std::size_t max_frames = 0;             ///< 0: every frame
  nlohmann::json provenance;              ///< stored under "encoder" in the manifest
};
struct EncodeSummary {
  std::size_t frames = 0, encoded = 0, skipped = 0;
  std::uint64_t container_bytes = 0;
  double bps = 0;
  double seconds = 0;  ///< encoding only (skipped frames excluded)
  double mvoxels_per_s = 0;
  double unquantized_squared_error = 0, quantized_squared_error = 0;  ///< FrameStats', summed
  ByteBreakdown breakdown;                                            ///< of the frames encoded
  std::array<std::size_t, 16> sparsity_histogram{};                   ///< FrameStats', summed
  std::array<std::size_t, 13> mean_bits_histogram{};                  ///< FrameStats', summed
  double seconds_pyramid = 0, seconds_bricks = 0, seconds_omp = 0, seconds_quantize = 0;
};
/// Writes OUT (a NAME.vreel directory). Frames go to temporary names renamed when complete; the
/// manifest is rewritten after each frame. Progress: frames done, total, status with MVoxel/s.
/// Throws InputError/FormatError.
EncodeSummary encode_series(const datasets::SeriesReader& series, const std::filesystem::path& out,
                            const EncodeJob& job, const Progress& progress = {});

/// Value range of the first `frames` frames (0: all).
std::pair<double, double> value_range(const datasets::SeriesReader& series, std::size_t frames,
                                      const Progress& progress = {});

/// Rate control for --bps: ε such that the container's bps, estimated from `sample_frames` evenly
/// spaced frames (encoded in memory) plus the dictionary, is within `relative` of target_bps.
/// Returns ε and the estimated bps.
struct RateSearch {
  double tolerance = 0, estimated_bps = 0;
  int iterations = 0;
};
RateSearch search_tolerance(const datasets::SeriesReader& series,
                            const dictionary::Dictionary& dictionary,
                            std::uint64_t dictionary_bytes, CodingSettings settings,
                            double target_bps, std::size_t frames, std::size_t sample_frames = 3,
                            double relative = 0.03, const Progress& progress = {});

}  // namespace volreel::encoder
