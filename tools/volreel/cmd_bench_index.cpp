// cmd_bench_index.cpp: `volreel bench index NAME.vreel` — the player's spatial index and per-frame
// scheduling at scale (docs/design.md, "Streaming"): the time to open a container (manifest and
// spatial index), the scheduler's time per frame while the playhead plays and after random seeks
// (StreamScheduler::update: the index's time window, priorities, requests, atlas slots, the
// pre-render selection and the SVO), the index's memory and the process's peak resident memory.
// Bricks are read from the container as the player reads them but not decoded or drawn: what is
// measured is what grows with the container, not the renderer.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/player/camera.hpp"
#include "volreel/stream/scheduler.hpp"

namespace volreel::cli {

namespace {

struct BenchIndexOptions {
  std::string container;
  std::string size = "512x512";
  double play_seconds = 10;
  double fps = 30;
  double speed = 1;  ///< keyframes per displayed frame while playing
  std::size_t seeks = 10;
  double settle_seconds = 10;
  std::string index_memory = "128M";
  double atlas_mb = 256;
  std::uint64_t seed = 1;
};

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct Timings {
  std::vector<double> ms;
  void add(double v) { ms.push_back(v); }
  double mean() const {
    return ms.empty() ? 0 : std::accumulate(ms.begin(), ms.end(), 0.0) / double(ms.size());
  }
  double quantile(double q) const {
    if (ms.empty()) return 0;
    std::vector<double> s = ms;
    std::sort(s.begin(), s.end());
    return s[std::min(s.size() - 1, static_cast<std::size_t>(q * double(s.size())))];
  }
  double max() const { return ms.empty() ? 0 : *std::max_element(ms.begin(), ms.end()); }
  void print(const char* what) const {
    std::printf("  %-34s %6zu frames  mean %7.3f ms  p95 %7.3f ms  max %7.3f ms\n", what, ms.size(),
                mean(), quantile(0.95), max());
  }
};

double mib(std::uint64_t bytes) {
  return static_cast<double>(bytes) / (1024.0 * 1024.0);
}

void run_bench_index(const BenchIndexOptions& o) {
  const auto [width, height] = loop::parse_size(o.size);
  if (!(o.atlas_mb > 0)) throw InputError("--atlas-mb: expected a positive size");
  stream::IndexOptions index_options;
  index_options.memory_bytes = format::detail::parse_byte_size(o.index_memory, "--index-memory");

  std::printf("volreel bench index: %s\n%s\n", o.container.c_str(), describe_machine().c_str());
  // 1. Open: manifest, dictionary and the spatial index (whole, or a time window).
  const auto open_start = Clock::now();
  const format::Container container(o.container);
  stream::SchedulerSettings settings;
  // The player's atlas: as many slots as its 16-bit GPU atlas of --atlas-mb.
  settings.atlas_slots = static_cast<std::uint32_t>(std::clamp<std::uint64_t>(
      static_cast<std::uint64_t>(o.atlas_mb * 1024 * 1024) /
          loop::CpuFrameLoop::gpu_slot_bytes(container.manifest().shape()),
      1, 1u << 20));
  stream::StreamScheduler scheduler(container, settings, index_options);
  const double open_s = seconds_since(open_start);
  const stream::SpatialIndex& index = scheduler.index();
  const format::Manifest& m = container.manifest();
  const std::size_t frames = index.frame_count();
  if (frames == 0) throw InputError(o.container + ": the container has no frames");
  std::size_t nodes_per_frame = index.node_count();
  std::printf(
      "container: %zu frames of %ux%ux%u, %zu octree nodes a frame (%.3g keyframe nodes at "
      "most), max keyframe gap %u\n",
      frames, m.dims[0], m.dims[1], m.dims[2], nodes_per_frame,
      static_cast<double>(nodes_per_frame) * static_cast<double>(frames), m.max_keyframe_gap);
  std::printf("index: %s, %zu frames held at once (--index-memory %s)\n",
              index.windowed() ? "time window" : "whole container", index.window_frames(),
              o.index_memory.c_str());
  std::printf("atlas: %u brick slots (--atlas-mb %g)\n", settings.atlas_slots, o.atlas_mb);
  std::printf("open (manifest, dictionary, index): %.3f s\n\n", open_s);

  player::OrbitCamera camera =
      player::OrbitCamera::framing({static_cast<double>(m.dims[0]), static_cast<double>(m.dims[1]),
                                    static_cast<double>(m.dims[2])},
                                   width, height);
  std::uint64_t frame_number = 0;
  std::uint64_t index_bytes = 0;
  const double frame_s = 1.0 / o.fps;
  // One displayed frame: the scheduler's update timed, the camera orbiting, paced at --fps.
  const auto step = [&](double playhead, Timings& t) {
    const auto start = Clock::now();
    const stream::FrameUpdate u = scheduler.update(camera, playhead, ++frame_number);
    t.add(1e3 * seconds_since(start));
    scheduler.retire(frame_number);
    index_bytes = std::max(index_bytes, index.memory_bytes());
    camera.azimuth += 2.0 * 3.14159265358979 * frame_s / 20.0;  // a turn in 20 s
    const double left = frame_s - seconds_since(start);
    if (left > 0) std::this_thread::sleep_for(std::chrono::duration<double>(left));
    return u.stats;
  };

  // 2. Play from a quarter of the timeline.
  Timings playing;
  const auto last = static_cast<double>(frames - 1);
  double playhead = std::floor(0.25 * last);
  const auto play_frames = static_cast<std::size_t>(o.play_seconds * o.fps);
  std::printf("playing %zu frames at %.0f fps, %.3g keyframes a frame, the camera orbiting...\n",
              play_frames, o.fps, o.speed);
  std::fflush(stdout);
  std::size_t not_ready = 0;
  for (std::size_t i = 0; i < play_frames; ++i) {
    const stream::StreamStats s = step(playhead, playing);
    if (!s.index_ready) ++not_ready;
    playhead = std::fmod(playhead + o.speed, last + 1);
  }

  // 3. Random seeks: frames until the index holds the playhead's frames, and until the view is
  // settled: every visible node at its target level of detail, or nothing left to load for it
  // (the atlas full of what the view needs most).
  Timings seeking;
  std::vector<double> to_index, to_settled, settled_fraction;
  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> uniform(0.0, last);
  std::size_t unsettled = 0;
  std::printf("%zu random seeks...\n", o.seeks);
  std::fflush(stdout);
  for (std::size_t k = 0; k < o.seeks; ++k) {
    playhead = std::round(uniform(rng));
    const auto start = Clock::now();
    double index_s = -1;
    int idle = 0;
    bool settled = false;
    while (seconds_since(start) < o.settle_seconds) {
      const stream::StreamStats s = step(playhead, seeking);
      if (index_s < 0 && s.index_ready) index_s = seconds_since(start);
      idle = s.index_ready && s.quiet() ? idle + 1 : 0;
      if (s.index_ready && (s.fraction_at_target >= 1.0 || idle >= 3)) {
        settled = true;
        settled_fraction.push_back(s.fraction_at_target);
        break;
      }
    }
    if (index_s >= 0) to_index.push_back(index_s);
    if (settled)
      to_settled.push_back(seconds_since(start));
    else
      ++unsettled;
  }

  const auto mean = [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
  };
  const auto worst = [](const std::vector<double>& v) {
    return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end());
  };
  std::printf("\nscheduler update per frame:\n");
  playing.print("playing");
  seeking.print("after seeks (until settled)");
  std::printf("  frames played without the playhead's frames indexed: %zu of %zu\n", not_ready,
              play_frames);
  std::printf(
      "seek: the playhead's frames indexed after %.3f s (worst %.3f s); view settled after %.3f s "
      "(worst %.3f s), %.0f %% of the visible nodes then at their target level of detail",
      mean(to_index), worst(to_index), mean(to_settled), worst(to_settled),
      100 * mean(settled_fraction));
  if (unsettled > 0)
    std::printf("; %zu seeks not settled within %g s", unsettled, o.settle_seconds);
  std::printf("\n");
  const stream::StreamStats last_stats = scheduler.update(camera, playhead, ++frame_number).stats;
  std::printf(
      "index memory: %.1f MiB at most (%zu keyframe nodes held now, frames %u..%u); peak "
      "resident memory of the process: %.1f MiB\n",
      mib(index_bytes), index.keyframe_count(), index.held_begin(),
      index.held_end() > 0 ? index.held_end() - 1 : 0, mib(peak_resident_bytes()));
  std::printf(
      "last frame: %u nodes at their target level of detail (%.0f %% drawn at it), %u holes, "
      "%u keyframe nodes selected, atlas %u of %u slots, SVO %u nodes\n",
      last_stats.target_nodes, 100 * last_stats.fraction_at_target, last_stats.holes,
      last_stats.selected, last_stats.atlas_occupied, last_stats.atlas_capacity,
      last_stats.svo_nodes);
  std::printf("bricks read: %llu (%.1f MB); scheduler errors: %zu\n",
              static_cast<unsigned long long>(last_stats.bricks_loaded),
              1e-6 * static_cast<double>(last_stats.bytes_loaded), scheduler.error_count());
  for (const std::string& e : scheduler.errors()) std::printf("  error: %s\n", e.c_str());
  if (scheduler.error_count() > 0)
    throw InputError(std::to_string(scheduler.error_count()) +
                     " reads of bricks failed (listed above): the figures are of a run without "
                     "them");
}

}  // namespace

