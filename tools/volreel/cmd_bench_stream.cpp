// cmd_bench_stream.cpp: `volreel bench stream NAME.vreel` — the streaming benchmark of the player
// (docs/design.md, "Streaming"). A scripted tour (play forward, reverse, random seeks, camera
// moves) is replayed against a player's clock, by default a simulated one: frame k is drawn at tour
// time k/fps and the loader's link (bandwidth, latency) runs on the same clock, so a run is the
// same on any machine whatever the CPU renderer's speed, and the policies are compared without
// noise. With --clock wall each frame samples the tour at the wall-clock time since the start
// instead (the loader then runs in real time; results vary with the machine's load). Every frame
// runs the whole streaming loop on the CPU (loop::CpuFrameLoop):
//   1. StreamScheduler::update(camera, playhead, frame) — priorities, requests, arrivals, slots,
//      pre-render selection and the array-encoded SVO;
//   2. each upload decoded into its CpuAtlas slot (CPU reference decoder);
//   3. cpu_render::render_svo with the frame's SVO;
//   4. the frame retired.
// The timed loop only records the frame's image, camera, playhead and statistics; the ground truth
// (cpu_render::render_reference of the original series, the two frames around the playhead
// interpolated in time) is rendered after the run, and each frame's image PSNR and SSIM measured
// against it. The same tour runs with the patent's priorities and with the nearest-keyframe-first
// baseline at the same bandwidth, printed side by side, with two checks: the patent's policy draws
// better images than the baseline, and no frame has a hole once the root brick arrived.
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/cpu_render/tour.hpp"
#include "volreel/format/container.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/stream_bench/bench_stream.hpp"
#include "volreel/stream_bench/run_report.hpp"
#include "volreel/stream_bench/run_summary.hpp"
#include "volreel/stream_bench/tour_run.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;
namespace sb = stream_bench;

struct BenchStreamOptions {
  std::string container, series, out;
  sb::BenchStreamSettings s;
  ReaderOptions reader;
};

/// Each long step of the library on its own progress bar.
void stage(const std::string& title, const std::string& unit,
           const std::function<void(const sb::Progress&)>& step) {
  ProgressBar bar(title, unit);
  step([&bar](double done, double total, const std::string& status) {
    bar.update({done, total, status});
  });
  bar.finish();
}

