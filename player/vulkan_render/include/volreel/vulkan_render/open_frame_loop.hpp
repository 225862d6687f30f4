// open_frame_loop.hpp: the frame loop a program asks for — the Vulkan loop (VulkanFrameLoop, on a
// context of its own) or the CPU loop (loop::CpuFrameLoop) — behind loop::FrameLoop, for
// `volreel render` and `volreel bench play`.
#pragma once

#include <memory>
#include <string>

#include "volreel/format/container.hpp"
#include "volreel/loop/frame_loop.hpp"

namespace volreel::vulkan_render {

/// Which ray caster draws.
enum class RendererChoice {
  /// Vulkan on a GPU; the CPU reference renderer where Vulkan itself runs on the CPU (lavapipe:
  /// the C++ ray caster with OpenMP draws the same image several times faster there) or where
  /// there is no Vulkan device (per NoDevice).
  automatic,
  vulkan,  ///< the Vulkan loop, also on a CPU implementation
  cpu,     ///< the CPU loop
};

/// "auto", "vulkan", "cpu" -> RendererChoice; throws InputError naming `option` otherwise.
RendererChoice parse_renderer(const std::string& text, const std::string& option = "--renderer");

/// What to do when no Vulkan device is present.
enum class NoDevice {
  use_cpu,  ///< print a notice on stderr and render on the CPU
  fail,     ///< throw InputError (with the hint)
};

/// The loop `choice` asks for; without a Vulkan device (automatic, vulkan), per `no_device`
/// (`hint` ends the error). An automatic choice of the CPU loop on a CPU Vulkan implementation is
/// announced on stderr. The container must outlive the loop. Throws vulkan::Error on other Vulkan
/// failures.
std::unique_ptr<loop::FrameLoop> open_frame_loop(const format::Container& container,
                                                 const loop::FrameLoopOptions& options,
                                                 RendererChoice choice, NoDevice no_device,
                                                 const std::string& hint);

}  // namespace volreel::vulkan_render
