// cpu_frame_loop.hpp: the per-frame streaming loop (frame_loop.hpp) on the CPU — the stream
// scheduler, bricks decoded by the CPU reference decoder into a cpu_render::CpuAtlas and drawn by
// cpu_render::render_svo. No Vulkan: the headless fallback of `volreel render` where no Vulkan
// device exists (and `--cpu`), and the player window's CPU reference renderer.
#pragma once

#include <memory>
#include <vector>

#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/frame_loop.hpp"

namespace volreel::loop {

class CpuFrameLoop final : public FrameLoop {
 public:
  /// Bytes of one slot of a 16-bit GPU atlas for bricks of `shape`: options.atlas_bytes / this is
  /// the slot count.
  static std::uint64_t gpu_slot_bytes(format::BrickShape shape) {
    return std::uint64_t{shape.voxels()} * 2;
  }

  /// Indexes the container; the atlas gets as many slots as a 16-bit GPU atlas of
  /// options.atlas_bytes would (gpu_slot_bytes each, 1 to 2^20; it stores float32, twice that).
  /// The container must outlive the loop.
  CpuFrameLoop(const format::Container& container, const FrameLoopOptions& options);
  /// The same over an index of the container built before (stream::build_spatial_index).
  CpuFrameLoop(const format::Container& container, stream::SpatialIndex index,
               const FrameLoopOptions& options);

  /// One frame, rendered at once (decode_ms: CPU decoding; render_ms: render_svo) at the
  /// camera's size. The image is kept for read_back(report.ticket) whatever `readback` says.
  FrameReport frame(const player::OrbitCamera& camera, double playhead,
                    const cpu_render::TransferFunction& transfer, bool readback = false) override;
  FrameReport stream(const player::OrbitCamera& camera, double playhead) override;
  /// What the last frame's working set (its view's nodes and resident bricks, blended as it drew
  /// them: StreamScheduler::previous_svo) draws at this camera, playhead and transfer function,
  /// from the atlas as that frame left it: call it before the next frame(), whose uploads change
  /// the atlas. Next to that frame's image it shows the change due to the working set alone (no
  /// camera motion, no change of time step). An empty image before the first frame.
  cpu_render::RgbaImage render_previous_working_set(
      const player::OrbitCamera& camera, double playhead,
      const cpu_render::TransferFunction& transfer) const;
  /// The image of the last frame; throws std::invalid_argument for any other ticket.
  cpu_render::RgbaImage read_back(Ticket ticket) const override { return last_image(ticket); }
  /// The same without a copy.
  const cpu_render::RgbaImage& last_image(Ticket ticket) const;
  void finish() override {}  // every frame retired when frame() returns
  bool can_pipeline() const override { return false; }
  void set_pipelined(bool) override {}
  void resize(int width, int height) override;
  std::string describe() const override;

  std::uint32_t slot_count() const override { return atlas_->slot_count(); }
  stream::StreamScheduler& scheduler() override { return *scheduler_; }
  const stream::StreamScheduler& scheduler() const override { return *scheduler_; }
  const cpu_render::VolumeGeometry& geometry() const override { return geometry_; }
  const FrameLoopOptions& options() const override { return options_; }
  const cpu_render::CpuAtlas& atlas() const { return *atlas_; }
  /// The scheduler's output of the last frame (uploads with their payloads, the SVO, the
  /// scheduler's own new errors).
  const stream::FrameUpdate& last_update() const { return last_update_; }

 private:
  static std::uint32_t slots_for(const FrameLoopOptions& options, format::BrickShape shape);
  /// Steps 1–2 of a frame: the scheduler's update and the decode of the uploads.
  stream::FrameUpdate update_and_decode(const player::OrbitCamera& camera, double playhead,
                                        FrameReport& report);

  const format::Container& container_;
  FrameLoopOptions options_;
  cpu_render::VolumeGeometry geometry_;
  std::unique_ptr<cpu_render::CpuAtlas> atlas_;
  std::unique_ptr<stream::StreamScheduler> scheduler_;
  cpu_render::RgbaImage image_;
  std::vector<std::uint32_t> feedback_;  ///< the rays' feedback per leaf record, last frame
  stream::FrameUpdate last_update_;
  Ticket ticket_ = 0;
};

}  // namespace volreel::loop
