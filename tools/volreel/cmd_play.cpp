// cmd_play.cpp: `volreel play NAME.vreel` — the interactive player window (player/app). Exit codes
// beyond the usual: 3 when there is no display, 4 when there is no Vulkan device that can present
// to a window (scripts and tests skip on them).
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>

#include "commands.hpp"
#include "loop_options.hpp"
#include "remote_options.hpp"
#include "volreel/app/player.hpp"
#include "volreel/app/script.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/vulkan/error.hpp"

namespace volreel::cli {

namespace {

struct PlayCommandOptions {
  app::PlayerOptions player;
  std::string size = "1024x720";
  double atlas_mb = 256, upload_mb = 8;
  std::string bandwidth = "0", latency = "0";
  std::string renderer = "auto", decode = "auto";
  std::string script_file, script_inline, screenshot_on_exit;
  RemoteCli remote;
};

void run_play(PlayCommandOptions& o) {
  check_renderer_options(o.renderer, false, o.decode);
  app::PlayerOptions& p = o.player;
  {
    const auto [w, h] = loop::parse_size(o.size);
    if (w < 64 || h < 64)
      throw InputError("--size: a window needs at least 64x64 pixels, found '" + o.size + "'");
    p.width = w;
    p.height = h;
  }
  if (!(o.atlas_mb > 0)) throw InputError("--atlas-mb: expected a positive size");
  p.atlas_bytes = static_cast<std::uint64_t>(o.atlas_mb * 1024 * 1024);
  p.upload_bytes =
      std::max<std::uint64_t>(static_cast<std::uint64_t>(o.upload_mb * 1024 * 1024), 1);
  p.bandwidth_bytes_per_s = loop::parse_bandwidth(o.bandwidth);
  p.latency_s = loop::parse_latency(o.latency);
  p.decode = loop::parse_decode(o.decode);
  if (!(p.lod_blend.fade_out_s >= 0) || p.lod_blend.fade_out_s > 60)
    throw InputError("--lod-fade-out: expected seconds in [0, 60], found '" +
                     format::number_text(p.lod_blend.fade_out_s) + "'");
  if (!(p.lod_blend.fade_s >= 0) || p.lod_blend.fade_s > 60)
    throw InputError("--lod-fade: expected seconds in [0, 60], found '" +
                     format::number_text(p.lod_blend.fade_s) + "'");
  p.renderer = o.renderer == "cpu"      ? app::RendererKind::cpu
               : o.renderer == "vulkan" ? app::RendererKind::vulkan
                                        : app::RendererKind::automatic;
  if (!o.script_file.empty()) {
    try {
      const auto bytes =
          format::detail::read_whole_file(o.script_file, format::detail::max_json_bytes);
      p.script.assign(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    } catch (const format::FormatError& e) {
      throw InputError(std::string(e.what()) + " (the script)");
    }
  }
  if (!o.script_inline.empty()) p.script += "\n" + o.script_inline;
  if (!o.screenshot_on_exit.empty()) {
    // Checked now, not when the session ends: a PNG file in a folder that exists.
    if (const std::string problem = app::screenshot_path_problem(o.screenshot_on_exit);
        !problem.empty())
      throw InputError("--screenshot-on-exit " + o.screenshot_on_exit + ": " + problem);
    format::detail::check_writable(o.screenshot_on_exit, "--screenshot-on-exit");
    p.screenshot_on_exit = o.screenshot_on_exit;
  }
  p.source = open_container_source(p.container.string(), o.remote);
  try {
    const app::PlayerResult result = app::run_player(p);
    if (result.failed_screenshots > 0)
      throw InputError(std::to_string(result.failed_screenshots) +
                       " screenshot(s) could not be written (see the messages above)");
    if (result.read_failures > 0)
      throw InputError(std::to_string(result.read_failures) +
                       " bricks or frames could not be read (the messages above name them): the "
                       "session showed the container without them");
  } catch (const app::NoDisplayError& e) {
    std::fprintf(stderr, "volreel play: %s\n", e.what());
    throw CLI::RuntimeError(3);
  } catch (const vulkan::NoDeviceError& e) {
    std::fprintf(
        stderr,
        "volreel play: no Vulkan device that can show a window: %s\n"
        "Render without a window with `volreel render NAME.vreel --tour T.json --out DIR`.\n",
        e.what());
    throw CLI::RuntimeError(4);
  }
}

}  // namespace

void add_play_command(CLI::App& app) {
  auto o = std::make_shared<PlayCommandOptions>();
  CLI::App* cmd = app.add_subcommand("play",
                                     "Play a container in a window, like a video: space "
                                     "play/pause, r reverse, [ ] speed (0.25x-8x),\n"
                                     "left/right step one keyframe, Home/End, c reset view, h hide "
                                     "the panels; left drag orbits, right or\n"
                                     "middle drag pans, the wheel zooms. Needs a display (try "
                                     "`xvfb-run -a volreel play ...`); without one,\n"
                                     "use `volreel render`. Scripts replay timed actions for "
                                     "tests: \"0.5 key space; 12f key right;\n"
                                     "2.0 settle; 2.1 screenshot a.png; 3 quit\" (see "
                                     "player/app/include/volreel/app/script.hpp).");
  cmd->add_option("CONTAINER", o->player.container, container_argument_help)->required();
  add_remote_options(*cmd, o->remote);
  cmd->add_option("--size", o->size, "Window size WxH, pixels")
      ->check(image_size())
      ->capture_default_str();
  cmd->add_option("--atlas-mb", o->atlas_mb, "Brick atlas memory budget, MiB")
      ->capture_default_str();
  cmd->add_option("--bandwidth", o->bandwidth,
                  "Limit brick reads to this rate, e.g. 20MB/s, 500kB/s or 1GB/s (a bare number: "
                  "MB/s; 0: unlimited)")
      ->check(parsed_by([](const std::string& text) { loop::parse_bandwidth(text); }))
      ->capture_default_str();
  cmd->add_option("--latency", o->latency,
                  "Add this latency to every brick read, e.g. 50ms or 0.2s (a bare number: ms)")
      ->check(parsed_by([](const std::string& text) { loop::parse_latency(text); }))
      ->capture_default_str();
  cmd->add_option("--upload-mb", o->upload_mb,
                  "Compressed brick data decoded per frame at most, MiB")
      ->check(positive())
      ->capture_default_str();
  cmd->add_option("--max-requests", o->player.max_requests, "Brick reads in flight at most")
      ->check(CLI::Range(1, 100000))
      ->capture_default_str();
  cmd->add_option("--transfer", o->player.transfer,
                  "Transfer function: auto (from the data's quantiles), a preset (grayscale, "
                  "cool-warm, fire, turbulence, transparent) or a JSON file")
      ->capture_default_str();
  cmd->add_option("--sse", o->player.sse_target, "Screen-space error target, pixels per voxel")
      ->check(positive())
      ->capture_default_str();
  cmd->add_option("--keyframes-per-second", o->player.keyframes_per_second, "Playback rate at 1x")
      ->check(positive())
      ->capture_default_str();
  cmd->add_flag("--loop", o->player.loop, "Wrap around at the ends of the timeline");
  cmd->add_flag("!--no-vsync", o->player.vsync, "Present as fast as possible (mailbox/immediate)");
  cmd->add_option("--renderer", o->renderer,
                  "Volume renderer: auto (the Vulkan ray caster on a GPU, the CPU one where Vulkan "
                  "runs on the CPU, as lavapipe does), cpu or vulkan")
      ->check(CLI::IsMember({"auto", "cpu", "vulkan"}))
      ->capture_default_str();
  cmd->add_option("--render-scale", o->player.render_scale,
                  "Volume image size relative to the window")
      ->check(in_range(0.05, 1))
      ->capture_default_str();
  cmd->add_option("--frame-ms", o->player.frame_ms,
                  "Frame-time target while the view is busy (orbiting, playing, streaming): the "
                  "volume is rendered smaller to hold it and at full size once the view is still, "
                  "milliseconds (0: always full size)")
      ->check(non_negative())
      ->capture_default_str();
  cmd->add_option("--decode", o->decode,
                  "Where bricks are decoded: auto (on the CPU with a CPU Vulkan implementation "
                  "such as lavapipe, in the compute shader on a GPU), gpu or cpu")
      ->check(CLI::IsMember({"auto", "gpu", "cpu"}))
      ->capture_default_str();
  cmd->add_option("--lod-fade", o->player.lod_blend.fade_s,
                  "A node whose own bricks arrive while an ancestor draws it fades in from the "
                  "parent's drawing over this many seconds (0: at once)")
      ->capture_default_str();
  cmd->add_option("--lod-fade-out", o->player.lod_blend.fade_out_s,
                  "A node whose children drew it in the last frame and that is now drawn by "
                  "itself keeps drawing them, fading to its own drawing over this many seconds "
                  "(0: at once)")
      ->capture_default_str();
  cmd->add_option("--spatial-blend", o->player.lod_blend.spatial,
                  "A node's corners next to a coarser neighbour take its parent's drawing "
                  "(true/false)")
      ->capture_default_str();
  cmd->add_option("--restricted", o->player.restricted,
                  "Restricted working set: the view's target nodes that touch differ by at most "
                  "one level; a coarser neighbour is refined too (true/false)")
      ->capture_default_str();
  cmd->add_option(
         "--restricted-drawing", o->player.restricted_drawing,
         "Restricted drawing: while bricks stream in, a region drawn from data more than one "
         "level finer than a region it touches is drawn coarser (true/false)")
      ->capture_default_str();
  cmd->add_option(
         "--ray-feedback", o->player.ray_feedback,
         "Leave out of the streaming the nodes no ray reached in a recent frame (behind "
         "opaque material, outside the image), from the ray caster's feedback (true/false)")
      ->capture_default_str();
  cmd->add_option("--script", o->script_file, "Replay the timed actions of this file");
  cmd->add_option("--script-inline", o->script_inline,
                  "Replay these timed actions ('0.5 key space; 2 quit')");
  cmd->add_option("--frames", o->player.max_frames, "Quit after N frames (0: run until closed)");
  cmd->add_option("--screenshot-on-exit", o->screenshot_on_exit,
                  "Write the last frame to this PNG");
  cmd->add_option(
         "--fixed-frame-time", o->player.fixed_frame_seconds,
         "Advance the playhead by this many seconds per frame instead of the real frame time (0: "
         "the real frame time)")
      ->check(non_negative());
  cmd->add_flag("--quiet", o->player.quiet, "No status lines on stdout");
  cmd->callback([o] { run_play(*o); });
}

}  // namespace volreel::cli
