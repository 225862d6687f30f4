// volume_renderer.hpp: the player's "stream and render the volume into an image" step behind one
// interface, so the window loop does not care which renderer draws:
//   - the Vulkan ray caster (vulkan_render::VulkanFrameLoop: scheduler → GPU decode into the
//     atlas → ray casting into a storage image, submitted on the context's queue);
//   - the CPU reference renderer (loop::CpuFrameLoop: scheduler → CPU decode into a CpuAtlas →
//     cpu_render::render_svo; the image is uploaded through a staging buffer per frame slot).
// Either's frame loop owns the stream scheduler, so its atlas decides the slot count.
//
// Per frame, on frame slot s ∈ [0, frames in flight) whose previous frame has retired:
//   1. frame(): the scheduler's update and the renderer's work for the frame (CPU work, plus the
//      Vulkan renderer's own submissions, which precede the window's on the same queue);
//   2. record(): commands into the window's command buffer that leave image() readable by a
//      transfer (blit) in image_layout().
#pragma once

#include <vulkan/vulkan.h>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/frame_loop.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/vulkan/context.hpp"

namespace volreel::app::detail {

/// Milliseconds spent in one frame's steps; nullopt where not measured (pipelined GPU work).
struct StepTimes {
  double schedule = 0;           ///< StreamScheduler::update (CPU)
  double upload = 0;             ///< staging/submitting bricks (CPU)
  std::optional<double> decode;  ///< decoding bricks into the atlas
  std::optional<double> render;  ///< ray casting (CPU time, or GPU time of an earlier frame)
};

struct FrameInputs {
  std::uint32_t slot = 0;       ///< frame-in-flight slot
  std::uint64_t gpu_frame = 0;  ///< the window's frame number (from 1)
  player::OrbitCamera camera;   ///< width × height = the volume image size
  double playhead = 0;          ///< keyframe units
  const cpu_render::TransferFunction* transfer = nullptr;
};

struct FrameOutput {
  stream::StreamStats stats;
  StepTimes times;
  std::vector<std::string> new_errors;  ///< scheduler and decode problems of this frame
};

class VolumeRenderer {
 public:
  virtual ~VolumeRenderer() = default;
  /// A short name for the HUD.
  virtual std::string name() const = 0;
  virtual stream::StreamScheduler& scheduler() = 0;
  /// Sets the volume image size (pixels); the caller waited for the device to be idle.
  virtual void resize(std::uint32_t width, std::uint32_t height) = 0;
  virtual FrameOutput frame(const FrameInputs& inputs) = 0;
  virtual void record(VkCommandBuffer commands, std::uint32_t slot) = 0;
  /// The window's frames ≤ gpu_frame have completed.
  virtual void retired(std::uint64_t gpu_frame) = 0;
  virtual VkImage image() const = 0;
  virtual VkImageLayout image_layout() const = 0;
  virtual VkExtent2D extent() const = 0;
  /// Whether frames are overlapped with the GPU (Vulkan) or waited for to measure each step.
  virtual void set_exact_timings(bool exact) { (void)exact; }
};

struct RendererSetup {
  const vulkan::Context* context = nullptr;
  const format::Container* container = nullptr;
  stream::SchedulerSettings scheduler;  ///< atlas_slots is replaced by the atlas's
  std::uint64_t atlas_bytes = 0;        ///< memory budget of the atlas
  std::uint32_t frames_in_flight = 2;
  std::uint32_t width = 1, height = 1;  ///< first image size
  loop::FrameLoopOptions::Decode decode = loop::FrameLoopOptions::Decode::automatic;  ///< Vulkan
};

std::unique_ptr<VolumeRenderer> make_cpu_renderer(const RendererSetup& setup);
std::unique_ptr<VolumeRenderer> make_vulkan_renderer(const RendererSetup& setup);

}  // namespace volreel::app::detail
