// run_summary.hpp: what `volreel bench stream` records of a run of its tour with one priority
// policy — per rendered frame (FrameRecord), per seek (SeekResult) and per run (RunResult) — and
// summarize(), which turns a run's frame records into its averages and the time from each seek to
// full quality; and the image metrics beyond PSNR and SSIM: popping (popping_rms: how much the
// image error changes from one frame to the next; working-set popping, image_change_rms against
// what the previous working set draws) and the error at level-of-detail seams (lod_boundary,
// seam_rms).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <span>
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
  /// Per pixel of `image` (row-major, width·height values) the data level of the region that
  /// dominated the pixel, 255 for none (background); empty when the renderer gave none.
  std::vector<std::uint8_t> lod_map;
  double psnr = 0, ssim = 0;  ///< against the ground truth, dB (may be infinite) and [−1, 1]
  /// popping_rms of the previous frame in time order and this one (8-bit units); NaN for the
  /// first frame, a pair of different image sizes, or before measure().
  double popping = std::numeric_limits<double>::quiet_NaN();
  /// Working-set popping: image_change_rms of this frame and the image the previous frame's
  /// working set draws at this frame's camera, playhead and transfer function
  /// (loop::CpuFrameLoop::render_previous_working_set): the change due to bricks arriving and
  /// leaving and to blending weights alone, neither the camera's motion nor the data's. NaN for
  /// the first frame and on the wall clock (not measured there: it takes a second render).
  double working_set_popping = std::numeric_limits<double>::quiet_NaN();
  /// seam_rms of this frame with lod_map (8-bit units); NaN without a lod_map, without boundary
  /// pixels, or before measure().
  double seam = std::numeric_limits<double>::quiet_NaN();
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
  /// Popping (FrameRecord::popping) where the working set changed: the quadratic mean (root
  /// mean square, so that a change spread over several frames — a fade — counts less than the
  /// same change at once) and the maximum over the frames i ≥ 1 with a finite popping where
  /// bricks were uploaded or leaves blend (stats.uploads or stats.blended_leaves > 0: a fade
  /// spreads an arrival's change over the frames after it), except the first frame at or after each
  /// seek (a cut: its change is the seek's) and a frame after one with holes (what appears was not
  /// drawn before, as at start-up). Bricks uploaded in a frame are drawn in that same frame's
  /// image, so the jump they cause lies between frame i − 1 and frame i, which is what frame i's
  /// popping measures. popping_frames counts those frames; both values are NaN when there are none.
  double mean_popping = std::numeric_limits<double>::quiet_NaN();
  double max_popping = std::numeric_limits<double>::quiet_NaN();
  std::size_t popping_frames = 0;
  /// The quadratic mean of popping over every frame i ≥ 1 with a finite popping but those left
  /// out above (NaN when there is none): the
  /// baseline that the camera and the data's own motion leave unexplained anyway.
  double mean_popping_all = std::numeric_limits<double>::quiet_NaN();
  /// Working-set popping (FrameRecord::working_set_popping): the quadratic mean and the maximum
  /// over the frames counted in mean_popping_all (a frame where nothing changed counts 0, so that
  /// runs of one tour compare over the same frames), and how many frames that is; NaN when none.
  double mean_working_set_popping = std::numeric_limits<double>::quiet_NaN();
  double max_working_set_popping = std::numeric_limits<double>::quiet_NaN();
  std::size_t working_set_popping_frames = 0;
  /// Mean seam error (FrameRecord::seam) over the seam_frames frames where it is finite (NaN
  /// when there are none).
  double mean_seam = std::numeric_limits<double>::quiet_NaN();
  std::size_t seam_frames = 0;
};

/// Fills the run's averages from its frames (PSNR capped at psnr_cap_db in the mean; popping and
/// seam error over the frames RunResult names; the bytes are the last frame's totals) and appends
/// one SeekResult per seek: `seeks` holds (tour time, keyframe) pairs in time order; a seek's times
/// count from its first frame at or after it until the next seek.
void summarize(RunResult& run, const std::vector<std::pair<double, double>>& seeks);

/// Popping between two consecutive frames: with the error images E = image − reference (per
/// channel, in 8-bit units), the root mean square over every pixel and channel of E − E_previous.
/// The change of the image that the change of the ground truth (the data's motion, the camera's)
/// explains cancels; what remains is the streamed image changing differently from the truth, as
/// when finer bricks arrive. NaN when the two frames' images differ in size or channels. Throws
/// std::invalid_argument when a frame's reference and image differ in size or channels.
double popping_rms(const image::Image& previous_reference, const image::Image& previous_image,
                   const image::Image& reference, const image::Image& image);

/// How much an image changed: the root mean square over every pixel and channel of after −
/// before (8-bit units); NaN when the two differ in size or channels or are empty.
double image_change_rms(const image::Image& before, const image::Image& after);

/// The level-of-detail boundary pixels of `lod_map` (width·height values, row-major, 255: no
/// level): 1 for a pixel p with lod_map[p] != 255 such that a pixel within Chebyshev distance
/// `radius` (inside the image) has a value other than lod_map[p] and other than 255; 0 for every
/// other pixel. Throws std::invalid_argument when lod_map does not hold width·height values or
/// radius is negative.
std::vector<std::uint8_t> lod_boundary(std::span<const std::uint8_t> lod_map, int width, int height,
                                       int radius = 2);

/// Error at level-of-detail seams: how much the image error E = image − reference steps between
/// neighbouring pixels on the boundary — a seam is a step the streamed image has and the ground
/// truth has not. The root mean square, over every pair of horizontally or vertically adjacent
/// pixels that are both in lod_boundary(lod_map, radius) and every channel, of E(p) − E(q), in
/// 8-bit units. A coarse region's error that is smooth across the boundary (blended) scores
/// less than the same error ending in a step. NaN when lod_map is empty or has no such pair. Throws
/// std::invalid_argument when reference and image differ in size or channels, or lod_map is neither
/// empty nor one value per pixel.
double seam_rms(const image::Image& reference, const image::Image& image,
                std::span<const std::uint8_t> lod_map, int radius = 2);

}  // namespace volreel::stream_bench