void run_bench_stream(const BenchStreamOptions& o) {
  // 1. Settings (all checked before any work), the container, the tour, the link, the truth.
  const sb::BenchStreamSettings& s = o.s;
  s.check();
  const auto [width, height] = s.image_size();
  const double latency = s.latency_s();
  if (!fs::is_directory(o.container))
    throw InputError(o.container + ": not a container folder (NAME.vreel)");
  const format::Container container(o.container);
  const format::Manifest& m = container.manifest();
  if (container.frame_count() == 0) throw InputError(o.container + ": the container has no frames");
  const cpu_render::TourContext context = cpu_render::TourContext::of(m);
  const cpu_render::Tour tour = s.tour.empty()
                                    ? sb::bench_tour(context, s.duration, s.seed, width, height)
                                    : cpu_render::Tour::load(s.tour, context);
  // Playing every brick of the volume at the tour's fastest speed needs this many bytes per second.
  const double play_speed = sb::tour_play_speed(tour);
  const double playback_rate = static_cast<double>(container.total_bytes()) /
                               static_cast<double>(container.frame_count()) * play_speed;
  const double bandwidth = sb::bench_bandwidth(s.bandwidth, playback_rate);
  const fs::path out = sb::bench_out_dir(o.out);
  std::string truth_note;
  sb::GroundTruth truth(
      container, sb::open_original(o.series, o.reader.to_open_options(), container, truth_note));
  const std::string transfer_spec = s.transfer_spec();
  auto transfer = sb::bench_transfer(transfer_spec, container, truth);
  std::vector<std::string> index_errors;
  const stream::SpatialIndex index = stream::build_spatial_index(container, &index_errors);
  for (const std::string& e : index_errors)
    std::fprintf(stderr, "volreel: warning: %s\n", e.c_str());
  const sb::SchedulerSetup sched = sb::scheduler_setup(s, bandwidth, latency, index);
  const sb::RunSetup setup = sb::run_setup(s, container, index, index_errors.size(), sched.settings,
                                           width, height, std::move(transfer));
  const stream::SchedulerSettings& ss = setup.settings;

  const auto seeks = sb::tour_seeks(tour);
  std::printf("volreel bench stream\nmachine: %s\n", describe_machine().c_str());
  std::printf(
      "input:   %s: %ux%ux%u, %zu frames, %u levels, %s, %s in all (mean brick %.0f bytes)\n",
      o.container.c_str(), m.dims[0], m.dims[1], m.dims[2], container.frame_count(),
      truth.geometry().levels, m.codec == format::Codec::ksvd ? "ksvd" : "zfp",
      stream_bench::mb_text(static_cast<double>(container.total_bytes())).c_str(),
      sched.brick_bytes);
  std::printf("truth:   %s\n", truth.original()
                                   ? ("the original series (" + truth_note + ")").c_str()
                                   : truth_note.c_str());
  char clock_text[96];
  if (setup.simulated_fps > 0)
    std::snprintf(clock_text, sizeof clock_text, "simulated clock, %g frames per tour second",
                  setup.simulated_fps);
  else
    std::snprintf(clock_text, sizeof clock_text, "wall clock (tour time = seconds since start)");
  std::printf(
      "tour:    %s, %.1f s, %zu seeks; %s\n",
      s.tour.empty()
          ? "built-in bench tour (play, reverse, 5 random seeks, pauses, slow motion, orbit, zoom)"
          : s.tour.c_str(),
      tour.duration(), seeks.size(), clock_text);
  if (s.seeds > 1)
    std::printf(
        "         %u tours, seeds %llu to %llu (their seeks differ), each run with both policies\n",
        s.seeds, static_cast<unsigned long long>(s.seed),
        static_cast<unsigned long long>(s.seed + s.seeds - 1));
  std::printf(
      "render:  CPU ray caster, %dx%d, step %g voxel, transfer function: %s\n", width, height,
      s.step,
      transfer_spec == "auto" ? "auto (quantiles of the middle frame)" : transfer_spec.c_str());
  std::printf(
      "stream:  bandwidth %s, latency %g ms, %zu requests in flight at most, %u atlas slots%s, SSE "
      "target %g px\n",
      sb::rate_text(bandwidth).c_str(), latency * 1e3, ss.loader.max_in_flight, ss.atlas_slots,
      sched.atlas_capped ? " (every brick of the container)" : "", s.sse_target);
  if (playback_rate > 0)
    std::printf(
        "         playing the whole volume at the tour's fastest speed (%.3g keyframes/s) needs "
        "%s: the link "
        "carries %s of it\n",
        play_speed, sb::rate_text(playback_rate).c_str(),
        bandwidth > 0
            ? (std::to_string(static_cast<int>(std::lround(100 * bandwidth / playback_rate))) +
               " %")
                  .c_str()
            : "all");
  std::printf(
      "patent:  priority = %g*SSE/(1+SSE) + lerp(random, temporal, lerp(%g, 1, temporal)), "
      "temporal exponent %g;\n"
      "         SSE of %s\n",
      s.sse_weight, s.temporal_lerp_min, ss.priority.temporal_exponent,
      s.sse_priority == "node" ? "the node ([0042])"
                               : "the node's level (the largest of its visible nodes)");
  if (s.due_window)
    std::printf(
        "         due window first: the keyframes around the playhead and those it reaches within "
        "%g s; the\n"
        "         rest ([0045] order) holds at most %g s of the link in flight\n",
        s.lookahead, s.speculative_link);
  else
    std::printf("         no due window (--due-window off): every keyframe node by [0045] alone\n");
  std::fflush(stdout);
  // 2. The runs (timed), then the ground truth of each; with --seeds, once per tour, each tour's
  //    files in OUT/seed_S.
  const std::vector<sb::TourRuns> tours =
      sb::run_tours(s, setup, tour, context, truth, out, stage, [&](const sb::TourRuns& tr) {
        if (s.seeds == 1) return;
        std::printf("\ntour seed %llu:\n", static_cast<unsigned long long>(tr.seed));
        sb::print_side_by_side(tr.runs);
      });

  // 3. Side by side, the targets, the files.
  std::printf(
      "\nimage PSNR = 10*log10(255^2/MSE) over 8-bit RGB against the ground truth (frames "
      "identical to it count as %.0f dB); SSIM: per channel, averaged\n",
      sb::psnr_cap_db);
  if (s.seeds == 1) sb::print_side_by_side(tours.front().runs);
  nlohmann::json summary = sb::bench_summary_json(
      s, o.container, setup, {bandwidth, latency, playback_rate}, truth.original(), tours);
  const auto patent = sb::policy_totals(tours, "patent");
  const auto nearest = sb::policy_totals(tours, "nearest");
  if (s.seeds > 1) sb::print_tour_table(tours, patent, nearest);
  const char* over = s.seeds > 1 ? " (mean over the tours)" : "";
  std::printf("\nchecks:\n");
  if (patent && nearest) {
    const bool higher = patent->mean_psnr > nearest->mean_psnr;
    std::printf(
        "  patent's mean image PSNR higher than nearest-keyframe-first%s: %s (%.2f vs %.2f dB, "
        "%+.2f dB)\n",
        over, higher ? "yes" : "NO", patent->mean_psnr, nearest->mean_psnr,
        patent->mean_psnr - nearest->mean_psnr);
    summary["target_higher_psnr"] = higher;
  }
  if (patent) {
    const bool no_holes = patent->holes == 0 && patent->roots;
    std::printf(
        "  patent: no frame with a hole after the first root brick arrived: %s (%zu of %zu frames "
        "have holes)\n",
        no_holes ? "yes" : "NO", patent->holes, patent->frames);
    summary["target_no_holes"] = no_holes;
  }
  if (!truth.original())
    std::printf(
        "  (ground truth is the container's own decode, so PSNR measures streaming loss only)\n");
  {
    std::ofstream js(out / "summary.json");
    js << summary.dump(1) << '\n';
    if (!js) throw InputError("writing " + (out / "summary.json").string() + " failed");
  }
  std::printf(
      "\nwrote %s: %sstream_<policy>.csv (per frame), summary.json, %stour.json, "
      "%sframes_<policy>/frame_NNNNN.png "
      "(streamed | ground truth)\n",
      out.c_str(), s.seeds > 1 ? "seed_S/" : "", s.seeds > 1 ? "seed_S/" : "",
      s.seeds > 1 ? "seed_S/" : "");
}

}  // namespace

