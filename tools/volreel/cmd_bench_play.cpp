// cmd_bench_play.cpp: `volreel bench play NAME.vreel` — the player's frame rate and frame-time
// split (schedule, upload, decode, render) while playing forward, reversing and seeking along a
// built-in script with an orbiting camera, the throughput when the CPU work of a frame overlaps
// the GPU work of the previous one, and the time from a random seek until every visible node is
// drawn at its target LOD. With a frame-time target (--frame-ms, the player's default), frames
// while the camera orbits, the playhead runs or a seek streams in are rendered at the resolution
// that holds the target (loop::ResolutionControl) and the still view at full resolution, as in
// the player window; --frame-ms 0 renders every frame at full resolution.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "loop_options.hpp"
#include "read_failures.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/format/container.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/loop/frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/loop/resolution_control.hpp"
#include "volreel/vulkan_render/open_frame_loop.hpp"

namespace volreel::cli {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct BenchPlayOptions {
  std::string container;
  loop::LoopSettings loop;
  std::size_t frames_per_phase = 60;
  std::size_t seeks = 5;
  double speed = 10;           ///< keyframes per second of playback
  double frame_dt = 1.0 / 30;  ///< playback time per rendered frame, seconds
  double timeout = 60;         ///< seconds a seek may take to reach full quality
  double frame_ms = 100;       ///< frame-time target while busy (0: always full resolution)
  std::string transfer = "auto";
  std::string renderer = "auto";
  bool cpu = false;
  std::uint64_t seed = 1;
};

/// Per-phase sums.
struct PhaseStats {
  std::size_t frames = 0;
  double wall_s = 0, schedule = 0, upload = 0, decode = 0, render = 0, at_target = 0,
         min_at_target = 1, scale = 0;
  std::uint64_t loaded_before = 0, loaded_after = 0;
  void add(const loop::FrameReport& r, double frame_scale) {
    ++frames;
    scale += frame_scale;
    schedule += r.timings.schedule_ms;
    upload += r.timings.upload_ms;
    decode += r.timings.decode_ms;
    render += r.timings.render_ms;
    at_target += r.stats.fraction_at_target;
    min_at_target = std::min(min_at_target, r.stats.fraction_at_target);
    loaded_after = r.stats.bytes_loaded;
  }
  void print(const char* name) const {
    const double n = static_cast<double>(std::max<std::size_t>(frames, 1));
    std::printf("%-18s %6zu %8.2f %9.1f %6.0f%% %9.2f %8.2f %8.2f %8.1f %9.1f %8.0f%% %7.0f%%\n",
                name, frames, n / wall_s, 1000 * wall_s / n, 100 * scale / n, schedule / n,
                upload / n, decode / n, render / n, double(loaded_after - loaded_before) * 1e-6,
                100 * at_target / n, 100 * min_at_target);
  }
};

void run_bench_play(const BenchPlayOptions& o) {
  check_renderer_options(o.renderer, o.cpu, o.loop.decode);
  // 1. Container, device, loop.
  const format::Container container(o.container);
  const format::Manifest& m = container.manifest();
  loop::FrameLoopOptions options;
  options.render.background = {0.06f, 0.06f, 0.08f};
  try {
    loop::apply(o.loop, options);
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  const std::unique_ptr<loop::FrameLoop> loop = vulkan_render::open_frame_loop(
      container, options,
      o.cpu ? vulkan_render::RendererChoice::cpu : vulkan_render::parse_renderer(o.renderer),
      vulkan_render::NoDevice::fail,
      "(bench play measures the player's Vulkan or CPU ray caster; --renderer cpu measures the "
      "CPU one without a Vulkan device)");
  const std::string device = loop->describe();
  const std::uint32_t slots = loop->slot_count();
  const std::size_t keyframes = container.frame_count();
  const double last = static_cast<double>(keyframes - 1);
  const cpu_render::TransferFunction tf = loop::transfer_from_spec(o.transfer, container);
  std::printf("volreel bench play\nmachine: %s\ndevice:  %s\n", describe_machine().c_str(),
              device.c_str());
  std::printf("input:   %s: %ux%ux%u, %zu frames, %s, %u octree levels\n", o.container.c_str(),
              m.dims[0], m.dims[1], m.dims[2], keyframes,
              m.codec == format::Codec::ksvd ? "ksvd" : "zfp", m.levels);
  std::printf(
      "view:    %dx%d, transfer function '%s', ray step %g voxels, SSE target %g px, culling %s\n",
      options.width, options.height, o.transfer.c_str(), options.render.step,
      options.scheduler.priority.sse_target, options.transfer_culling ? "on" : "off");
  std::printf(
      "atlas:   %u slots (%.0f MiB), upload budget %.0f MiB/frame, bandwidth %s, latency %s\n",
      slots, o.loop.atlas_mb, o.loop.upload_budget_mb,
      options.scheduler.loader.bandwidth_bytes_per_s > 0 ? o.loop.bandwidth.c_str() : "unlimited",
      o.loop.latency.c_str());
  std::printf(
      "script:  playback %g keyframes/s, %.4f s of playback per frame, camera orbiting 1 degree "
      "per frame, "
      "%zu frames per phase\n\n",
      o.speed, o.frame_dt, o.frames_per_phase);

  auto camera = player::OrbitCamera::framing(
      {double(m.dims[0]), double(m.dims[1]), double(m.dims[2])}, options.width, options.height);
  const double azimuth0 = camera.azimuth;
  std::size_t frame_number = 0;
  const auto next_camera = [&] {
    camera.azimuth = azimuth0 + glm::radians(static_cast<double>(frame_number++));
    return camera;
  };

  // Frames at the resolution the frame-time control chooses: busy frames (camera or playhead
  // moving, data streaming in) reduced, still ones full; the camera takes the image size.
  loop::ResolutionControl control(loop::ResolutionSettings{o.frame_ms > 0 ? o.frame_ms : 100});
  const int full_width = options.width, full_height = options.height;
  int width = full_width, height = full_height;
  double scale = 1;
  Clock::time_point previous_start;
  bool previous_drawn = false;
  ReadFailures failures;  // any makes the run fail at the end
  const auto draw = [&](player::OrbitCamera view, double at, bool busy) {
    scale = o.frame_ms > 0 ? control.next(busy) : 1.0;
    const auto [w, h] = loop::scaled_size(full_width, full_height, scale);
    if (w != width || h != height) {
      loop->resize(w, h);
      width = w;
      height = h;
    }
    view.width = w;
    view.height = h;
    // The level of detail of the full-size image (as the player does): the screen-space error
    // is measured in the reduced image's pixels.
    loop->scheduler().priority_settings().sse_target =
        options.scheduler.priority.sse_target * scale;
    const auto start = Clock::now();
    loop::FrameReport r = loop->frame(view, at, tf);
    failures.add(r.new_errors);
    // Serial frames: their own time; overlapped ones: the time between frame starts.
    const double ms = loop->options().pipelined && previous_drawn
                          ? 1000 * std::chrono::duration<double>(start - previous_start).count()
                          : 1000 * seconds_since(start);
    control.measured(scale, ms);
    previous_start = start;
    previous_drawn = true;
    return r;
  };
  /// Frames at a still view until one at full resolution shows every visible node at its target
  /// LOD (busy, so reduced, while bricks stream in); false on the timeout, or once nothing more
  /// can come (quiet frames at full resolution: an atlas too small for the view, read errors).
  const auto until_full_quality = [&](double at, std::size_t& frames, loop::FrameReport& r,
                                      Clock::time_point start) {
    // The stream step first: a view whose bricks are all there is drawn at full resolution at
    // once (as in the player, whose previous frame says so).
    const loop::FrameReport probe = loop->stream(camera, at);
    failures.add(probe.new_errors);
    bool complete = probe.stats.fraction_at_target >= 1.0;
    int quiet = 0;
    do {
      r = draw(camera, at, !complete);
      ++frames;
      complete = r.stats.fraction_at_target >= 1.0;
      if (complete && scale == 1.0) return true;
      quiet = r.stats.quiet() && scale == 1.0 ? quiet + 1 : 0;
      if (quiet >= 3) return false;
    } while (seconds_since(start) < o.timeout);
    return false;
  };
  /// Why a view did not reach full quality, for the report.
  const auto short_of_full = [&](const loop::FrameReport& r) -> std::string {
    if (r.stats.atlas_capacity > 0 && r.stats.atlas_occupied >= r.stats.atlas_capacity)
      return " (incomplete: the view wants more bricks than the atlas's " +
             std::to_string(r.stats.atlas_capacity) + " slots; give a larger --atlas-mb)";
    return r.stats.quiet() ? " (incomplete: nothing more could be read)" : " (timed out)";
  };

  // 2. Cold start: playhead 0, fixed camera, until everything visible is at its target LOD.
  double playhead = 0;
  {
    const auto start = Clock::now();
    std::size_t frames = 0;
    loop::FrameReport r;
    const bool reached = until_full_quality(playhead, frames, r, start);
    std::printf(
        "cold start to full quality: %.2f s, %zu frames (%.0f%% at target, %.1f MB loaded)%s\n\n",
        seconds_since(start), frames, 100 * r.stats.fraction_at_target,
        double(r.stats.bytes_loaded) * 1e-6, reached ? "" : short_of_full(r).c_str());
  }

  // 3. Phases along the script (the camera orbits: busy); serial frames give the exact time
  //    split. After each, the view stops: the time to the full-resolution image.
  std::printf("%-18s %6s %8s %9s %7s %9s %8s %8s %8s %9s %9s %8s\n", "phase", "frames", "fps",
              "frame ms", "scale", "schedule", "upload", "decode", "render", "MB read", "at target",
              "worst");
  SplitMix64 rng(o.seed);
  std::vector<double> refine_s;
  const auto run_phase = [&](const char* name, auto&& advance, bool pipelined) {
    PhaseStats s;
    loop->set_pipelined(pipelined);
    previous_drawn = false;
    loop::FrameReport r = draw(next_camera(), playhead, true);  // not counted: settles the mode
    s.loaded_before = r.stats.bytes_loaded;
    const auto start = Clock::now();
    for (std::size_t i = 0; i < o.frames_per_phase; ++i) {
      playhead = std::clamp(advance(i), 0.0, last);
      s.add(draw(next_camera(), playhead, true), scale);
    }
    loop->finish();
    s.wall_s = seconds_since(start);
    s.print(name);
    if (!pipelined) {
      const auto stop = Clock::now();
      camera.azimuth = azimuth0 + glm::radians(static_cast<double>(frame_number - 1));
      draw(camera, playhead, false);
      loop->finish();
      refine_s.push_back(seconds_since(stop));
    }
  };
  const double step = o.speed * o.frame_dt;
  run_phase(
      "forward", [&](std::size_t) { return playhead + step; }, false);
  run_phase(
      "reverse", [&](std::size_t) { return playhead - step; }, false);
  run_phase(
      "seek every 10th",
      [&](std::size_t i) { return i % 10 == 0 ? rng.uniform(0, last) : playhead + step; }, false);
  playhead = 0;
  if (loop->can_pipeline()) {
    run_phase(
        "forward, overlapped", [&](std::size_t) { return playhead + step; }, true);
    std::printf(
        "(overlapped: the CPU work of a frame runs while the GPU renders the previous one; its "
        "decode and\n"
        " render columns are not measured per frame)\n");
  }
  loop->set_pipelined(false);
  if (o.frame_ms > 0)
    std::printf(
        "(scale: mean side of the rendered image relative to %dx%d; frame-time target %g ms)\n",
        full_width, full_height, o.frame_ms);
  else
    std::printf("(scale: every frame at %dx%d: --frame-ms 0)\n", full_width, full_height);
  if (!refine_s.empty())
    std::printf("full-resolution image after the view stops: %s s (each phase)\n",
                [&] {
                  std::string list;
                  for (double t : refine_s) {
                    char b[32];
                    std::snprintf(b, sizeof b, "%s%.3f", list.empty() ? "" : ", ", t);
                    list += b;
                  }
                  return list;
                }()
                    .c_str());

  // 4. Random seeks: how long until every visible node is drawn at its target LOD, at full
  //    resolution (the frames while bricks stream in are busy ones).
  std::printf("\nrandom seek to full quality (camera still; %zu seeks):\n", o.seeks);
  camera.azimuth = azimuth0;
  std::vector<double> times;
  for (std::size_t k = 0; k < o.seeks; ++k) {
    // Spread over the timeline (golden-ratio steps from a seeded start), never the same twice.
    playhead = last * std::fmod(0.5 + 0.6180339887 * double(k + 1) + 0.1 * double(o.seed), 1.0);
    const std::uint64_t before = loop->scheduler().loader().bytes_read();
    const auto start = Clock::now();
    std::size_t frames = 0;
    loop::FrameReport r;
    const bool reached = until_full_quality(playhead, frames, r, start);
    const double t = seconds_since(start);
    if (reached) times.push_back(t);
    std::printf("  seek to keyframe %7.2f: %.3f s, %4zu frames, %.1f MB read%s\n", playhead, t,
                frames, double(r.stats.bytes_loaded - before) * 1e-6,
                reached ? "" : short_of_full(r).c_str());
  }
  if (!times.empty()) {
    double sum = 0;
    for (double t : times) sum += t;
    std::printf("  mean %.3f s, worst %.3f s", sum / double(times.size()),
                *std::max_element(times.begin(), times.end()));
  }
  if (times.size() < o.seeks)
    std::printf("%s%zu of the %zu seeks did not reach full quality (above)",
                times.empty() ? "  " : "; ", o.seeks - times.size(), o.seeks);
  if (o.seeks > 0) std::printf("\n");
  loop->finish();
  failures.fail_if_any("the figures above are of frames drawn without them");
}

}  // namespace

void add_bench_play_command(CLI::App& bench) {
  auto o = std::make_shared<BenchPlayOptions>();
  CLI::App* cmd =
      bench.add_subcommand("play",
                           "Player frame rate and frame-time split while playing forward, "
                           "reversing and seeking, and the time from a "
                           "random seek to full quality (--renderer: Vulkan or the CPU ray "
                           "caster)");
  o->loop.size = "512x512";
  cmd->add_option("CONTAINER", o->container, "The container directory NAME.vreel")->required();
  cmd->add_option("--size", o->loop.size, "Image size WxH")
      ->check(image_size())
      ->capture_default_str();
  cmd->add_option("--frames-per-phase", o->frames_per_phase, "Frames measured per phase")
      ->check(in_range(1, 1 << 20))
      ->capture_default_str();
  cmd->add_option("--seeks", o->seeks, "Random seeks timed to full quality")->capture_default_str();
  cmd->add_option("--speed", o->speed, "Playback rate, keyframes per second")
      ->check(positive())
      ->capture_default_str();
  cmd->add_option("--timeout", o->timeout, "Seconds a seek may take to reach full quality")
      ->check(positive())
      ->capture_default_str();
  cmd->add_option("--frame-ms", o->frame_ms,
                  "Frame-time target while the view is busy (reduced resolution, full when "
                  "still), milliseconds; 0: every frame at full resolution")
      ->check(non_negative())
      ->capture_default_str();
  cmd->add_option("--transfer", o->transfer,
                  "Transfer function: auto (data quantiles), a preset or a JSON file")
      ->capture_default_str();
  add_loop_options(*cmd, o->loop);
  add_renderer_options(*cmd, o->renderer, o->cpu);
  cmd->add_option("--seed", o->seed, "Seed of the seek positions")
      ->check(seed_number())
      ->capture_default_str();
  cmd->callback([o] { run_bench_play(*o); });
}

}  // namespace volreel::cli
