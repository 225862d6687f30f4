// loop_options.hpp: the options of the player's per-frame loop (atlas, streaming limits, quality)
// shared by `volreel render` and `volreel bench play`.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <stdexcept>
#include <string>

#include "volreel/datasets/volume.hpp"
#include "volreel/loop/loop_settings.hpp"

namespace volreel::cli {

/// A check that runs `parse` (loop::parse_size, parse_bandwidth, ...) on an option's text when
/// the command line is read, so that a value it refuses is a command-line mistake (status 2),
/// with its message.
inline CLI::Validator parsed_by(std::function<void(const std::string&)> parse) {
  return CLI::Validator(
      [parse = std::move(parse)](std::string& text) {
        try {
          parse(text);
          return std::string();
        } catch (const std::invalid_argument& e) {
          const std::string message = e.what();
          const std::size_t colon = message.find(": ");  // "--size: expected ...": CLI11 names it
          return message.starts_with("--") && colon != std::string::npos ? message.substr(colon + 2)
                                                                         : message;
        }
      },
      "");
}

/// --size WIDTHxHEIGHT, checked by loop::parse_size.
inline CLI::Validator image_size() {
  return parsed_by([](const std::string& text) { loop::parse_size(text); });
}

/// --atlas-mb, --bandwidth, --latency, --sse-target, --upload-budget, --step,
/// --max-step-doublings, --no-culling, --decode, --lod-fade, --lod-fade-out, --spatial-blend,
/// --restricted,
/// --restricted-drawing, --ray-feedback.
inline void add_loop_options(CLI::App& cmd, loop::LoopSettings& loop) {
  cmd.add_option("--atlas-mb", loop.atlas_mb,
                 "Brick atlas memory, MiB (2 bytes a voxel: 93 312 bytes per slot of 36^3, 574 992 "
                 "of 66^3)")
      ->capture_default_str();
  cmd.add_option("--bandwidth", loop.bandwidth,
                 "Simulated read bandwidth, e.g. 20MB/s (0: unlimited)")
      ->check(parsed_by([](const std::string& text) { loop::parse_bandwidth(text); }))
      ->capture_default_str();
  cmd.add_option("--latency", loop.latency, "Simulated latency per request, e.g. 50ms")
      ->check(parsed_by([](const std::string& text) { loop::parse_latency(text); }))
      ->capture_default_str();
  cmd.add_option("--sse-target", loop.sse_target, "Screen-space error target, pixels per voxel")
      ->capture_default_str();
  cmd.add_option("--upload-budget", loop.upload_budget_mb,
                 "Compressed bytes uploaded per frame at most, MiB")
      ->capture_default_str();
  cmd.add_option("--step", loop.step, "Ray step, finest voxels")->capture_default_str();
  cmd.add_option(
         "--max-step-doublings", loop.max_step_doublings,
         "A leaf e levels coarser than the finest is sampled every step*2^min(e, N) voxels, with\n"
         "opacity corrected for the longer step (0: the fixed step everywhere)")
      ->capture_default_str();
  cmd.add_flag("--no-culling", loop.no_culling,
               "Do not skip nodes the transfer function makes invisible");
  cmd.add_option("--decode", loop.decode,
                 "Where bricks are decoded: auto (on the CPU with a CPU Vulkan implementation such "
                 "as lavapipe, in the compute shader on a GPU), gpu (the compute shader) or cpu "
                 "(the CPU decoder, texels copied into the atlas)")
      ->check(CLI::IsMember({"auto", "gpu", "cpu"}))
      ->capture_default_str();
  cmd.add_option("--lod-fade", loop.lod_fade,
                 "A node whose own bricks arrive while an ancestor draws it fades in from the "
                 "parent's drawing over this many seconds (0: at once)")
      ->capture_default_str();
  cmd.add_option("--lod-fade-out", loop.lod_fade_out,
                 "A node whose children drew it in the last frame and that is now drawn by itself "
                 "keeps drawing them, fading to its own drawing over this many seconds (0: at "
                 "once)")
      ->capture_default_str();
  cmd.add_option("--spatial-blend", loop.spatial_blend,
                 "A node's corners next to a coarser neighbour take its parent's drawing "
                 "(true/false)")
      ->capture_default_str();
  cmd.add_option("--restricted", loop.restricted,
                 "Restricted working set: the view's target nodes that touch differ by at most "
                 "one level; a coarser neighbour is refined too (true/false)")
      ->capture_default_str();
  cmd.add_option(
         "--restricted-drawing", loop.restricted_drawing,
         "Restricted drawing: while bricks stream in, a region drawn from data more than one "
         "level finer than a region it touches is drawn coarser (true/false)")
      ->capture_default_str();
  cmd.add_option("--ray-feedback", loop.ray_feedback,
                 "Leave out of the streaming the nodes no ray reached in a recent frame (behind "
                 "opaque material, outside the image), from the ray caster's feedback (true/false)")
      ->capture_default_str();
}

/// --renderer auto|vulkan|cpu (vulkan_render::parse_renderer) and --cpu, its shorthand.
inline void add_renderer_options(CLI::App& cmd, std::string& renderer, bool& cpu) {
  cmd.add_option("--renderer", renderer,
                 "Ray caster: auto (Vulkan on a GPU; the CPU reference renderer where Vulkan runs "
                 "on the CPU, as lavapipe does, or where there is no Vulkan device), vulkan or cpu")
      ->check(CLI::IsMember({"auto", "vulkan", "cpu"}))
      ->capture_default_str();
  cmd.add_flag("--cpu", cpu, "The same as --renderer cpu");
}

/// Refuses --cpu with --renderer vulkan, and --decode gpu|cpu with the CPU ray caster named (it
/// decodes its bricks on the CPU itself; --decode places the Vulkan ray caster's decoding).
inline void check_renderer_options(const std::string& renderer, bool cpu,
                                   const std::string& decode) {
  if (cpu && renderer == "vulkan")
    throw InputError(
        "--cpu with --renderer vulkan: --cpu is the same as --renderer cpu; give "
        "one of them");
  if ((cpu || renderer == "cpu") && decode != "auto")
    throw InputError("--decode " + decode + " with the CPU ray caster (" +
                     (cpu ? "--cpu" : "--renderer cpu") +
                     "), which decodes its bricks on the CPU itself: --decode places the Vulkan "
                     "ray caster's decoding; leave it out, or give --renderer vulkan");
}

}  // namespace volreel::cli
