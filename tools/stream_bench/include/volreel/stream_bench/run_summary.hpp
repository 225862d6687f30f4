// run_summary.hpp: what `volreel bench stream` records of a run of its tour with one priority
// policy — per rendered frame (FrameRecord), per seek (SeekResult) and per run (RunResult) — and
// summarize(), which turns a run's frame records into its averages and the time from each seek to
// full quality.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "volreel/image/image.hpp"
#include "volreel/stream/scheduler.hpp"

namespace volreel::stream_bench {

/// Image PSNR of identical images is infinite; means count such a frame as this many dB.
constexpr double psnr_cap_db = 100.0;

struct FrameRecord {
  double time = 0, playhead = 0;  ///< tour seconds; keyframe units
  stream::StreamStats stats;
  double update_ms = 0, decode_ms = 0, render_ms = 0, frame_ms = 0;
  double measure_ms = 0;             ///< the bench's own bookkeeping (current_target_nodes)
  bool root_resident = false;        ///< a root brick has arrived by this frame
  std::uint32_t current_nodes = 0;   ///< target nodes at target LOD with the right keyframes
  double fraction_current = 0;       ///< current_nodes / target nodes (1 when none)
  std::uint64_t bytes_uploaded = 0;  ///< since the start: payload bytes decoded into the atlas
  image::Image image;
  double psnr = 0, ssim = 0;  ///< against the ground truth, dB (may be infinite) and [−1, 1]
};

struct SeekResult {
  double time = 0, keyframe = 0;
  /// Seconds until every target node is drawn as with everything loaded (target LOD and the
  /// keyframes around the playhead); NaN: not reached before the next seek.
  double to_full_quality = std::numeric_limits<double>::quiet_NaN();
  /// Seconds until every target node is at its target LOD (StreamStats, whatever its keyframes).
  double to_full_lod = std::numeric_limits<double>::quiet_NaN();
};

struct RunResult {
  std::string name;
  std::vector<FrameRecord> frames;
  std::vector<SeekResult> seeks;
  double wall_s = 0;
  double first_root_s = std::numeric_limits<double>::quiet_NaN();
  std::size_t errors = 0;
  // Averages.
  double mean_psnr = 0, mean_ssim = 0, min_psnr = 0, mean_fraction = 0, full_lod_share = 0;
  double mean_current = 0, full_quality_share = 0;
  std::size_t frames_with_holes_after_root = 0, hole_frames = 0;
  std::uint32_t max_holes_after_root = 0;
  double bytes_loaded = 0, bytes_uploaded = 0;
  /// Bricks the loader read, and what the container's source transferred meanwhile (requests,
  /// bytes received; 0 for local files) during the timed run.
  std::uint64_t bricks_loaded = 0, loader_reads = 0, transfer_requests = 0, transfer_bytes = 0;
  double mean_update_ms = 0, mean_decode_ms = 0, mean_render_ms = 0, mean_frame_ms = 0;
};

/// Fills the run's averages from its frames (PSNR capped at psnr_cap_db in the mean; the bytes
/// are the last frame's totals) and appends one SeekResult per seek: `seeks` holds (tour time,
/// keyframe) pairs in time order; a seek's times count from its first frame at or after it
/// until the next seek.
void summarize(RunResult& run, const std::vector<std::pair<double, double>>& seeks);

}  // namespace volreel::stream_bench
