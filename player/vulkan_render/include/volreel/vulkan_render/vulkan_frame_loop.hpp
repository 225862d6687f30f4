// vulkan_frame_loop.hpp: volreel's per-frame streaming loop (loop/frame_loop.hpp) on the GPU: the
// stream scheduler's update, the decode of the arrived bricks into their atlas slots
// (vulkan::AtlasDecoder), the leaf histograms for transfer-function culling, and the ray caster
// (Raycaster). open_frame_loop.hpp opens it, or the CPU loop.
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
#include <span>
#include <string>
#include <vector>

#include "volreel/format/container.hpp"
#include "volreel/loop/frame_loop.hpp"
#include "volreel/vulkan/atlas.hpp"
#include "volreel/vulkan/atlas_decoder.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan_render/raycaster.hpp"

namespace volreel::vulkan_render {

class VulkanFrameLoop final : public loop::FrameLoop {
 public:
  /// Indexes the container, creates the atlas (16-bit unorm over the manifest's value range with
  /// a 1 % margin), the decoder (with the dictionary) and the ray caster (rgba8 output). The
  /// context and the container must outlive the loop. Throws vulkan::Error on Vulkan failures.
  VulkanFrameLoop(const vulkan::Context& context, const format::Container& container,
                  const loop::FrameLoopOptions& options);
  /// The same on a context the loop owns (destroyed after everything else).
  VulkanFrameLoop(std::unique_ptr<vulkan::Context> context, const format::Container& container,
                  const loop::FrameLoopOptions& options);
  ~VulkanFrameLoop() override;
  VulkanFrameLoop(const VulkanFrameLoop&) = delete;
  VulkanFrameLoop& operator=(const VulkanFrameLoop&) = delete;

  loop::FrameReport frame(const player::OrbitCamera& camera, double playhead,
                          const cpu_render::TransferFunction& transfer,
                          bool readback = false) override;
  loop::FrameReport stream(const player::OrbitCamera& camera, double playhead) override;
  cpu_render::RgbaImage read_back(Ticket ticket) const override {
    return raycaster_->read_back(ticket);
  }
  void finish() override;
  bool can_pipeline() const override { return true; }
  void set_pipelined(bool on) override { options_.pipelined = on; }
  /// Transfer-function culling from the next frame on (FrameLoopOptions::transfer_culling).
  void set_transfer_culling(bool on) { options_.transfer_culling = on; }
  void resize(int width, int height) override;
  std::string describe() const override;

  std::uint32_t slot_count() const override { return atlas_->slot_count(); }
  stream::StreamScheduler& scheduler() override { return *scheduler_; }
  const stream::StreamScheduler& scheduler() const override { return *scheduler_; }
  const cpu_render::VolumeGeometry& geometry() const override { return geometry_; }
  const loop::FrameLoopOptions& options() const override { return options_; }

  std::optional<double> gpu_milliseconds(Ticket ticket) const {
    return raycaster_->gpu_milliseconds(ticket);
  }
  /// The scheduler's output of the last frame (uploads with their payloads, the SVO), e.g. to
  /// mirror the atlas on the CPU in tests.
  const stream::FrameUpdate& last_update() const { return last_update_; }
  const Raycaster& raycaster() const { return *raycaster_; }
  Raycaster& raycaster() { return *raycaster_; }
  const vulkan::Atlas& atlas() const { return *atlas_; }
  const vulkan::AtlasDecoder& decoder() const { return *decoder_; }

 private:
  VulkanFrameLoop(std::unique_ptr<vulkan::Context>&& owned, const vulkan::Context& context,
                  const format::Container& container, const loop::FrameLoopOptions& options);
  /// Retires the completed frames; hands the newest one's feedback table to the scheduler.
  void retire_completed();
  /// Hands frame `ticket`'s feedback table to the scheduler (waits for the frame).
  void take_feedback(Ticket ticket);
  /// Steps 1–3 of a frame: retire, the scheduler's update, the decode of the uploads.
  stream::FrameUpdate update_and_decode(const player::OrbitCamera& camera, double playhead,
                                        loop::FrameReport& report);
  void decode_uploads(const std::vector<stream::BrickUpload>& uploads,
                      std::vector<std::string>& errors);
  std::uint64_t histogram_of(const stream::KeyframeKey& key) const;

  std::unique_ptr<vulkan::Context> owned_context_;  // null unless given; destroyed last
  const vulkan::Context& context_;
  const format::Container& container_;
  loop::FrameLoopOptions options_;
  cpu_render::VolumeGeometry geometry_;
  std::unique_ptr<vulkan::Atlas> atlas_;
  std::unique_ptr<vulkan::AtlasDecoder> decoder_;
  std::unique_ptr<Raycaster> raycaster_;
  std::unique_ptr<stream::StreamScheduler> scheduler_;
  std::vector<std::uint64_t> slot_histograms_;  ///< per atlas slot, its brick's node histogram
  std::vector<std::uint64_t> leaf_histograms_;
  std::vector<std::uint32_t> changed_slots_;  ///< decoded since the last rendered frame
  stream::FrameUpdate last_update_;
  Ticket retired_ = 0;
  Ticket fed_back_ = 0;  ///< the newest frame whose feedback table went to the scheduler
};

/// Histogram words of each leaf record: the OR of the histograms of the slots of A and B, and of
/// C and D where the leaf blends levels of detail (those with a nonzero weight); slots without a
/// histogram (0) make the leaf's histogram 0 (drawn).
void leaf_histograms(std::span<const std::uint32_t> svo_leaves,
                     std::span<const std::uint64_t> slot_histograms,
                     std::vector<std::uint64_t>& out);

}  // namespace volreel::vulkan_render
