// open_frame_loop.hpp: the frame loop a program asks for — the Vulkan loop (VulkanFrameLoop, on a
// context of its own) or the CPU loop (loop::CpuFrameLoop) — behind loop::FrameLoop, for
// `volreel render` and `volreel bench play`.
#pragma once

#include <memory>
#include <string>

#include "volreel/format/container.hpp"
#include "volreel/loop/frame_loop.hpp"

namespace volreel::vulkan_render {

/// What to do when no Vulkan device is present.
enum class NoDevice {
  use_cpu,  ///< print a notice on stderr and render on the CPU
  fail,     ///< throw InputError (with the hint)
};

/// The Vulkan loop unless `cpu`; without a Vulkan device, per `no_device` (`hint` ends the
/// error). The container must outlive the loop. Throws vulkan::Error on other Vulkan failures.
std::unique_ptr<loop::FrameLoop> open_frame_loop(const format::Container& container,
                                                 const loop::FrameLoopOptions& options, bool cpu,
                                                 NoDevice no_device, const std::string& hint);

}  // namespace volreel::vulkan_render
