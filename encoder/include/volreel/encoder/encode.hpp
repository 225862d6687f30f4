// encode.hpp: the whole encode as `volreel encode` runs it, for any front end (the command line,
// the Python module): the value range, the dictionary (given, the container's own when resuming,
// the DCT basis, or trained), ε (given, from a PSNR or a size target), and the series written to a
// container (series_encoder.hpp).
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "volreel/datasets/series.hpp"
#include "volreel/encoder/coding_settings.hpp"
#include "volreel/encoder/default_dictionary.hpp"
#include "volreel/encoder/series_encoder.hpp"
#include "volreel/encoder/tolerance.hpp"

namespace volreel::encoder {

struct EncodeRequest {
  /// How bricks are coded; encode() sets the value range, ε and zfp's accuracy, and the brick
  /// size when it is 0 (format::choose_brick_shape).
  CodingSettings coding;
  /// What ε is asked to be (ksvd): tolerance, PSNR (also every frame's target,
  /// EncodeJob::psnr_target) or a size.
  ToleranceRequest tolerance;
  /// zfp: the absolute error per brick (default: range · 1e-3).
  std::optional<double> zfp_accuracy;
  /// ksvd: a dictionary file, "dct" for the DCT basis alone, or empty: train one (on resume, the
  /// container's own).
  std::string dictionary;
  /// Training a dictionary: K (0: chosen by the container size it gives).
  int atoms = 0;
  bool half_atoms = true;  ///< the container stores the atoms in binary16
  bool resume = false, overwrite = false;
  std::size_t max_frames = 0;  ///< 0: every frame
  /// The most time steps between keyframes of a node. Unset: default_max_keyframe_gap, lowered
  /// until G + 1 frames take at most `memory`; 1 with a size target (its search codes whole
  /// frames) and for frames coded piecewise.
  std::optional<std::uint32_t> max_keyframe_gap;
  /// The bytes the encode may hold for frames (0: half the usable memory). A frame that does
  /// not fit whole (whole_frame_bytes) is coded piecewise (EncodeJob::piecewise), a few planes at a
  /// time, without keyframe gaps; that needs a dictionary given (training and --bps read whole
  /// frames). Frames of a few bricks are coded side by side, as many as fit (EncodeJob::memory).
  std::uint64_t memory = 0;
  nlohmann::json provenance;  ///< stored under "encoder" in the manifest, with the program's
  /// The processes that encode together (MPI ranks); null: this process alone. Each reads its
  /// share of the frames for the value range; rank 0 trains the dictionary and chooses ε, and
  /// the others receive them; then each codes its share of the frames (EncodeJob::ranks). Every
  /// process must call encode() with the same request.
  const Ranks* ranks = nullptr;
};

/// What encode() tells its caller as it goes; every member may be empty.
struct EncodeEvents {
  /// A line worth printing ("value range [a, b]", "using the dictionary of K = 256 atoms").
  std::function<void(const std::string&)> message;
  /// A long stage starts ("value range" in "frames", "coreset", "rate control", "encoding"); the
  /// Progress returned receives its progress until stage_done.
  std::function<Progress(const std::string& stage, const std::string& unit)> stage;
  std::function<void()> stage_done;
  /// Training without K: each K as soon as it is measured or skipped.
  DictionaryCandidateCallback candidate;
  /// ε chosen (ksvd), with the dictionary's K.
  std::function<void(const ToleranceChoice&, const CodingSettings&, std::uint32_t atoms)>
      tolerance_chosen;
};

/// The keyframe gap an encode of frames of `dims` in bricks of `shape` uses when none is asked
/// for (see EncodeRequest::max_keyframe_gap) with `memory` bytes (0: half the machine's);
/// `lowered` says whether memory lowered it.
std::uint32_t default_keyframe_gap(const Dims& dims, format::BrickShape shape, bool size_target,
                                   std::uint64_t memory = 0, bool* lowered = nullptr);
/// What coding a frame of `dims` whole holds: the frame, and its finest level decoded to measure
/// it (float32 each). Frames larger than EncodeRequest::memory are coded piecewise.
double whole_frame_bytes(const Dims& dims);
/// EncodeRequest::memory when 0: half of format::detail::usable_memory_bytes (the machine's
/// physical memory, or its container's limit where lower).
std::uint64_t default_encode_memory();

/// How far a container may land from a bps target (EncodeRequest's tolerance.bps): 5 %.
inline constexpr double bps_tolerance = 0.05;

/// The targets an encode asked for that its container misses (none: met, or not asked for).
struct MissedTargets {
  bool psnr = false;       ///< a frame's finest level below the --psnr target
  bool bps = false;        ///< more than bps_tolerance from the --bps target
  bool max_error = false;  ///< coded blocks past the --max-error bound (coding.max_error)
  bool any() const { return psnr || bps || max_error; }
};
/// What `summary` (of an encode asked for `psnr_target` and `bps_target` dB and bps, 0: none)
/// misses.
MissedTargets missed_targets(const EncodeSummary& summary, double psnr_target, double bps_target);

/// Throws InputError where the request's options do not go together (checked by encode before
/// it reads anything; the command line checks them before it opens the input).
void check_request(const EncodeRequest& request);

/// Encodes `series` into the container `out` as asked. With several ranks, only rank 0 should be
/// given events (one progress bar, one report). Temporary dictionary files are removed
/// whatever happens. Throws InputError/FormatError with what was wrong.
EncodeSummary encode(const datasets::SeriesReader& series, const std::filesystem::path& out,
                     EncodeRequest request, const EncodeEvents& events = {});

}  // namespace volreel::encoder
