// cpu_frame_loop.hpp: the per-frame streaming loop of frame_loop.hpp on the CPU — the same stream
// scheduler, bricks decoded by the CPU reference decoder into a cpu_render::CpuAtlas and drawn by
// cpu_render::render_svo. The headless fallback of `volreel render` where no Vulkan device exists
// (and `--cpu`).
#pragma once

#include <memory>

#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/vulkan_render/frame_loop.hpp"

namespace volreel::vulkan_render {

class CpuFrameLoop {
 public:
  /// Indexes the container; the atlas gets as many slots as a 16-bit GPU atlas of
  /// options.atlas_bytes would (93 312 bytes per slot; it stores float32, twice that).
  CpuFrameLoop(const format::Container& container, const FrameLoopOptions& options);

  /// One frame, rendered at once (decode_ms: CPU decoding; render_ms: render_svo). The image is
  /// kept for read_back(report.ticket).
  FrameReport frame(const player::OrbitCamera& camera, double playhead,
                    const cpu_render::TransferFunction& transfer);
  /// The image of the last frame; throws std::invalid_argument for any other ticket.
  const cpu_render::RgbaImage& read_back(Ticket ticket) const;

  stream::StreamScheduler& scheduler() { return *scheduler_; }
  const cpu_render::CpuAtlas& atlas() const { return *atlas_; }
  const cpu_render::VolumeGeometry& geometry() const { return geometry_; }
  FrameLoopOptions& options() { return options_; }

 private:
  const format::Container& container_;
  FrameLoopOptions options_;
  cpu_render::VolumeGeometry geometry_;
  std::unique_ptr<cpu_render::CpuAtlas> atlas_;
  std::unique_ptr<stream::StreamScheduler> scheduler_;
  cpu_render::RgbaImage image_;
  Ticket ticket_ = 0;
};

}  // namespace volreel::vulkan_render
