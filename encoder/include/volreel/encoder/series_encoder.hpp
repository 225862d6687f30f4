// series_encoder.hpp: a whole series -> a container (a NAME.vreel directory, format/SPEC.md):
// the manifest, the dictionary, and every frame (frame_encoder.hpp), resumable after an
// interruption.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <utility>

#include <nlohmann/json.hpp>

#include "volreel/datasets/series.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/encoder/coding_settings.hpp"
#include "volreel/encoder/frame_encoder.hpp"
#include "volreel/encoder/keyframes.hpp"
#include "volreel/encoder/ranks.hpp"
#include "volreel/format/brick_decode.h"

namespace volreel::encoder {

/// EncodeJob::max_keyframe_gap where no option sets it (docs/benchmarks.md, "Keyframes").
inline constexpr std::uint32_t default_max_keyframe_gap = 8;

/// The whole series into a container.
struct EncodeJob {
  CodingSettings coding;                  ///< value range filled in by encode_series if both are 0
  std::filesystem::path dictionary_file;  ///< ksvd: copied into the container as dictionary.bin
  /// ksvd: store the atoms in the container as binary16 (half the dictionary's bytes) and code
  /// against the rounded atoms, so the decoder's atoms are the encoder's; the PSNR barely moves
  /// (docs/benchmarks.md).
  bool half_atoms = true;
  bool resume = false;         ///< keep frames already written and valid
  bool overwrite = false;      ///< replace an existing complete container
  std::size_t max_frames = 0;  ///< 0: every frame
  /// The most time steps between two stored bricks of a node (format/SPEC.md, "Keyframes"): a
  /// node keeps no brick at the steps between where interpolation meets the error rule
  /// (keyframes.hpp). 1: every frame stores every brick. Memory: G + 1 frames with their bricks.
  std::uint32_t max_keyframe_gap = default_max_keyframe_gap;
  nlohmann::json provenance;  ///< stored under "encoder" in the manifest
  /// Code each frame a few planes at a time (SeriesReader::read_slab, FrameEncoder::code_planes)
  /// and measure its delivered error as it is coded, so that no whole frame is ever in memory:
  /// the container is the same. Needs max_keyframe_gap 1 (a stretch with gaps holds its frames).
  bool piecewise = false;
  /// Bytes the encoder may hold (EncodeRequest::memory; 0: default_encode_memory()): frames of a
  /// few bricks are coded side by side, as many ahead of their stretch as fit besides it.
  std::uint64_t memory = 0;
  /// > 0 (dB, ksvd variable rate): every frame's finest-level PSNR over the sequence's value range
  /// at least this (volreel encode --psnr). A frame that falls short is coded again at a smaller
  /// ε (ε·10^(−shortfall/20), a little less), up to max_tolerance_retries times; the next frame
  /// of its keyframe stretch starts from the ε that sufficed, a stretch's end frames from the
  /// job's ε (so that a stretch codes alike whichever process codes it, and when resumed).
  double psnr_target = 0;
  /// The processes that encode together (MPI ranks); null: this process alone. Each codes a
  /// contiguous share of the keyframe stretches and writes their frames; rank 0 prepares the
  /// container and writes the manifest. When frames are coded piecewise and there are fewer
  /// stretches than processes, the processes form as many teams as there are stretches, and a
  /// team codes each frame of its share together, brick by brick (spatial decomposition), its
  /// first process writing. The container is the same for any number of processes.
  const Ranks* ranks = nullptr;
};

/// How often encode_series codes a frame again for EncodeJob::psnr_target.
inline constexpr int max_tolerance_retries = 6;
/// A try for EncodeJob::psnr_target that raises the frame's PSNR by less than this (dB) is the
/// last: a smaller ε no longer buys precision (the payload's finest steps are reached).
inline constexpr double min_retry_gain_db = 0.01;

/// The largest magnitude of an input value: a decoded value is a block mean plus up to 255
/// coefficients (each up to about 15 times the value range), and must stay below
/// format::max_decoded_magnitude. Larger input is refused before anything is written.
inline constexpr double max_input_magnitude = 1e33;

/// The delivered quality of the frames an encode wrote, measured on their finest level decoded by
/// the CPU reference decoder against the frames read (the range: the sequence's value range).
struct DeliveredQuality {
  std::size_t frames = 0;
  double squared_error = 0;  ///< summed over every voxel of every frame measured
  double voxels = 0;
  double max_abs_error = 0;
  double worst_frame_psnr = std::numeric_limits<double>::infinity();
  std::size_t worst_frame = 0;
  std::size_t frames_coded_again = 0;  ///< frames coded more than once for psnr_target
  /// Frames whose tries for psnr_target stopped because a smaller ε raised their PSNR by less
  /// than min_retry_gain_db (the payload's finest steps reached: the frame keeps the try before)
  /// or ε was at its floor (smallest_relative_tolerance of the range).
  std::size_t frames_at_finest = 0;
  double tolerance_scale = 1;  ///< the smallest ε a frame needed, against the job's
  /// PSNR of all measured voxels together, 10·log10(range²/MSE) (∞ when lossless).
  double sequence_psnr(double range) const;
};
struct EncodeSummary {
  std::size_t frames = 0, encoded = 0, skipped = 0;
  std::uint64_t container_bytes = 0;
  double bps = 0;
  double seconds = 0;          ///< encoding only (skipped frames excluded); the slowest process's
  std::size_t processes = 1;   ///< that coded frames together (EncodeJob::ranks)
  std::size_t team_size = 1;   ///< the most processes that coded one frame together
  double process_seconds = 0;  ///< seconds summed over the processes (the parts below are too)
  /// Frames coded at once, side by side, one thread each (frames of a few bricks); the parts
  /// below are then each frame's, summed: thread seconds.
  std::size_t frames_at_once = 1;
  double mvoxels_per_s = 0;
  double unquantized_squared_error = 0, quantized_squared_error = 0;  ///< FrameStats', summed
  ByteBreakdown breakdown;                                            ///< of the frames encoded
  std::array<std::size_t, 256> sparsity_histogram{};                  ///< FrameStats', summed
  std::array<std::size_t, VR_MEAN_BITS + 1> mean_bits_histogram{};    ///< FrameStats', summed
  std::array<std::size_t, 17> coef_bits_histogram{};                  ///< FrameStats', summed
  std::uint64_t code_bits = 0;                                        ///< FrameStats', summed
  std::size_t split_bricks = 0;                                       ///< FrameStats', summed
  std::size_t blocks_over_bound = 0;                                  ///< FrameStats', summed
  double seconds_pyramid = 0, seconds_bricks = 0, seconds_omp = 0, seconds_quantize = 0;

