// vulkan_renderer.cpp: the player's GPU path (volume_renderer.hpp) over
// vulkan_render::VulkanFrameLoop — the scheduler's uploads decoded into the GPU atlas and the ray
// caster's dispatch, both submitted on the context's queue before the window's own commands, which
// blit the ray caster's output (a storage image kept in GENERAL layout, its writes made visible to
// transfers by the ray caster's closing barrier).
//
// Pipelined (the default), frame() returns right after submitting, so the CPU work of frame N+1
// overlaps the GPU work of frame N; the ray-casting time shown is then the GPU time of the frame
// two back (timestamps) and the decode time is not measured. Exact timings wait for each step.
#include <optional>

#include "volreel/vulkan_render/vulkan_frame_loop.hpp"
#include "volume_renderer.hpp"

namespace volreel::app::detail {

namespace {

class VulkanRenderer final : public VolumeRenderer {
 public:
  explicit VulkanRenderer(const RendererSetup& setup) : loop_(make_loop(setup)) {}

  std::string name() const override {
    return std::string("Vulkan ray caster") + (loop_->options().pipelined ? " (pipelined)" : "");
  }
  stream::StreamScheduler& scheduler() override { return loop_->scheduler(); }
  VkImage image() const override { return loop_->raycaster().output().handle(); }
  VkImageLayout image_layout() const override { return loop_->raycaster().output_layout(); }
  VkExtent2D extent() const override {
    return {static_cast<std::uint32_t>(loop_->raycaster().width()),
            static_cast<std::uint32_t>(loop_->raycaster().height())};
  }
  void retired(std::uint64_t) override {}  // the loop retires its own frames (ray caster tickets)
  void resize(std::uint32_t width, std::uint32_t height) override {
    loop_->resize(static_cast<int>(width), static_cast<int>(height));
  }
  void set_exact_timings(bool exact) override { loop_->set_pipelined(!exact); }

  FrameOutput frame(const FrameInputs& in) override {
    FrameOutput out;
    // The frame two back has completed (the window waited for its fence, which follows the ray
    // caster's submission on the queue) and is still in the ray caster's ring.
    const loop::Ticket last = loop_->raycaster().last_ticket();
    const loop::Ticket earlier = last > 1 ? last - 1 : 0;
    std::optional<double> earlier_ms;
    if (loop_->options().pipelined && earlier > 0) earlier_ms = loop_->gpu_milliseconds(earlier);
    player::OrbitCamera camera = in.camera;
    camera.width = loop_->raycaster().width();
    camera.height = loop_->raycaster().height();
    loop::FrameReport report = loop_->frame(camera, in.playhead, *in.transfer);
    out.stats = report.stats;
    out.new_errors = std::move(report.new_errors);
    out.times.schedule = report.timings.schedule_ms;
    out.times.upload = report.timings.upload_ms;
    if (loop_->options().pipelined) {
      out.times.render = earlier_ms;
    } else {
      out.times.decode = report.timings.decode_ms;
      out.times.render = report.timings.render_ms;
    }
    return out;
  }

  void record(VkCommandBuffer, std::uint32_t) override {}  // ordered by the queue

 private:
  std::unique_ptr<vulkan_render::VulkanFrameLoop> loop_;

  static std::unique_ptr<vulkan_render::VulkanFrameLoop> make_loop(const RendererSetup& setup) {
    loop::FrameLoopOptions o;
    o.scheduler = setup.scheduler;
    o.atlas_bytes = setup.atlas_bytes;
    o.width = static_cast<int>(setup.width);
    o.height = static_cast<int>(setup.height);
    o.gpu.frames_in_flight = setup.frames_in_flight + 1;
    o.pipelined = true;
    o.gpu.decode = setup.decode;
    return std::make_unique<vulkan_render::VulkanFrameLoop>(*setup.context, *setup.container, o);
  }
};

}  // namespace

std::unique_ptr<VolumeRenderer> make_vulkan_renderer(const RendererSetup& setup) {
  return std::make_unique<VulkanRenderer>(setup);
}

}  // namespace volreel::app::detail
