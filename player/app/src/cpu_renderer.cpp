// cpu_renderer.cpp: the player's CPU path (volume_renderer.hpp) — bricks decoded by the CPU
// reference decoder into a CpuAtlas, the frame ray cast by cpu_render::render_svo, and the 8-bit
// image copied through a host-visible staging buffer (one per frame slot) into a device image.
// Slow, but independent of the GPU ray caster: a reference to compare the window against.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <vector>

#include "volreel/cpu_render/cpu_atlas.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/vulkan/resources.hpp"
#include "volume_renderer.hpp"

namespace volreel::app::detail {

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

std::uint32_t cpu_slots(const RendererSetup& setup) {
  const std::uint64_t slot_bytes = cpu_render::CpuAtlas::slot_values * sizeof(float);
  return static_cast<std::uint32_t>(
      std::clamp<std::uint64_t>(setup.atlas_bytes / slot_bytes, 1, 1u << 16));
}

stream::SchedulerSettings with_slots(stream::SchedulerSettings s, std::uint32_t slots) {
  s.atlas_slots = slots;
  return s;
}

class CpuRenderer final : public VolumeRenderer {
 public:
  explicit CpuRenderer(const RendererSetup& setup)
      : context_(*setup.context),
        container_(*setup.container),
        atlas_(cpu_slots(setup)),
        scheduler_(container_, with_slots(setup.scheduler, atlas_.slot_count())),
        geometry_(cpu_render::VolumeGeometry::of(container_.manifest().dims)),
        staging_(setup.frames_in_flight) {
    resize(setup.width, setup.height);
  }

  std::string name() const override { return "CPU reference renderer"; }
  stream::StreamScheduler& scheduler() override { return scheduler_; }
  VkImage image() const override { return image_.handle(); }
  VkImageLayout image_layout() const override { return VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL; }
  VkExtent2D extent() const override { return {width_, height_}; }
  void retired(std::uint64_t gpu_frame) override { scheduler_.retire(gpu_frame); }

  void resize(std::uint32_t width, std::uint32_t height) override {
    width_ = std::max(width, 1u);
    height_ = std::max(height, 1u);
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
    // 1. The scheduler.
    auto t0 = Clock::now();
    stream::FrameUpdate update = scheduler_.update(in.camera, in.playhead, in.gpu_frame);
    out.times.schedule = ms_since(t0);
    out.new_errors = std::move(update.new_errors);
    // 2. Decode this frame's uploads into their slots; a bad payload is a HUD message and its
    //    slot shows the lowest value.
    t0 = Clock::now();
    const format::Manifest& m = container_.manifest();
    for (const stream::BrickUpload& u : update.uploads) {
      try {
        atlas_.decode_into(u.slot, u.payload, m.codec, m.zfp_accuracy, container_.atoms(), u.file,
                           u.offset);
      } catch (const std::exception& e) {
        scheduler_.report_error(e.what());
        out.new_errors.emplace_back(e.what());
        std::fill(atlas_.slot(u.slot).begin(), atlas_.slot(u.slot).end(),
                  static_cast<float>(m.value_min));
      }
    }
    out.times.decode = ms_since(t0);
    // 3. Ray cast the SVO.
    t0 = Clock::now();
    cpu_render::RgbaImage image;
    player::OrbitCamera camera = in.camera;
    camera.width = static_cast<int>(width_);
    camera.height = static_cast<int>(height_);
    try {
      cpu_render::RenderOptions options;
      image = cpu_render::render_svo({update.svo_nodes, update.svo_leaves}, atlas_, geometry_,
                                     camera, *in.transfer, options);
    } catch (const std::exception& e) {
      std::string message = std::string("render: ") + e.what();
      scheduler_.report_error(message);
      out.new_errors.push_back(std::move(message));
    }
    // 4. To 8-bit RGBA in the slot's staging buffer.
    std::byte* pixels = staging_[in.slot].mapped();
    const std::size_t count = std::size_t{width_} * height_;
    if (image.width == static_cast<int>(width_) && image.height == static_cast<int>(height_)) {
      for (std::size_t i = 0; i < count; ++i)
        for (std::size_t c = 0; c < 4; ++c) {
          const float v = c == 3 ? 1.0f : image.rgba[4 * i + c];
          pixels[4 * i + c] =
              static_cast<std::byte>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
        }
    } else {
      std::fill(pixels, pixels + 4 * count, std::byte{0});
    }
    out.times.render = ms_since(t0);
    out.stats = update.stats;
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
  const format::Container& container_;
  cpu_render::CpuAtlas atlas_;
  stream::StreamScheduler scheduler_;
  cpu_render::VolumeGeometry geometry_;
  std::uint32_t width_ = 0, height_ = 0;
  std::vector<vulkan::Buffer> staging_;  // destroyed before the image; both before the context
  vulkan::Image image_;
};

}  // namespace

std::unique_ptr<VolumeRenderer> make_cpu_renderer(const RendererSetup& setup) {
  return std::make_unique<CpuRenderer>(setup);
}

}  // namespace volreel::app::detail
