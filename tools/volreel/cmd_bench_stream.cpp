// cmd_bench_stream.cpp: `volreel bench stream NAME.vreel` — the streaming benchmark of the player
// (docs/design.md, "Streaming"; the library: volreel/stream_bench/bench_stream.hpp). Its options,
// then prepare_bench and run_tours, then the header, the side-by-side tables, the checks and the
// files written.
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "remote_options.hpp"
#include "volreel/stream_bench/bench_stream.hpp"
#include "volreel/stream_bench/run_report.hpp"
#include "volreel/stream_bench/tour_run.hpp"

namespace volreel::cli {

namespace {

namespace sb = stream_bench;

struct BenchStreamOptions {
  std::string container, series, out;
  sb::BenchStreamSettings s;
  ReaderOptions reader;
  RemoteCli remote;
};

/// Each long step of the library on its own progress bar; Ctrl-C or SIGTERM (StopOnSignal) stops
/// it at the next update.
void stage(const std::string& title, const std::string& unit,
           const std::function<void(const sb::Progress&)>& step) {
  ProgressBar bar(title, unit);
  step([&bar](double done, double total, const std::string& status) {
    stop_if_interrupted();
    bar.update({done, total, status});
  });
  bar.finish();
}

/// run_bench_stream's work, up to the files written into `folder` (--out, or where this run
/// stages its files for it; empty: a new temporary folder, which *made names); returns how many
/// reads of bricks or frames failed while streaming (the runs' figures are of frames drawn
/// without them).
std::size_t run_bench_stream_into(const BenchStreamOptions& o, const std::string& folder,
                                  std::filesystem::path* made) {
  // 1. Settings (all checked before any work), the container, the tour, the link, the truth.
  const sb::BenchStreamSettings& s = o.s;
  if (!o.remote.cache.empty() && remote::is_url(o.container) &&
      (s.policies().size() > 1 || s.seeds > 1))
    throw InputError(
        "--cache with " +
        std::string(s.seeds > 1 ? "--seeds " + std::to_string(s.seeds) : "--policy both") +
        ": every run after the first would read the bricks the first kept from the cache "
        "instead of the server, and the runs would not compare; with --cache give --policy "
        "patent or nearest and --seeds 1 (a second invocation then measures the warm start)");
  const sb::BenchPlan plan = sb::prepare_bench(
      s, o.container, o.series, o.reader.to_open_options(), folder,
      remote::is_url(o.container) ? open_container_source(o.container, o.remote) : nullptr);
  if (folder.empty()) *made = plan.out;
  const sb::RunSetup& setup = plan.setup;
  const sb::GroundTruth& truth = *plan.truth;
  const std::string shown = remote::without_credentials(o.container);  // no password printed
  sb::print_bench_header(plan, s, shown, describe_machine());
  std::fflush(stdout);
  // 2. The runs (timed), then the ground truth of each; with --seeds, once per tour, each tour's
  //    files in OUT/seed_S.
  const std::vector<sb::TourRuns> tours =
      sb::run_tours(s, setup, *plan.tour, plan.context, *plan.truth, plan.out, stage,
                    [&](const sb::TourRuns& tr) {
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
  nlohmann::json summary =
      sb::bench_summary_json(s, shown, setup, plan.link, truth.original(), tours);
  const auto patent = sb::policy_totals(tours, "patent");
  const auto nearest = sb::policy_totals(tours, "nearest");
  if (s.seeds > 1) sb::print_tour_table(tours, patent, nearest);
  sb::print_checks(summary, patent, nearest, s.seeds > 1, truth.original());
  {
    std::ofstream js(plan.out / "summary.json");
    js << summary.dump(1) << '\n';
    if (!js) throw InputError("writing " + (plan.out / "summary.json").string() + " failed");
  }
  std::printf(
      "\nwrote %s: %sstream_<policy>.csv (per frame), summary.json, %stour.json, "
      "%sframes_<policy>/frame_NNNNN.png "
      "(streamed | ground truth)\n",
      o.out.empty() ? plan.out.c_str() : o.out.c_str(), s.seeds > 1 ? "seed_S/" : "",
      s.seeds > 1 ? "seed_S/" : "", s.seeds > 1 ? "seed_S/" : "");
  std::size_t errors = 0;
  for (const sb::TourRuns& tour : tours)
    for (const sb::RunResult& run : tour.runs) errors += run.errors;
  return errors;
}

void run_bench_stream(const BenchStreamOptions& o) {
  namespace fs = std::filesystem;
  const StopOnSignal stop;
  // Nothing half-written on a failure or Ctrl-C: a --out that does not exist is created by the
  // run and removed (with the parents it created) if the run fails; into one that exists the run
  // writes a staging folder beside it, whose files replace those of the same names in --out only
  // once all are written. Without --out, the temporary folder made is removed.
  std::error_code ec;
  fs::path remove_on_failure, staging;
  if (!o.out.empty()) {
    // Not there at all (file_type::none instead when it cannot be told, as without permission).
    const auto missing = [&](const fs::path& p) {
      return fs::symlink_status(p, ec).type() == fs::file_type::not_found;
    };
    if (missing(o.out)) {
      remove_on_failure = fs::absolute(o.out, ec);
      while (remove_on_failure.has_relative_path() && missing(remove_on_failure.parent_path()))
        remove_on_failure = remove_on_failure.parent_path();
    } else if (fs::is_directory(o.out, ec)) {
      staging = fs::path(o.out).lexically_normal();
      if (!staging.has_filename()) staging = staging.parent_path();
      staging += ".partial-" + std::to_string(::getpid());
      remove_on_failure = staging;
    }
  }
  fs::path made;
  std::size_t errors = 0;
  try {
    errors = run_bench_stream_into(o, staging.empty() ? o.out : staging.string(), &made);
    if (!staging.empty()) {
      for (const fs::directory_entry& e : fs::directory_iterator(staging)) {
        const fs::path target = fs::path(o.out) / e.path().filename();
        fs::remove_all(target);
        fs::rename(e.path(), target);
      }
      fs::remove(staging);
    }
  } catch (...) {
    if (!remove_on_failure.empty()) fs::remove_all(remove_on_failure, ec);
    if (!made.empty()) fs::remove_all(made, ec);
    throw;
  }
  // The files are written (runs drawn without what failed); the exit status says it failed.
  if (errors)
    throw InputError(std::to_string(errors) +
                     " reads of bricks or frames failed while streaming, over the runs of every "
                     "policy (the warnings above name the files): the runs' figures are of frames "
                     "drawn without them");
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
  cmd->add_option("CONTAINER", o->container, container_argument_help)->required();
  cmd->add_option(
         "--bandwidth", o->s.bandwidth,
         "Simulated read bandwidth: a rate (20MB/s, 500kB/s), a multiple of the playback "
         "data rate (0.5x: half\n"
         "of what playing every brick at the tour's fastest speed needs), or 0/unlimited.\n"
         "For a URL the network is the link: the rate is not simulated, only planned "
         "for (use --clock wall)")
      ->capture_default_str();
  cmd->add_option("--latency", o->s.latency, "Simulated latency per request, e.g. 50ms, 0.2s")
      ->capture_default_str();
  cmd->add_option("--tour", o->s.tour,
                  "Tour JSON (player/cpu_render tour.hpp); default: the built-in bench tour of "
                  "--duration seconds");
  cmd->add_option("--duration", o->s.duration, "Length of the built-in bench tour, seconds")
      ->capture_default_str();
  cmd->add_option("--seed", o->s.seed, "Seed of the built-in tour's random seeks")
      ->check(seed_number())
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
                  "16-bit GPU atlas holds\nin bricks of 36^3 (in bricks of 66^3 it holds 466)")
      ->capture_default_str();
  cmd->add_option("--max-in-flight", o->s.max_in_flight,
                  "Requests in flight at most (default, or 0: what the link delivers in latency + "
                  "0.5 s, 32 to 4096)");
  cmd->add_option("--io-threads", o->s.io_threads, "Loader threads")->capture_default_str();
  cmd->add_option("--policy", o->s.policy, "both, patent or nearest (nearest-keyframe-first)")
      ->capture_default_str();
  cmd->add_option(
      "--transfer", o->s.transfer,
      "Transfer function: auto (quantiles of the data), tour (the tour's), a preset (grayscale, "
      "cool-warm,\n"
      "fire, turbulence, transparent) or a JSON file; default: auto without --tour, the tour's "
      "with one");
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
  cmd->add_option("--ray-feedback", o->s.ray_feedback,
                  "Both policies: leave out of the selection the nodes no ray reached in the "
                  "last frame drawn\n"
                  "(behind opaque material, outside the image), from the renderer's feedback "
                  "(true/false)")
      ->capture_default_str();
  cmd->add_option("--lod-fade", o->s.lod_fade,
                  "Both policies: a node whose own bricks arrive while an ancestor draws it fades "
                  "in from the\n"
                  "parent's drawing over this many seconds instead of replacing it at once (0: at "
                  "once)")
      ->capture_default_str();
  cmd->add_option("--lod-fade-out", o->s.lod_fade_out,
                  "Both policies: a node whose children drew it in the last frame and that is now "
                  "drawn by itself\n"
                  "keeps drawing them, fading to its own drawing over this many seconds (0: at "
                  "once)")
      ->capture_default_str();
  cmd->add_option("--restricted", o->s.restricted,
                  "Both policies: a restricted working set, the view's target nodes that touch "
                  "differing by at\n"
                  "most one level (a coarser neighbour is refined too) (true/false)")
      ->capture_default_str();
  cmd->add_option("--restricted-drawing", o->s.restricted_drawing,
                  "Both policies: regions drawn from data more than one level finer than a "
                  "region they touch\n"
                  "are drawn coarser, while bricks stream in (true/false)")
      ->capture_default_str();
  cmd->add_option("--spatial-blend", o->s.spatial_blend,
                  "Both policies: a node's corners next to a coarser neighbour take its parent's "
                  "drawing, so\n"
                  "that the level of detail changes smoothly across the boundary (true/false)")
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
                  "Write every Nth frame as a PNG (default, or 0: the frames just after each "
                  "seek, half a second later, and the last)");
  cmd->add_option("--out", o->out,
                  "Output folder (default: a new folder in /tmp, printed at the end)");
  o->reader.add_to(*cmd);
  add_remote_options(*cmd, o->remote);
  cmd->callback([o] { run_bench_stream(*o); });
}

}  // namespace volreel::cli