  /// The PSNR lost to quantization over the frames encoded, 10·log10(quantized / unquantized
  /// squared error), in dB; 0 when no block was sparse-coded.
  double quantization_loss_db() const;
  /// ByteBreakdown::finest_owned_codes in bits per voxel of the container, when this run wrote
  /// every frame (the container's bytes are then all accounted for); std::nullopt otherwise.
  std::optional<double> finest_owned_codes_bps() const;
  DeliveredQuality delivered;  ///< of the frames encoded (not of those already there)
  /// Of the frames encoded: the bricks stored, and the nodes of their trees left without a brick
  /// (drawn by interpolation between their keyframes).
  std::size_t bricks_stored = 0, nodes_interpolated = 0;
  /// The settings the frames were coded with (value range and ε set).
  CodingSettings coding;
};
/// Writes OUT (a NAME.vreel directory). Frames go to temporary names renamed when complete; the
/// manifest is rewritten after each frame. Progress: frames done, total, status with MVoxel/s.
/// Throws InputError/FormatError.
EncodeSummary encode_series(const datasets::SeriesReader& series, const std::filesystem::path& out,
                            const EncodeJob& job, const Progress& progress = {});

/// The size of the manifest.json that encode_series writes for the first `frames` frames of a
/// series coded with `coding` (value range set), the job's keyframe gap and provenance, and a
/// dictionary of `atom_count` atoms, before anything is coded: the same manifest with every frame
/// and the dictionary listed (their sizes given a megabyte's digits, a variable-rate ε not chosen
/// yet a double's). The rate search counts it.
std::uint64_t estimated_manifest_bytes(const datasets::SeriesInfo& info, std::size_t frames,
                                       const CodingSettings& coding, std::uint32_t max_keyframe_gap,
                                       const nlohmann::json& provenance, std::uint32_t atom_count);

/// Throws InputError when `out` cannot take a new container: it is there and not a directory, it
/// holds a container and neither `resume` nor `overwrite` is given, or it holds files a container
/// does not (other files in frames/, a manifest.json or dictionary.bin not of a container), which
/// encode would replace. encode() checks this before
/// training and rate control, so that a name already taken is refused before the long work.
void refuse_existing_output(const std::filesystem::path& out, bool resume, bool overwrite);

/// Where encode() writes a container that replaces the one at `out` (--overwrite over a
/// container, or --resume of such a replacement interrupted): OUT/.volreel-new, a container of its
/// own, moved over OUT's manifest, dictionary and frames by commit_replacement once it is
/// complete. Until then the old container stays whole and readable.
std::filesystem::path replacement_folder(const std::filesystem::path& out);

/// Whether an encode into `out` replaces the container there, writing the new one in
/// replacement_folder(out): --overwrite over a container, or --resume of such a replacement.
bool replaces_container(const std::filesystem::path& out, bool overwrite, bool resume);

/// Whether replacement_folder(out) holds a complete container (its manifest says so).
bool complete_replacement(const std::filesystem::path& out);

/// Moves the complete container in replacement_folder(out) over out's (its frames/,
/// dictionary.bin and manifest.json; the manifest last, so that out holds no manifest while the
/// frames are swapped) and removes the replacement folder with the old frames. Other files in
/// out are left alone. A move that stopped halfway (out without a manifest) is finished by
/// calling it again. Throws InputError naming both folders when a move fails.
void commit_replacement(const std::filesystem::path& out);

/// Throws InputError naming `source` (the series) when a value of [value_min, value_max] is beyond
/// max_input_magnitude.
void check_value_range(double value_min, double value_max, const std::string& source);

/// Value range of the first `frames` frames (0: all); with ranks, each process reads its share.
std::pair<double, double> value_range(const datasets::SeriesReader& series, std::size_t frames,
                                      const Progress& progress = {},
                                      const Ranks& ranks = single_process());

}  // namespace volreel::encoder
