// open_frame_loop.cpp: the Vulkan loop or the CPU loop (see open_frame_loop.hpp).
#include "volreel/vulkan_render/open_frame_loop.hpp"

#include <cstdio>

#include "volreel/datasets/volume.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/error.hpp"
#include "volreel/vulkan_render/vulkan_frame_loop.hpp"

namespace volreel::vulkan_render {

RendererChoice parse_renderer(const std::string& text, const std::string& option) {
  if (text == "auto") return RendererChoice::automatic;
  if (text == "vulkan") return RendererChoice::vulkan;
  if (text == "cpu") return RendererChoice::cpu;
  throw InputError(option + ": expected auto, vulkan or cpu, found '" + text + "'");
}

std::unique_ptr<loop::FrameLoop> open_frame_loop(const format::Container& container,
                                                 const loop::FrameLoopOptions& options,
                                                 RendererChoice choice, NoDevice no_device,
                                                 const std::string& hint) {
  std::unique_ptr<vulkan::Context> context;
  if (choice != RendererChoice::cpu) {
    try {
      context = std::make_unique<vulkan::Context>(vulkan::ContextOptions{});
    } catch (const vulkan::NoDeviceError& e) {
      if (no_device == NoDevice::fail)
        throw InputError(std::string("no Vulkan device: ") + e.what() + " " + hint);
      std::fprintf(stderr,
                   "volreel: notice: no Vulkan device (%s): rendering on the CPU, as with --cpu\n",
                   e.what());
    }
  }
  if (context && choice == RendererChoice::automatic &&
      context->properties().deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU) {
    std::fprintf(stderr,
                 "volreel: notice: Vulkan runs on the CPU here (%s): rendering with the CPU "
                 "reference renderer, faster there (--renderer vulkan to use Vulkan)\n",
                 context->device_name().c_str());
    context.reset();
  }
  if (context) return std::make_unique<VulkanFrameLoop>(std::move(context), container, options);
  return std::make_unique<loop::CpuFrameLoop>(container, options);
}

}  // namespace volreel::vulkan_render
