// cpu_renderer.cpp: the player's CPU path (volume_renderer.hpp) over loop::CpuFrameLoop — bricks
// decoded by the CPU reference decoder into a CpuAtlas, the frame ray cast by
// cpu_render::render_svo, and the 8-bit image copied through a host-visible staging buffer (one
// per frame slot) into a device image. Slow, but independent of the GPU ray caster: a reference
// to compare the window against.
#include <algorithm>
#include <cmath>
#include <exception>
#include <vector>

#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/vulkan/resources.hpp"
#include "volume_renderer.hpp"

namespace volreel::app::detail {

namespace {

/// The loop's options: the CPU atlas stores float32 voxels, so `atlas_bytes` holds half as many
/// slots as a 16-bit GPU atlas of the same memory (the loop counts 16-bit slots), at most 2^16.
loop::FrameLoopOptions cpu_options(const RendererSetup& setup) {
  loop::FrameLoopOptions o;
  o.scheduler = setup.scheduler;
  o.atlas_bytes = std::min<std::uint64_t>(
      setup.atlas_bytes / 2,
      (1u << 16) * loop::CpuFrameLoop::gpu_slot_bytes(setup.container->manifest().shape()));
  o.width = static_cast<int>(setup.width);
  o.height = static_cast<int>(setup.height);
  return o;
}

class CpuRenderer final : public VolumeRenderer {
 public:
  explicit CpuRenderer(const RendererSetup& setup)
      : context_(*setup.context),
        loop_(*setup.container, cpu_options(setup)),
        staging_(setup.frames_in_flight) {
    resize(setup.width, setup.height);
  }

  std::string name() const override { return "CPU reference renderer"; }
  stream::StreamScheduler& scheduler() override { return loop_.scheduler(); }
  VkImage image() const override { return image_.handle(); }
  VkImageLayout image_layout() const override { return VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL; }
  VkExtent2D extent() const override { return {width_, height_}; }
  void retired(std::uint64_t) override {}  // the loop retires each frame once it is rendered

  void resize(std::uint32_t width, std::uint32_t height) override {
    width_ = std::max(width, 1u);
    height_ = std::max(height, 1u);
    loop_.resize(static_cast<int>(width_), static_cast<int>(height_));
    vulkan::ImageDesc desc;
    desc.type = VK_IMAGE_TYPE_2D;
    desc.format = VK_FORMAT_R8G8B8A8_UNORM;
    desc.extent = {width_, height_, 1};
    // SAMPLED only because vulkan::Image always makes a view, which needs a view-able usage.
    desc.usage = VK_IMAGE_USAGE_TRANSFER_SRC_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT |
                 VK_IMAGE_USAGE_SAMPLED_BIT;
    image_ = vulkan::Image(context_, desc);
    for (auto& buffer : staging_)
      buffer = vulkan::Buffer(
          context_, VkDeviceSize{width_} * height_ * 4, VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
          VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
  }

  FrameOutput frame(const FrameInputs& in) override {
    FrameOutput out;
    // 1. The loop: scheduler, decode (a bad payload is a HUD message and its slot shows the
    //    lowest value), ray casting of the SVO.
    player::OrbitCamera camera = in.camera;
    camera.width = static_cast<int>(width_);
    camera.height = static_cast<int>(height_);
    const cpu_render::RgbaImage* image = nullptr;
    try {
      loop::FrameReport report = loop_.frame(camera, in.playhead, *in.transfer);
      out.stats = report.stats;
      out.new_errors = std::move(report.new_errors);
      out.times.schedule = report.timings.schedule_ms;
      out.times.decode = report.timings.decode_ms;
      out.times.render = report.timings.render_ms;
      image = &loop_.last_image(report.ticket);
    } catch (const std::exception& e) {
      std::string message = std::string("render: ") + e.what();
      loop_.scheduler().report_error(message);
      out.new_errors.push_back(std::move(message));
    }
    // 2. To 8-bit RGBA in the slot's staging buffer.
    std::byte* pixels = staging_[in.slot].mapped();
    const std::size_t count = std::size_t{width_} * height_;
    if (image && image->width == static_cast<int>(width_) &&
        image->height == static_cast<int>(height_)) {
      for (std::size_t i = 0; i < count; ++i)
        for (std::size_t c = 0; c < 4; ++c) {
          const float v = c == 3 ? 1.0f : image->rgba[4 * i + c];
          pixels[4 * i + c] =
              static_cast<std::byte>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
        }
    } else {
      std::fill(pixels, pixels + 4 * count, std::byte{0});
    }
    return out;
  }

  void record(VkCommandBuffer cb, std::uint32_t slot) override {
    vulkan::image_barrier(cb, image_.handle(), VK_IMAGE_LAYOUT_UNDEFINED,
                          VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
    VkBufferImageCopy copy{};
    copy.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    copy.imageExtent = {width_, height_, 1};
    vkCmdCopyBufferToImage(cb, staging_[slot].handle(), image_.handle(),
                           VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &copy);
    vulkan::image_barrier(cb, image_.handle(), VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL,
                          VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, VK_PIPELINE_STAGE_TRANSFER_BIT,
                          VK_ACCESS_TRANSFER_WRITE_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT,
                          VK_ACCESS_TRANSFER_READ_BIT);
  }

 private:
  const vulkan::Context& context_;
  loop::CpuFrameLoop loop_;
  std::uint32_t width_ = 0, height_ = 0;
  std::vector<vulkan::Buffer> staging_;  // destroyed before the image; both before the context
  vulkan::Image image_;
};

}  // namespace

std::unique_ptr<VolumeRenderer> make_cpu_renderer(const RendererSetup& setup) {
  return std::make_unique<CpuRenderer>(setup);
}

}  // namespace volreel::app::detail
