// tour_run.hpp: one run of `volreel bench stream`'s tour with one priority policy — every frame
// streamed and drawn by loop::CpuFrameLoop on the tour's clock (run_tour) — and its measurement
// after the timed loop against the ground truth (measure): each frame's image PSNR, SSIM, popping
// and seam error, a few side-by-side PNGs, then summarize().
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/tour.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/time_step.hpp"
#include "volreel/stream/priorities.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/stream/selection.hpp"
#include "volreel/stream_bench/run_summary.hpp"

namespace volreel::stream_bench {

/// Progress of a long step: (done, total, status), once per frame.
using Progress = std::function<void(double done, double total, const std::string& status)>;

/// Ground truth: the original series (or the container's finest level, each time step decoded as
/// the player draws it).
class GroundTruth {
 public:
  /// `series` may be null (the container's own finest level). Throws InputError naming --series
  /// when the series' dims differ from the container's or it has fewer frames.
  GroundTruth(const format::Container& container, std::unique_ptr<datasets::SeriesReader> series);

  bool original() const { return series_ != nullptr; }
  const cpu_render::VolumeGeometry& geometry() const { return geometry_; }

  /// Frame t at the finest level. A few frames are kept; frame `keep` is never evicted, so a
  /// reference to it stays valid.
  const std::vector<float>& frame(std::size_t t,
                                  std::size_t keep = std::numeric_limits<std::size_t>::max());
  /// The reference image at `playhead`: the two frames around it, blended linearly.
  cpu_render::RgbaImage render(double playhead, const player::OrbitCamera& camera,
                               const cpu_render::TransferFunction& tf,
                               const cpu_render::RenderOptions& options);

 private:
  const format::Container& container_;
  std::unique_ptr<datasets::SeriesReader> series_;
  cpu_render::VolumeGeometry geometry_;
  std::map<std::size_t, std::vector<float>> cache_;
  format::TimeStepDecoder steps_;  ///< the container's time steps, as the player draws them
};

struct RunSetup {
  const format::Container* container = nullptr;
  const stream::SpatialIndex* index = nullptr;  ///< built once, copied into each run's scheduler
  std::size_t index_errors = 0;                 ///< frames the index left out (printed once)
  const cpu_render::Tour* tour = nullptr;
  std::optional<cpu_render::TransferFunction> transfer;
  stream::SchedulerSettings settings;  ///< atlas_slots: the atlas's slot count
  cpu_render::RenderOptions render;
  int width = 0, height = 0;
  double simulated_fps = 0;  ///< > 0: the simulated clock at this frame rate; 0: the wall clock
};

/// "patent" or "nearest".
const char* policy_name(stream::PriorityPolicy policy);

/// Target nodes drawn exactly as with everything loaded: both picks at full detail and from the
/// time steps with data nearest the playhead on each side, recomputed from the scheduler's atlas
/// with the same view traversal and selection as its update(). `view` and `resident` are scratch.
std::uint32_t current_target_nodes(const stream::StreamScheduler& scheduler,
                                   const player::OrbitCamera& camera, double playhead,
                                   stream::ViewTraversal& view,
                                   stream::ResidentKeyframes& resident);

/// Plays the setup's tour with `policy` until its end; the scheduler's warnings go to stderr.
RunResult run_tour(const RunSetup& setup, stream::PriorityPolicy policy, const Progress& progress);

/// The ground truth of every frame of `run` (its image PSNR and SSIM, its popping against the
/// previous frame in time order and its seam error: popping_rms, seam_rms with the frame's
/// lod_map), PNGs (streamed | ground truth) of every png_every-th frame (0: around each seek and
/// the last) under out/frames_<policy>/, then summarize(run, seeks).
void measure(RunResult& run, const RunSetup& setup, GroundTruth& truth,
             const std::vector<std::pair<double, double>>& seeks, const std::filesystem::path& out,
             std::size_t png_every, const Progress& progress);

}  // namespace volreel::stream_bench