void add_bench_stream_command(CLI::App& bench) {
  auto o = std::make_shared<BenchStreamOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "stream",
      "Streaming benchmark: replay a tour (play, reverse, random seeks, camera moves) with the CPU "
      "renderer,\n"
      "streaming bricks through a bandwidth- and latency-limited loader, once with the patent's "
      "priorities and\n"
      "once nearest-keyframe-first. By default the tour and the link run on a simulated clock "
      "(--fps frames per\n"
      "tour second), so results do not depend on the machine's speed or load; --clock wall replays "
      "in real time. Per frame and averaged: image PSNR/SSIM against a render of the\n"
      "original data at that playhead, fraction of nodes at target LOD, holes, bytes loaded, time "
      "to full quality\n"
      "after each seek. Writes OUT/stream_<policy>.csv, OUT/summary.json and a few PNGs.");
  cmd->add_option("CONTAINER", o->container, "The container directory NAME.vreel")->required();
  cmd->add_option("--bandwidth", o->s.bandwidth,
                  "Simulated read bandwidth: a rate (20MB/s, 500kB/s), a multiple of the playback "
                  "data rate (0.5x: half\n"
                  "of what playing every brick at the tour's fastest speed needs), or 0/unlimited")
      ->capture_default_str();
  cmd->add_option("--latency", o->s.latency, "Simulated latency per request, e.g. 50ms, 0.2s")
      ->capture_default_str();
  cmd->add_option("--tour", o->s.tour,
                  "Tour JSON (player/cpu_render tour.hpp); default: the built-in bench tour of "
                  "--duration seconds");
  cmd->add_option("--duration", o->s.duration, "Length of the built-in bench tour, seconds")
      ->capture_default_str();
  cmd->add_option("--seed", o->s.seed, "Seed of the built-in tour's random seeks")
      ->capture_default_str();
  cmd->add_option("--seeds", o->s.seeds,
                  "Replay this many built-in tours (seeds --seed, --seed + 1, ...): with five "
                  "seeks a tour, which time\n"
                  "steps a policy happened to hold decides much of a fast link's result; the "
                  "targets use the mean")
      ->capture_default_str();
  cmd->add_option("--clock", o->s.clock,
                  "simulated: frame k at tour time k/fps, the link on the same clock "
                  "(deterministic); wall: the tour\n"
                  "and the link in real time")
      ->capture_default_str();
  cmd->add_option("--fps", o->s.fps, "Simulated clock: frames drawn per tour second")
      ->capture_default_str();
  cmd->add_option(
      "--series", o->series,
      "Original series for the ground truth (raw series directory, HDF5 or raw file); default: "
      "the\n"
      "manifest's source if that path exists, else the container's own finest-level decode");
  cmd->add_option("--size", o->s.size, "Image size WxH (the tour's own size is not used)")
      ->capture_default_str();
  cmd->add_option("--atlas-slots", o->s.atlas_slots,
                  "Brick slots of the atlas (= heap capacity); the default is what 256 MiB of a "
                  "16-bit GPU atlas holds")
      ->capture_default_str();
  cmd->add_option("--max-in-flight", o->s.max_in_flight,
                  "Requests in flight at most (default: what the link delivers in latency + 0.5 s, "
                  "at least 32)");
  cmd->add_option("--io-threads", o->s.io_threads, "Loader threads")->capture_default_str();
  cmd->add_option("--policy", o->s.policy, "both, patent or nearest (nearest-keyframe-first)")
      ->capture_default_str();
  cmd->add_option(
      "--transfer", o->s.transfer,
      "Transfer function: auto (quantiles of the data), tour (the tour's), a preset (grayscale, "
      "cool-warm,\n"
      "fire, turbulence) or a JSON file; default: auto without --tour, the tour's with one");
  cmd->add_option("--sse-target", o->s.sse_target, "Screen-space error target, pixels per voxel")
      ->capture_default_str();
  cmd->add_option("--sse-weight", o->s.sse_weight,
                  "Patent policy: weight of the SSE priority ([0045]: 10)")
      ->capture_default_str();
  cmd->add_option("--temporal-lerp-min", o->s.temporal_lerp_min,
                  "Patent policy: weight of the temporal priority against the random one at "
                  "temporal 0 ([0045]: 0.15;\n"
                  "1: the temporal priority alone, measured best)")
      ->capture_default_str();
  cmd->add_option(
         "--temporal-exponent", o->s.temporal_exponent,
         "Both policies: exponent of temporalPriority = (1 - distance/maxDistance)^e ([0043]: 4)")
      ->capture_default_str();
  cmd->add_option(
         "--sse-priority", o->s.sse_priority,
         "Patent policy: the SSE behind ssePriority: level (the largest SSE of the node's level in "
         "view,\n"
         "so that a full atlas keeps whole keyframes) or node (the node's own, [0042] literally)")
      ->check(CLI::IsMember({"level", "node"}))
      ->capture_default_str();
  cmd->add_option("--due-window", o->s.due_window,
                  "Patent policy: request first the keyframes the playhead needs now (the two "
                  "around it) and those\n"
                  "it reaches within --lookahead seconds at its current speed and direction, "
                  "before the rest by\n"
                  "[0045] (true/false; false: [0045] alone)")
      ->capture_default_str();
  cmd->add_option("--lookahead", o->s.lookahead,
                  "Patent policy, due window: seconds of playback ahead of the playhead whose "
                  "keyframes are due")
      ->capture_default_str();
  cmd->add_option("--speculative-link", o->s.speculative_link,
                  "Patent policy, due window: requests outside it (the [0045] order: coarse levels "
                  "of the whole\n"
                  "timeline, then farther keyframes) hold at most this many seconds of the link in "
                  "flight, so the\n"
                  "keyframes the playhead needs next never wait behind more (0: no bound)")
      ->capture_default_str();
  cmd->add_option(
         "--ancestor-handicap", o->s.ancestor_handicap,
         "Both policies, pre-render selection: an ancestor's keyframe distance is multiplied by\n"
         "exp(h * levels up) ([0046]: 4)")
      ->capture_default_str();
  cmd->add_option("--step", o->s.step, "Ray step, finest voxels (the ground truth uses the same)")
      ->capture_default_str();
  cmd->add_option("--upload-budget", o->s.upload_budget_mb,
                  "Compressed bytes uploaded per frame at most, MB")
      ->capture_default_str();
  cmd->add_option("--png-every", o->s.png_every,
                  "Write every Nth frame as a PNG (default: the frames just after each seek, half "
                  "a second later, and "
                  "the last)");
  cmd->add_option("--out", o->out,
                  "Output folder (default: a new folder in /tmp, printed at the end)");
  o->reader.add_to(*cmd);
  cmd->callback([o] { run_bench_stream(*o); });
}

}  // namespace volreel::cli
