// frame_loop.hpp: volreel's per-frame streaming loop behind one interface (docs/design.md,
// "Streaming", steps 1–7): for every rendered frame, the stream scheduler's update (priorities,
// requests, arrivals, atlas slots, the array-encoded SVO), the decode of the arrived bricks into
// their atlas slots (a bad brick's slot filled with the sequence's lowest value, so it shows as
// background), the rendering, and the retirement of finished frames. Two implementations:
//   - loop::CpuFrameLoop (cpu_frame_loop.hpp): CPU reference decoder and renderer, no Vulkan;
//   - vulkan_render::VulkanFrameLoop: GPU decode into the atlas and the Vulkan ray caster
//     (vulkan_render::open_frame_loop opens either).
// `volreel render`, `volreel bench play`, `volreel bench stream` and the player window drive it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/scheduler.hpp"

namespace volreel::loop {

/// A rendered frame's number (from 1): the scheduler's frame number and the read_back() handle.
using Ticket = std::uint64_t;

struct FrameLoopOptions {
  /// Scheduler settings; atlas_slots is replaced by the atlas's slot count.
  stream::SchedulerSettings scheduler;
  std::uint64_t atlas_bytes = std::uint64_t{256} << 20;  ///< atlas memory (16-bit voxels)
  int width = 512, height = 512;     ///< output image size, pixels (≥ 1; resize() changes it)
  cpu_render::RenderOptions render;  ///< step, background, termination
  /// Skip what the transfer function hides: leaf regions (histograms) and atlas blocks (ranges).
  bool transfer_culling = true;
  bool pipelined = false;  ///< overlap the next frame's CPU work with this frame's GPU work

  /// Where the Vulkan loop decodes bricks: automatic (on the CPU with a CPU Vulkan
  /// implementation such as lavapipe, where the reference decoder is several times faster than
  /// the compute shader; in the compute shader on a GPU), gpu (the compute shader) or cpu (the
  /// reference decoder, texels copied into the atlas). The CPU loop always decodes on the CPU.
  enum class Decode { automatic, gpu, cpu };

  /// Read by the Vulkan loop only.
  struct Gpu {
    Decode decode = Decode::automatic;
    std::uint64_t staging_bytes = std::uint64_t{8} << 20;  ///< one decoder staging buffer
    std::uint32_t frames_in_flight = 2;                    ///< ray caster ring entries (≥ 1)
  } gpu;
};

/// Where one frame's time went, milliseconds.
struct FrameTimings {
  double schedule_ms = 0;  ///< StreamScheduler::update (CPU)
  double upload_ms = 0;    ///< staging and submitting the decode batch (CPU; 0 on the CPU loop)
  double decode_ms = 0;    ///< decoding the bricks (CPU), or waiting for the GPU decode (0 when
                           ///< pipelined)
  double render_ms = 0;    ///< rendering (CPU; GPU timestamps, or wall time where the queue has
                           ///< none; 0 when pipelined)
  double frame_ms = 0;     ///< the whole frame() call
};

struct FrameReport {
  Ticket ticket = 0;
  stream::StreamStats stats;
  FrameTimings timings;
  std::vector<std::string> new_errors;  ///< scheduler and decode problems of this frame
};

class FrameLoop {
 public:
  virtual ~FrameLoop() = default;

  /// One frame at `playhead` (keyframe units) seen by `camera` (its size must be the output's)
  /// through `transfer`. With `readback`, read_back(report.ticket) gives the image (the CPU loop
  /// always keeps the last one).
  virtual FrameReport frame(const player::OrbitCamera& camera, double playhead,
                            const cpu_render::TransferFunction& transfer,
                            bool readback = false) = 0;
  /// The scheduler's update and the decode of what arrived, without rendering: for waiting until
  /// what a frame needs has arrived before drawing it. The next frame() draws it. No ticket
  /// (report.ticket is 0).
  virtual FrameReport stream(const player::OrbitCamera& camera, double playhead) = 0;
  /// The image of a recent frame rendered with readback (waits for it). Throws
  /// std::invalid_argument for a frame whose image is not kept.
  virtual cpu_render::RgbaImage read_back(Ticket ticket) const = 0;
  /// Waits for every frame and retires it.
  virtual void finish() = 0;
  /// Whether frames can overlap (set_pipelined); the CPU loop is serial.
  virtual bool can_pipeline() const = 0;
  /// Overlap the next frame's CPU work with this frame's GPU work (no effect where serial).
  virtual void set_pipelined(bool on) = 0;
  /// Changes the output size, pixels (waits for every frame first).
  virtual void resize(int width, int height) = 0;
  /// What renders, for report headers: the Vulkan device, or the CPU renderer and its threads.
  virtual std::string describe() const = 0;

  virtual std::uint32_t slot_count() const = 0;  ///< atlas slots
  virtual stream::StreamScheduler& scheduler() = 0;
  virtual const stream::StreamScheduler& scheduler() const = 0;
  virtual const cpu_render::VolumeGeometry& geometry() const = 0;
  virtual const FrameLoopOptions& options() const = 0;
};

/// What wait_for_view reached.
struct ViewWait {
  stream::StreamStats stats;  ///< of the last stream step
  double seconds = 0;         ///< spent waiting
  std::size_t steps = 0;      ///< stream steps taken
  bool complete = false;      ///< every visible node drawn at its target LOD
  bool timed_out = false;     ///< stopped by the timeout
  std::vector<std::string> new_errors;
};

/// Streams (FrameLoop::stream) at a fixed view until every visible node is drawn at its target
/// LOD, nothing more can come (the frame indexes around the playhead read or failed, no request
/// in flight and nothing waiting to be uploaded, as after read errors or with an atlas too small
/// for the view) or `timeout_s` passed. Sleeps briefly
/// while requests are in flight and nothing arrived. `between_steps`, when given, is called after
/// each step (a command's check for Ctrl-C: what it throws ends the wait).
ViewWait wait_for_view(FrameLoop& loop, const player::OrbitCamera& camera, double playhead,
                       double timeout_s, const std::function<void()>& between_steps = {});

}  // namespace volreel::loop
