// frame_loop.hpp: volreel's per-frame streaming loop on the GPU (docs/design.md, "Streaming",
// steps 1–7): for every rendered frame, the stream scheduler's update (priorities, requests,
// arrivals, atlas slots, the array-encoded SVO), the decode of the arrived bricks into their atlas
// slots (vulkan::AtlasDecoder), the leaf histograms for transfer-function culling, and the ray
// caster (Raycaster). `volreel render`, `volreel bench play` and a windowed player drive it.
//
// Frames in flight: GPU frame numbers are the Raycaster's tickets. A frame's SVO only references
// slots the scheduler will not overwrite before that frame retired; frame() retires every
// completed frame before it asks the scheduler for the next one. With `pipelined`, frame() returns
// right after submitting, so the CPU work of frame N+1 overlaps the GPU work of frame N; without
// it, frame() waits for the decode and the ray casting, which gives an exact time split.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/container.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/atlas_decoder.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan_render/raycaster.hpp"

namespace volreel::vulkan_render {

struct FrameLoopOptions {
  /// Scheduler settings; atlas_slots is replaced by the atlas's slot count.
  stream::SchedulerSettings scheduler;
  std::uint64_t atlas_bytes = std::uint64_t{256} << 20;  ///< GPU memory of the atlas
  vulkan::AtlasFormat atlas_format = vulkan::AtlasFormat::r16_unorm;
  std::uint64_t staging_bytes = std::uint64_t{8} << 20;  ///< one decoder staging buffer
  RaycasterOptions raycaster;                           ///< output size, format, ring
  cpu_render::RenderOptions render;                     ///< step, background, termination
  /// Skip what the transfer function hides: leaf regions (histograms) and atlas blocks (ranges).
  bool transfer_culling = true;
  bool pipelined = false;        ///< overlap the next frame's CPU work with this frame's GPU work
};

/// Where one frame's time went, milliseconds.
struct FrameTimings {
  double schedule_ms = 0;  ///< StreamScheduler::update (CPU)
  double upload_ms = 0;    ///< staging and submitting the decode batch (CPU)
  double decode_ms = 0;    ///< waiting for the GPU decode (0 when pipelined)
  double render_ms = 0;    ///< ray casting on the GPU (timestamps; wall time where the queue has
                           ///< none; 0 when pipelined: ask gpu_milliseconds(ticket) later)
  double frame_ms = 0;     ///< the whole frame() call
};

struct FrameReport {
  Ticket ticket = 0;  ///< the GPU frame (Raycaster ticket)
  stream::StreamStats stats;
  FrameTimings timings;
  std::vector<std::string> new_errors;  ///< scheduler and decode problems of this frame
};

class FrameLoop {
 public:
  /// Indexes the container, creates the atlas (value range: the manifest's with a 1 % margin),
  /// the decoder (with the dictionary) and the ray caster. The context and the container must
  /// outlive the loop. Throws vulkan::Error on Vulkan failures.
  FrameLoop(const vulkan::Context& context, const format::Container& container,
            const FrameLoopOptions& options);
  ~FrameLoop();
  FrameLoop(const FrameLoop&) = delete;
  FrameLoop& operator=(const FrameLoop&) = delete;

  /// One frame at `playhead` (keyframe units) seen by `camera` (its size must be the output's)
  /// through `transfer`. With `readback`, read_back(report.ticket) gives the image.
  FrameReport frame(const player::OrbitCamera& camera, double playhead,
                    const cpu_render::TransferFunction& transfer, bool readback = false);
  /// The image of a recent frame rendered with readback (waits for it).
  cpu_render::RgbaImage read_back(Ticket ticket) const { return raycaster_->read_back(ticket); }
  std::optional<double> gpu_milliseconds(Ticket ticket) const {
    return raycaster_->gpu_milliseconds(ticket);
  }
  /// Waits for every frame and retires it.
  void finish();
  /// The scheduler's output of the last frame (uploads with their payloads, the SVO), e.g. to
  /// mirror the atlas on the CPU in tests.
  const stream::FrameUpdate& last_update() const { return last_update_; }

  /// Changes the output size (waits for every frame first).
  void resize(int width, int height) { raycaster_->resize(width, height); }

  stream::StreamScheduler& scheduler() { return *scheduler_; }
  const stream::StreamScheduler& scheduler() const { return *scheduler_; }
  const Raycaster& raycaster() const { return *raycaster_; }
  Raycaster& raycaster() { return *raycaster_; }
  const vulkan::Atlas& atlas() const { return *atlas_; }
  const vulkan::AtlasDecoder& decoder() const { return *decoder_; }
  const cpu_render::VolumeGeometry& geometry() const { return geometry_; }
  const FrameLoopOptions& options() const { return options_; }
  FrameLoopOptions& options() { return options_; }

 private:
  void retire_completed();
  void decode_uploads(const std::vector<stream::BrickUpload>& uploads,
                      std::vector<std::string>& errors);
  std::uint64_t histogram_of(const stream::KeyframeKey& key) const;

  const vulkan::Context& context_;
  const format::Container& container_;
  FrameLoopOptions options_;
  cpu_render::VolumeGeometry geometry_;
  std::unique_ptr<vulkan::Atlas> atlas_;
  std::unique_ptr<vulkan::AtlasDecoder> decoder_;
  std::unique_ptr<Raycaster> raycaster_;
  std::unique_ptr<stream::StreamScheduler> scheduler_;
  std::vector<std::uint64_t> slot_histograms_;  ///< per atlas slot, its brick's node histogram
  std::vector<std::uint64_t> leaf_histograms_;
  std::vector<std::uint32_t> changed_slots_;
  stream::FrameUpdate last_update_;
  Ticket retired_ = 0;
};

/// Histogram words of each leaf record: the OR of the histograms of the slots of A and B (those
/// with a nonzero weight); slots without a histogram (0) make the leaf's histogram 0 (drawn).
void leaf_histograms(std::span<const std::uint32_t> svo_leaves,
                     std::span<const std::uint64_t> slot_histograms,
                     std::vector<std::uint64_t>& out);

}  // namespace volreel::vulkan_render
