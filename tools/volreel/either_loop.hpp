// either_loop.hpp: the Vulkan frame loop or the CPU reference loop behind one interface, for
// `volreel render` and `volreel bench play`.
#pragma once

#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/container.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/error.hpp"
#include "volreel/vulkan_render/cpu_frame_loop.hpp"
#include "volreel/vulkan_render/frame_loop.hpp"

namespace volreel::cli {

struct EitherLoop {
  std::unique_ptr<vulkan::Context> context;
  std::unique_ptr<vulkan_render::FrameLoop> gpu;
  std::unique_ptr<vulkan_render::CpuFrameLoop> cpu;
  std::string device;  ///< what renders, for the report header

  /// One frame; with `readback`, image(report.ticket) gives it (the CPU loop always keeps it).
  vulkan_render::FrameReport frame(const player::OrbitCamera& camera, double playhead,
                                   const cpu_render::TransferFunction& tf, bool readback = false) {
    return gpu ? gpu->frame(camera, playhead, tf, readback) : cpu->frame(camera, playhead, tf);
  }
  cpu_render::RgbaImage image(vulkan_render::Ticket ticket) const {
    return gpu ? gpu->read_back(ticket) : cpu->read_back(ticket);
  }
  std::uint32_t slots() const { return gpu ? gpu->atlas().slot_count() : cpu->atlas().slot_count(); }
  /// Vulkan: overlap the next frame's CPU work with this frame's GPU work (the CPU loop is serial).
  void set_pipelined(bool on) {
    if (gpu) gpu->options().pipelined = on;
  }
  void finish() {
    if (gpu) gpu->finish();
  }
};

/// What to do when no Vulkan device is present.
enum class NoDevice {
  use_cpu,  ///< print a notice and render on the CPU
  fail,     ///< throw InputError (with the hint)
};

/// The Vulkan loop unless `cpu`; without a device, per `no_device` (`hint` ends the error).
inline EitherLoop open_loop(const format::Container& container, const vulkan_render::FrameLoopOptions& options,
                            bool cpu, NoDevice no_device, const std::string& hint) {
  EitherLoop loop;
  if (!cpu) {
    try {
      loop.context = std::make_unique<vulkan::Context>(vulkan::ContextOptions{});
    } catch (const vulkan::NoDeviceError& e) {
      if (no_device == NoDevice::fail) throw InputError(std::string("no Vulkan device: ") + e.what() + " " + hint);
      std::fprintf(stderr, "volreel: notice: no Vulkan device (%s): rendering on the CPU, as with --cpu\n", e.what());
    }
  }
  if (loop.context) {
    loop.gpu = std::make_unique<vulkan_render::FrameLoop>(*loop.context, container, options);
    loop.device = loop.context->describe();
  } else {
    loop.cpu = std::make_unique<vulkan_render::CpuFrameLoop>(container, options);
    loop.device = "CPU reference renderer (" + std::to_string(std::thread::hardware_concurrency()) + " threads)";
  }
  return loop;
}

}  // namespace volreel::cli