void add_bench_index_command(CLI::App& bench) {
  auto o = std::make_shared<BenchIndexOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "index",
      "The player's spatial index and scheduling at scale: time to open the container (manifest, "
      "dictionary,\n"
      "spatial index), the scheduler's time per frame while playing and after random seeks, the "
      "time until a\n"
      "seek's frames are indexed and the view settles (every visible node at its target level), "
      "the "
      "index's memory and the process's "
      "peak resident\n"
      "memory. Bricks are read as the player reads them, not decoded or drawn. `volreel gen "
      "mosaic` writes a\n"
      "large container to measure.");
  cmd->add_option("CONTAINER", o->container, "Container directory NAME.vreel")->required();
  cmd->add_option("--size", o->size, "Viewport WIDTHxHEIGHT (sets the levels of detail wanted)")
      ->capture_default_str();
  cmd->add_option("--play-seconds", o->play_seconds, "Seconds of playback")
      ->check(in_range(0, 3600))
      ->capture_default_str();
  cmd->add_option("--fps", o->fps, "Displayed frames per second (the loop is paced)")
      ->check(in_range(1, 1000))
      ->capture_default_str();
  cmd->add_option("--speed", o->speed, "Keyframes the playhead advances a displayed frame")
      ->check(in_range(0, 1000))
      ->capture_default_str();
  cmd->add_option("--seeks", o->seeks, "Random seeks after playing")
      ->check(in_range(0, 1e6))
      ->capture_default_str();
  cmd->add_option("--settle-seconds", o->settle_seconds,
                  "Longest wait after a seek for the view to settle")
      ->check(in_range(0.1, 600))
      ->capture_default_str();
  cmd->add_option("--index-memory", o->index_memory,
                  "Keyframe nodes the index may hold (e.g. 128M, 1G); a container that needs "
                  "more is indexed as a time window around the playhead, of at least 2 * the "
                  "max keyframe gap + 4 frames (0: that smallest window)")
      ->capture_default_str();
  cmd->add_option("--atlas-mb", o->atlas_mb,
                  "Brick atlas memory budget, MiB, as the player's: its slots")
      ->check(in_range(1, 1048576))
      ->capture_default_str();
  cmd->add_option("--seed", o->seed, "Seed of the random seeks")
      ->check(seed_number())
      ->capture_default_str();
  cmd->callback([o] { run_bench_index(*o); });
}

}  // namespace volreel::cli
