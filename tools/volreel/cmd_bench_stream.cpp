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
#include <stdlib.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/tour.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/stream_bench/run_report.hpp"
#include "volreel/stream_bench/run_summary.hpp"
#include "volreel/stream_bench/tour_run.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;
using stream_bench::GroundTruth;
using stream_bench::psnr_cap_db;
using stream_bench::RunResult;
using stream_bench::RunSetup;

struct BenchStreamOptions {
  std::string container, tour, series, out, transfer;
  std::string size = "192x192";
  std::string bandwidth = "20MB/s", latency = "50ms";
  std::string policy = "both";
  std::uint32_t atlas_slots = 2876;
  std::size_t max_in_flight = 0;  ///< 0: from the bandwidth (see run_bench_stream)
  unsigned io_threads = 4;
  double duration = 20;
  std::string clock = "simulated";
  double fps = 10;  ///< simulated clock: frames per tour second
  // The scheduler's defaults (stream::PrioritySettings, SchedulerSettings, SelectionSettings).
  double sse_target = stream::PrioritySettings{}.sse_target;
  double sse_weight = stream::PrioritySettings{}.sse_weight,
         temporal_lerp_min = stream::PrioritySettings{}.temporal_lerp_min,
         temporal_exponent = stream::PrioritySettings{}.temporal_exponent;
  bool due_window = stream::PrioritySettings{}.due_window;
  std::string sse_priority = stream::PrioritySettings{}.sse_scope == stream::SseScope::node ? "node" : "level";
  double lookahead = stream::PrioritySettings{}.lookahead_s;
  double speculative_link = stream::SchedulerSettings{}.speculative_link_s;
  double ancestor_handicap = stream::SelectionSettings{}.ancestor_handicap;
  double step = 1.0;
  double upload_budget_mb = 64;
  std::uint64_t seed = 1;
  unsigned seeds = 1;  ///< built-in tours with seeds seed, seed + 1, ...
  std::size_t png_every = 0;
  ReaderOptions reader;
};

[[noreturn]] void bad(const std::string& option, const std::string& expected, const std::string& found) {
  throw InputError(option + ": expected " + expected + ", found '" + found + "'");
}

std::string rate_text(double bytes_per_s) {
  if (!(bytes_per_s > 0)) return "unlimited";
  char s[32];
  std::snprintf(s, sizeof s, "%g MB/s", bytes_per_s * 1e-6);
  return s;
}

// ---------------------------------------------------------------------------------------------
// The built-in bench tour.

/// Play forward over half the timeline, reverse, then five random seeks (each at least a quarter
/// of the timeline away from the playhead) alternating pauses and playback (normal, half and slow
/// speed); the camera orbits once, rises and sinks, and zooms in and out.
cpu_render::Tour bench_tour(const cpu_render::TourContext& context, double duration, std::uint64_t seed,
                            int width, int height) {
  const double last = static_cast<double>(std::max<std::size_t>(context.keyframes, 1) - 1);
  const double d = duration;
  const double speed = std::max(0.5 * last / (0.25 * d), 0.25);
  SplitMix64 rng(seed);
  double playhead = 0;
  const auto seek_target = [&] {
    double r = playhead;
    for (int tries = 0; tries < 100; ++tries) {
      r = std::round(rng.uniform(0, last) * 4) / 4;  // quarter keyframes
      if (std::abs(r - playhead) >= 0.25 * last) break;
    }
    playhead = r;
    return r;
  };
  nlohmann::json segments = nlohmann::json::array();
  const auto play = [&](double seconds, double v, bool forward) {
    segments.push_back({{forward ? "play" : "reverse", seconds}, {"speed", v}});
    playhead = std::clamp(playhead + (forward ? v : -v) * seconds, 0.0, last);
  };
  const auto pause = [&](double seconds) { segments.push_back({{"pause", seconds}}); };
  const auto seek = [&] { segments.push_back({{"seek", seek_target()}}); };
  play(0.25 * d, speed, true);
  play(0.15 * d, speed, false);
  seek();
  pause(0.10 * d);
  seek();
  play(0.15 * d, 0.5 * speed, true);
  seek();
  pause(0.10 * d);
  seek();
  play(0.15 * d, std::min(1.0, speed), true);  // slow: states between keyframes
  seek();
  pause(0.10 * d);

  const player::OrbitCamera f = player::OrbitCamera::framing(
      glm::dvec3(context.dims[0], context.dims[1], context.dims[2]), width, height);
  const double az = glm::degrees(f.azimuth), el = glm::degrees(f.elevation);
  struct Key {
    double at, elevation, zoom;
  };
  const Key keys[] = {{0, 0, 1}, {0.25, 15, 1}, {0.5, -10, 1}, {0.6, -10, 0.6}, {0.75, 10, 0.6}, {1, 0, 1}};
  nlohmann::json camera = nlohmann::json::array();
  for (const Key& k : keys)
    camera.push_back({{"t", k.at * d},
                      {"azimuth", az + 360.0 * k.at},
                      {"elevation", el + k.elevation},
                      {"distance", f.distance * k.zoom},
                      {"target", {f.target.x, f.target.y, f.target.z}},
                      {"fov", glm::degrees(f.fov_y)}});
  const nlohmann::json json = {{"duration", d},        {"fps", 30},
                               {"size", {width, height}}, {"camera", camera},
                               {"segments", segments}, {"transfer", {{{"t", 0}, {"preset", "cool-warm"}}}}};
  return cpu_render::Tour::from_json(json, context, "bench tour");
}

/// Seeks of a tour: two playhead keys at the same time (a cut) — time and target keyframe.
std::vector<std::pair<double, double>> tour_seeks(const cpu_render::Tour& tour) {
  std::vector<std::pair<double, double>> seeks;
  const auto& keys = tour.playhead_keys();
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (keys[i].time == keys[i - 1].time && keys[i].keyframe != keys[i - 1].keyframe)
      seeks.emplace_back(keys[i].time, keys[i].keyframe);
  return seeks;
}

/// The tour's fastest playback, keyframes per tour second (0 when it never plays).
double tour_play_speed(const cpu_render::Tour& tour) {
  double speed = 0;
  const auto& keys = tour.playhead_keys();
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (keys[i].time > keys[i - 1].time)
      speed = std::max(speed, std::abs(keys[i].keyframe - keys[i - 1].keyframe) / (keys[i].time - keys[i - 1].time));
  return speed;
}

/// --bandwidth: a rate (20MB/s), unlimited (or 0), or a multiple of the playback data rate (0.5x).
double bench_bandwidth(const std::string& text, double playback_bytes_per_s) {
  if (text == "unlimited") return 0;
  if (!text.empty() && (text.back() == 'x' || text.back() == 'X')) {
    const std::optional<double> factor = positive_number(text.substr(0, text.size() - 1));
    if (!factor) bad("--bandwidth", "a multiple of the playback data rate such as 0.5x, or a rate such as 20MB/s", text);
    if (!(playback_bytes_per_s > 0))
      throw InputError("--bandwidth " + text + ": the tour never plays, so there is no playback data rate; give a rate such as 1MB/s");
    return *factor * playback_bytes_per_s;
  }
  return loop::parse_bandwidth(text);
}

/// The path inside a manifest's "source" ("raw series DIR", "raw file FILE (f32)", "HDF5 FILE
/// (datasets …)") or the encoder's "series" field.
std::vector<std::string> source_candidates(const format::Manifest& m) {
  std::vector<std::string> out;
  std::string s = m.source;
  for (const char* prefix : {"raw series ", "raw file ", "HDF5 "})
    if (s.rfind(prefix, 0) == 0) {
      s = s.substr(std::string(prefix).size());
      const std::size_t paren = s.rfind(" (");
      if (paren != std::string::npos && s.back() == ')') s.resize(paren);
      break;
    }
  if (!s.empty()) out.push_back(s);
  if (m.encoder.is_object() && m.encoder.contains("series") && m.encoder["series"].is_string())
    out.push_back(m.encoder["series"].get<std::string>());
  return out;
}

/// Opens the original series: --series, else the manifest's source if that path exists (as
/// given, or relative to the container's folder and its parent). nullptr: none found (`note`
/// says why).
std::unique_ptr<datasets::SeriesReader> open_original(const BenchStreamOptions& o, const format::Container& container,
                                                      std::string& note) {
  const format::Manifest& m = container.manifest();
  datasets::OpenOptions options = o.reader.to_open_options();
  if (!options.dims) options.dims = Dims{m.dims[0], m.dims[1], m.dims[2]};
  if (!o.series.empty()) {
    if (!fs::exists(o.series)) throw InputError("--series " + o.series + ": no such file or folder");
    note = "--series " + o.series;
    return datasets::open_series(o.series, options);
  }
  const fs::path dir = fs::absolute(container.directory()).lexically_normal();
  for (const std::string& c : source_candidates(m)) {
    std::vector<fs::path> tries = {fs::path(c)};
    if (fs::path(c).is_relative()) {
      tries.push_back(dir.parent_path() / c);
      tries.push_back(dir.parent_path().parent_path() / c);
    }
    for (const fs::path& p : tries) {
      if (!fs::exists(p)) continue;
      try {
        auto reader = datasets::open_series(p, options);
        note = "the manifest's source " + p.string();
        return reader;
      } catch (const InputError& e) {
        note = "the manifest's source " + p.string() + " could not be opened (" + e.what() + ")";
      }
    }
  }
  if (note.empty()) note = "the manifest's source '" + m.source + "' was not found";
  note = "the container's own finest-level decode (" + note +
         "; pass --series ORIGINAL to measure against the original data)";
  return nullptr;
}

/// --transfer: "tour" (the tour's own), "auto" (quantiles of the ground truth's middle frame), or
/// what the player takes (a preset name or a JSON file: loop::transfer_from_spec).
std::optional<cpu_render::TransferFunction> bench_transfer(const std::string& spec, const format::Container& container,
                                                           GroundTruth& truth) {
  const format::Manifest& m = container.manifest();
  if (spec == "tour") return std::nullopt;
  if (spec == "auto")
    return cpu_render::TransferFunction::from_quantiles(truth.frame(container.frame_count() / 2),
                                                        static_cast<float>(m.value_min), static_cast<float>(m.value_max));
  return loop::transfer_from_spec(spec, container, "--transfer");
}

// ---------------------------------------------------------------------------------------------
// One run of the tour with one priority policy.


/// Progress of a stream_bench step shown on `bar`.
stream_bench::Progress progress_of(ProgressBar& bar) {
  return [&bar](double done, double total, const std::string& status) { bar.update({done, total, status}); };
}

void run_bench_stream(const BenchStreamOptions& o) {
  // 1. Options (all checked before any work).
  const auto [width, height] = loop::parse_size(o.size);
  if (o.bandwidth.empty() || (o.bandwidth.back() != 'x' && o.bandwidth.back() != 'X'))
    bench_bandwidth(o.bandwidth, 0);  // a malformed rate is reported before any work
  const double latency = loop::parse_latency(o.latency);
  if (!(o.duration > 0) || o.duration > 3600) bad("--duration", "seconds in (0, 3600]", std::to_string(o.duration));
  if (o.clock != "simulated" && o.clock != "wall") bad("--clock", "simulated or wall", o.clock);
  if (!(o.fps > 0) || o.fps > 240) bad("--fps", "frames per second in (0, 240]", std::to_string(o.fps));
  if (!(o.sse_target > 0) || !std::isfinite(o.sse_target)) bad("--sse-target", "pixels per voxel > 0", std::to_string(o.sse_target));
  if (!(o.sse_weight >= 0) || !std::isfinite(o.sse_weight)) bad("--sse-weight", "a weight >= 0", std::to_string(o.sse_weight));
  if (!(o.temporal_exponent > 0) || o.temporal_exponent > 64)
    bad("--temporal-exponent", "an exponent in (0, 64]", std::to_string(o.temporal_exponent));
  if (!(o.temporal_lerp_min >= 0 && o.temporal_lerp_min <= 1))
    bad("--temporal-lerp-min", "a weight in [0, 1]", std::to_string(o.temporal_lerp_min));
  if (!(o.ancestor_handicap >= 0) || o.ancestor_handicap > 64)
    bad("--ancestor-handicap", "an exponent in [0, 64]", std::to_string(o.ancestor_handicap));
  if (!(o.speculative_link >= 0) || o.speculative_link > 60)
    bad("--speculative-link", "seconds in [0, 60]", std::to_string(o.speculative_link));
  if (!(o.lookahead >= 0) || o.lookahead > 60) bad("--lookahead", "seconds in [0, 60]", std::to_string(o.lookahead));
  if (!(o.step > 0) || !std::isfinite(o.step)) bad("--step", "a ray step in voxels > 0", std::to_string(o.step));
  if (o.atlas_slots < 1 || o.atlas_slots > (1u << 16)) bad("--atlas-slots", "1..65536 slots", std::to_string(o.atlas_slots));
  if (!(o.upload_budget_mb > 0)) bad("--upload-budget", "MB per frame > 0", std::to_string(o.upload_budget_mb));
  if (o.io_threads < 1 || o.io_threads > 64) bad("--io-threads", "1..64", std::to_string(o.io_threads));
  if (o.seeds < 1 || o.seeds > 100) bad("--seeds", "1..100 tours", std::to_string(o.seeds));
  if (o.seeds > 1 && !o.tour.empty())
    throw InputError("--seeds " + std::to_string(o.seeds) + ": several seeds vary the built-in tour; drop --tour or --seeds");
  std::vector<stream::PriorityPolicy> policies;
  if (o.policy == "both") policies = {stream::PriorityPolicy::patent, stream::PriorityPolicy::nearest_keyframe_first};
  else if (o.policy == "patent") policies = {stream::PriorityPolicy::patent};
  else if (o.policy == "nearest") policies = {stream::PriorityPolicy::nearest_keyframe_first};
  else bad("--policy", "both, patent or nearest", o.policy);
  if (!fs::is_directory(o.container)) throw InputError(o.container + ": not a container folder (NAME.vreel)");
  const format::Container container(o.container);
  const format::Manifest& m = container.manifest();
  if (container.frame_count() == 0) throw InputError(o.container + ": the container has no frames");
  const cpu_render::TourContext context = cpu_render::TourContext::of(m);
  const cpu_render::Tour tour = o.tour.empty() ? bench_tour(context, o.duration, o.seed, width, height)
                                               : cpu_render::Tour::load(o.tour, context);
  // Playing every brick of the volume at the tour's fastest speed needs this many bytes per second.
  const double play_speed = tour_play_speed(tour);
  const double playback_rate =
      static_cast<double>(container.total_bytes()) / static_cast<double>(container.frame_count()) * play_speed;
  const double bandwidth = bench_bandwidth(o.bandwidth, playback_rate);
  fs::path out;
  if (o.out.empty()) {
    char pattern[] = "/tmp/volreel-bench-stream-XXXXXX";
    if (!::mkdtemp(pattern)) throw InputError("cannot create a temporary folder in /tmp");
    out = pattern;
  } else {
    out = o.out;
    if (fs::exists(out) && !fs::is_directory(out)) throw InputError("--out " + o.out + ": exists and is not a folder");
    fs::create_directories(out);
  }
  std::string truth_note;
  GroundTruth truth(container, open_original(o, container, truth_note));
  const std::string transfer_spec = !o.transfer.empty() ? o.transfer : o.tour.empty() ? "auto" : "tour";

  RunSetup setup;
  setup.container = &container;
  setup.tour = &tour;
  setup.width = width;
  setup.height = height;
  setup.transfer = bench_transfer(transfer_spec, container, truth);
  setup.render.step = o.step;
  setup.simulated_fps = o.clock == "simulated" ? o.fps : 0;
  setup.render.background = {0.06f, 0.06f, 0.08f};
  stream::SchedulerSettings& ss = setup.settings;
  ss.atlas_slots = o.atlas_slots;
  ss.priority.sse_target = o.sse_target;
  ss.priority.sse_weight = o.sse_weight;
  ss.priority.temporal_lerp_min = o.temporal_lerp_min;
  ss.priority.temporal_exponent = o.temporal_exponent;
  ss.priority.due_window = o.due_window;
  ss.priority.sse_scope = o.sse_priority == "node" ? stream::SseScope::node : stream::SseScope::level;
  ss.priority.lookahead_s = o.lookahead;
  ss.speculative_link_s = o.speculative_link;
  ss.selection.ancestor_handicap = o.ancestor_handicap;
  ss.upload_budget_bytes = static_cast<std::uint64_t>(o.upload_budget_mb * 1e6);
  ss.loader.bandwidth_bytes_per_s = bandwidth;
  ss.loader.latency_s = latency;
  ss.loader.threads = o.io_threads;
  // Requests in flight: arrivals are taken once per rendered frame, and the CPU renders far fewer
  // frames per second than a GPU player, so a small cap would limit throughput instead of the
  // bandwidth. By default the cap holds what the link delivers in latency + 0.5 s.
  std::vector<std::string> index_errors;
  const stream::SpatialIndex index = stream::build_spatial_index(container, &index_errors);
  for (const std::string& e : index_errors) std::fprintf(stderr, "volreel: warning: %s\n", e.c_str());
  setup.index = &index;
  setup.index_errors = index_errors.size();
  const std::size_t keyframe_nodes = index.keyframe_count();
  double brick_bytes = 1;
  {
    std::uint64_t total = 0;
    for (std::size_t k = 0; k < keyframe_nodes; ++k) total += index.keyframe(static_cast<stream::KeyframeId>(k)).bytes;
    if (keyframe_nodes > 0) brick_bytes = static_cast<double>(total) / static_cast<double>(keyframe_nodes);
  }
  // More slots than bricks change nothing (every keyframe node fits in the heap) but cost memory.
  const bool capped = keyframe_nodes > 0 && ss.atlas_slots > keyframe_nodes;
  if (capped) ss.atlas_slots = static_cast<std::uint32_t>(keyframe_nodes);
  ss.loader.max_in_flight =
      o.max_in_flight > 0 ? o.max_in_flight
      : bandwidth > 0     ? static_cast<std::size_t>(std::clamp(bandwidth * (latency + 0.5) / brick_bytes, 32.0, 4096.0))
                          : 1024;

  const auto seeks = tour_seeks(tour);
  std::printf("volreel bench stream\nmachine: %s\n", describe_machine().c_str());
  std::printf("input:   %s: %ux%ux%u, %zu frames, %u levels, %s, %s in all (mean brick %.0f bytes)\n", o.container.c_str(),
              m.dims[0], m.dims[1], m.dims[2], container.frame_count(), truth.geometry().levels,
              m.codec == format::Codec::ksvd ? "ksvd" : "zfp", stream_bench::mb_text(static_cast<double>(container.total_bytes())).c_str(),
              brick_bytes);
  std::printf("truth:   %s\n", truth.original() ? ("the original series (" + truth_note + ")").c_str() : truth_note.c_str());
  char clock_text[96];
  if (setup.simulated_fps > 0)
    std::snprintf(clock_text, sizeof clock_text, "simulated clock, %g frames per tour second", setup.simulated_fps);
  else
    std::snprintf(clock_text, sizeof clock_text, "wall clock (tour time = seconds since start)");
  std::printf("tour:    %s, %.1f s, %zu seeks; %s\n",
              o.tour.empty() ? "built-in bench tour (play, reverse, 5 random seeks, pauses, slow motion, orbit, zoom)"
                             : o.tour.c_str(),
              tour.duration(), seeks.size(), clock_text);
  if (o.seeds > 1)
    std::printf("         %u tours, seeds %llu to %llu (their seeks differ), each run with both policies\n", o.seeds,
                static_cast<unsigned long long>(o.seed), static_cast<unsigned long long>(o.seed + o.seeds - 1));
  std::printf("render:  CPU ray caster, %dx%d, step %g voxel, transfer function: %s\n", width, height, o.step,
              transfer_spec == "auto" ? "auto (quantiles of the middle frame)" : transfer_spec.c_str());
  std::printf("stream:  bandwidth %s, latency %g ms, %zu requests in flight at most, %u atlas slots%s, SSE target %g px\n",
              rate_text(bandwidth).c_str(), latency * 1e3, ss.loader.max_in_flight, ss.atlas_slots,
              capped ? " (every brick of the container)" : "", o.sse_target);
  if (playback_rate > 0)
    std::printf("         playing the whole volume at the tour's fastest speed (%.3g keyframes/s) needs %s: the link "
                "carries %s of it\n",
                play_speed, rate_text(playback_rate).c_str(),
                bandwidth > 0 ? (std::to_string(static_cast<int>(std::lround(100 * bandwidth / playback_rate))) + " %").c_str()
                              : "all");
  std::printf("patent:  priority = %g*SSE/(1+SSE) + lerp(random, temporal, lerp(%g, 1, temporal)), temporal exponent %g;\n"
              "         SSE of %s\n",
              o.sse_weight, o.temporal_lerp_min, ss.priority.temporal_exponent,
              o.sse_priority == "node" ? "the node ([0042])" : "the node's level (the largest of its visible nodes)");
  if (o.due_window)
    std::printf("         due window first: the keyframes around the playhead and those it reaches within %g s; the\n"
                "         rest ([0045] order) holds at most %g s of the link in flight\n",
                o.lookahead, o.speculative_link);
  else
    std::printf("         no due window (--due-window off): every keyframe node by [0045] alone\n");
  std::fflush(stdout);
  // 2. The runs (timed), then the ground truth of each; with --seeds, once per tour, each tour's
  //    files in OUT/seed_S.
  struct TourRuns {
    std::uint64_t seed = 0;
    std::vector<RunResult> runs;
  };
  std::vector<TourRuns> tours;
  for (unsigned i = 0; i < o.seeds; ++i) {
    TourRuns& tr = tours.emplace_back();
    tr.seed = o.seed + i;
    const cpu_render::Tour tour_i = i == 0 ? tour : bench_tour(context, o.duration, tr.seed, width, height);
    const fs::path dir = o.seeds > 1 ? out / ("seed_" + std::to_string(tr.seed)) : out;
    fs::create_directories(dir);
    {
      std::ofstream t(dir / "tour.json");
      t << tour_i.to_json().dump(1) << '\n';
      if (!t) throw InputError("writing " + (dir / "tour.json").string() + " failed");
    }
    setup.tour = &tour_i;
    const auto tour_seeks_i = tour_seeks(tour_i);
    for (const stream::PriorityPolicy p : policies) {
      {
        ProgressBar bar(std::string("streaming (") + stream_bench::policy_name(p) + ")", "s");
        tr.runs.push_back(stream_bench::run_tour(setup, p, progress_of(bar)));
        bar.finish();
      }
      {
        ProgressBar bar(std::string("ground truth (") + tr.runs.back().name + ")", "frames");
        stream_bench::measure(tr.runs.back(), setup, truth, tour_seeks_i, dir, o.png_every, progress_of(bar));
        bar.finish();
      }
      stream_bench::write_csv(dir / ("stream_" + tr.runs.back().name + ".csv"), tr.runs.back(), tour_seeks_i);
    }
    setup.tour = nullptr;
    if (o.seeds > 1) {
      std::printf("\ntour seed %llu:\n", static_cast<unsigned long long>(tr.seed));
      stream_bench::print_side_by_side(tr.runs);
    }
  }
  const std::vector<RunResult>& runs = tours.front().runs;

  // 3. Side by side, the targets, the files.
  std::printf("\nimage PSNR = 10*log10(255^2/MSE) over 8-bit RGB against the ground truth (frames identical to it count "
              "as %.0f dB); SSIM: per channel, averaged\n",
              psnr_cap_db);
  if (o.seeds == 1) stream_bench::print_side_by_side(runs);
  nlohmann::json summary = {{"container", o.container},
                            {"bandwidth_bytes_per_s", bandwidth},
                            {"latency_s", latency},
                            {"playback_bytes_per_s", playback_rate},
                            {"clock", o.clock},
                            {"fps", setup.simulated_fps > 0 ? nlohmann::json(setup.simulated_fps) : nlohmann::json()},
                            {"atlas_slots", ss.atlas_slots},
                            {"max_in_flight", ss.loader.max_in_flight},
                            {"sse_weight", o.sse_weight},
                            {"temporal_lerp_min", o.temporal_lerp_min},
                            {"temporal_exponent", o.temporal_exponent},
                            {"due_window", o.due_window},
                            {"sse_priority", o.sse_priority},
                            {"lookahead_s", o.lookahead},
                            {"speculative_link_s", o.speculative_link},
                            {"ancestor_handicap", o.ancestor_handicap},
                            {"size", {width, height}},
                            {"ground_truth", truth.original() ? "original series" : "container finest level"}};
  if (o.seeds == 1) {
    summary["runs"] = nlohmann::json::array();
    for (const RunResult& r : runs) summary["runs"].push_back(stream_bench::summary_json(r));
  } else {
    summary["tours"] = nlohmann::json::array();
    for (const TourRuns& tr : tours) {
      nlohmann::json t = {{"seed", tr.seed}, {"runs", nlohmann::json::array()}};
      for (const RunResult& r : tr.runs) t["runs"].push_back(stream_bench::summary_json(r));
      summary["tours"].push_back(t);
    }
  }
  // Per policy, over the tours: the mean of the tours' mean image PSNRs, and the frames with holes
  // after the first root brick (and whether every tour's first root arrived).
  struct PolicyTotals {
    double mean_psnr = 0;
    std::size_t holes = 0, frames = 0;
    bool roots = true;
  };
  const auto totals = [&](const char* name) -> std::optional<PolicyTotals> {
    PolicyTotals t;
    std::size_t n = 0;
    for (const TourRuns& tr : tours)
      for (const RunResult& r : tr.runs)
        if (r.name == name) {
          t.mean_psnr += r.mean_psnr;
          t.holes += r.frames_with_holes_after_root;
          t.frames += r.frames.size();
          t.roots = t.roots && !std::isnan(r.first_root_s);
          ++n;
        }
    if (n == 0) return std::nullopt;
    t.mean_psnr /= static_cast<double>(n);
    return t;
  };
  const auto patent = totals("patent");
  const auto nearest = totals("nearest");
  if (o.seeds > 1) {
    std::printf("\n  %-10s %16s %24s %12s\n", "tour seed", "patent [0045]", "nearest-keyframe-first", "difference");
    for (const TourRuns& tr : tours) {
      std::printf("  %-10llu", static_cast<unsigned long long>(tr.seed));
      double p = std::nan(""), n = std::nan("");
      for (const RunResult& r : tr.runs) (r.name == "patent" ? p : n) = r.mean_psnr;
      std::printf(" %13.2f dB %21.2f dB", p, n);
      if (patent && nearest) std::printf(" %+9.2f dB", p - n);
      std::printf("\n");
    }
    std::printf("  %-10s %13.2f dB %21.2f dB", "mean", patent ? patent->mean_psnr : std::nan(""),
                nearest ? nearest->mean_psnr : std::nan(""));
    if (patent && nearest) std::printf(" %+9.2f dB", patent->mean_psnr - nearest->mean_psnr);
    std::printf("   (mean image PSNR of each tour)\n");
  }
  const char* over = o.seeds > 1 ? " (mean over the tours)" : "";
  std::printf("\nchecks:\n");
  if (patent && nearest) {
    const bool higher = patent->mean_psnr > nearest->mean_psnr;
    std::printf("  patent's mean image PSNR higher than nearest-keyframe-first%s: %s (%.2f vs %.2f dB, %+.2f dB)\n", over,
                higher ? "yes" : "NO", patent->mean_psnr, nearest->mean_psnr, patent->mean_psnr - nearest->mean_psnr);
    summary["target_higher_psnr"] = higher;
  }
  if (patent) {
    const bool no_holes = patent->holes == 0 && patent->roots;
    std::printf("  patent: no frame with a hole after the first root brick arrived: %s (%zu of %zu frames have holes)\n",
                no_holes ? "yes" : "NO", patent->holes, patent->frames);
    summary["target_no_holes"] = no_holes;
  }
  if (!truth.original())
    std::printf("  (ground truth is the container's own decode, so PSNR measures streaming loss only)\n");
  {
    std::ofstream js(out / "summary.json");
    js << summary.dump(1) << '\n';
    if (!js) throw InputError("writing " + (out / "summary.json").string() + " failed");
  }
  std::printf("\nwrote %s: %sstream_<policy>.csv (per frame), summary.json, %stour.json, %sframes_<policy>/frame_NNNNN.png "
              "(streamed | ground truth)\n",
              out.c_str(), o.seeds > 1 ? "seed_S/" : "", o.seeds > 1 ? "seed_S/" : "", o.seeds > 1 ? "seed_S/" : "");
}

}  // namespace

void add_bench_stream_command(CLI::App& bench) {
  auto o = std::make_shared<BenchStreamOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "stream",
      "Streaming benchmark: replay a tour (play, reverse, random seeks, camera moves) with the CPU renderer,\n"
      "streaming bricks through a bandwidth- and latency-limited loader, once with the patent's priorities and\n"
      "once nearest-keyframe-first. By default the tour and the link run on a simulated clock (--fps frames per\n"
      "tour second), so results do not depend on the machine's speed or load; --clock wall replays in real time. Per frame and averaged: image PSNR/SSIM against a render of the\n"
      "original data at that playhead, fraction of nodes at target LOD, holes, bytes loaded, time to full quality\n"
      "after each seek. Writes OUT/stream_<policy>.csv, OUT/summary.json and a few PNGs.");
  cmd->add_option("CONTAINER", o->container, "The container directory NAME.vreel")->required();
  cmd->add_option("--bandwidth", o->bandwidth,
                  "Simulated read bandwidth: a rate (20MB/s, 500kB/s), a multiple of the playback data rate (0.5x: half\n"
                  "of what playing every brick at the tour's fastest speed needs), or 0/unlimited")
      ->capture_default_str();
  cmd->add_option("--latency", o->latency, "Simulated latency per request, e.g. 50ms, 0.2s")->capture_default_str();
  cmd->add_option("--tour", o->tour,
                  "Tour JSON (player/cpu_render tour.hpp); default: the built-in bench tour of --duration seconds");
  cmd->add_option("--duration", o->duration, "Length of the built-in bench tour, seconds")->capture_default_str();
  cmd->add_option("--seed", o->seed, "Seed of the built-in tour's random seeks")->capture_default_str();
  cmd->add_option("--seeds", o->seeds,
                  "Replay this many built-in tours (seeds --seed, --seed + 1, ...): with five seeks a tour, which time\n"
                  "steps a policy happened to hold decides much of a fast link's result; the targets use the mean")
      ->capture_default_str();
  cmd->add_option("--clock", o->clock,
                  "simulated: frame k at tour time k/fps, the link on the same clock (deterministic); wall: the tour\n"
                  "and the link in real time")
      ->capture_default_str();
  cmd->add_option("--fps", o->fps, "Simulated clock: frames drawn per tour second")->capture_default_str();
  cmd->add_option("--series", o->series,
                  "Original series for the ground truth (raw series directory, HDF5 or raw file); default: the\n"
                  "manifest's source if that path exists, else the container's own finest-level decode");
  cmd->add_option("--size", o->size, "Image size WxH (the tour's own size is not used)")->capture_default_str();
  cmd->add_option("--atlas-slots", o->atlas_slots,
                  "Brick slots of the atlas (= heap capacity); the default is what 256 MiB of a 16-bit GPU atlas holds")
      ->capture_default_str();
  cmd->add_option("--max-in-flight", o->max_in_flight,
                  "Requests in flight at most (default: what the link delivers in latency + 0.5 s, at least 32)");
  cmd->add_option("--io-threads", o->io_threads, "Loader threads")->capture_default_str();
  cmd->add_option("--policy", o->policy, "both, patent or nearest (nearest-keyframe-first)")->capture_default_str();
  cmd->add_option("--transfer", o->transfer,
                  "Transfer function: auto (quantiles of the data), tour (the tour's), a preset (grayscale, cool-warm,\n"
                  "fire, turbulence) or a JSON file; default: auto without --tour, the tour's with one");
  cmd->add_option("--sse-target", o->sse_target, "Screen-space error target, pixels per voxel")->capture_default_str();
  cmd->add_option("--sse-weight", o->sse_weight, "Patent policy: weight of the SSE priority ([0045]: 10)")->capture_default_str();
  cmd->add_option("--temporal-lerp-min", o->temporal_lerp_min,
                  "Patent policy: weight of the temporal priority against the random one at temporal 0 ([0045]: 0.15;\n"
                  "1: the temporal priority alone, measured best)")
      ->capture_default_str();
  cmd->add_option("--temporal-exponent", o->temporal_exponent,
                  "Both policies: exponent of temporalPriority = (1 - distance/maxDistance)^e ([0043]: 4)")
      ->capture_default_str();
  cmd->add_option("--sse-priority", o->sse_priority,
                  "Patent policy: the SSE behind ssePriority: level (the largest SSE of the node's level in view,\n"
                  "so that a full atlas keeps whole keyframes) or node (the node's own, [0042] literally)")
      ->check(CLI::IsMember({"level", "node"}))
      ->capture_default_str();
  cmd->add_option("--due-window", o->due_window,
                  "Patent policy: request first the keyframes the playhead needs now (the two around it) and those\n"
                  "it reaches within --lookahead seconds at its current speed and direction, before the rest by\n"
                  "[0045] (true/false; false: [0045] alone)")
      ->capture_default_str();
  cmd->add_option("--lookahead", o->lookahead,
                  "Patent policy, due window: seconds of playback ahead of the playhead whose keyframes are due")
      ->capture_default_str();
  cmd->add_option("--speculative-link", o->speculative_link,
                  "Patent policy, due window: requests outside it (the [0045] order: coarse levels of the whole\n"
                  "timeline, then farther keyframes) hold at most this many seconds of the link in flight, so the\n"
                  "keyframes the playhead needs next never wait behind more (0: no bound)")
      ->capture_default_str();
  cmd->add_option("--ancestor-handicap", o->ancestor_handicap,
                  "Both policies, pre-render selection: an ancestor's keyframe distance is multiplied by\n"
                  "exp(h * levels up) ([0046]: 4)")
      ->capture_default_str();
  cmd->add_option("--step", o->step, "Ray step, finest voxels (the ground truth uses the same)")->capture_default_str();
  cmd->add_option("--upload-budget", o->upload_budget_mb, "Compressed bytes uploaded per frame at most, MB")
      ->capture_default_str();
  cmd->add_option("--png-every", o->png_every,
                  "Write every Nth frame as a PNG (default: the frames just after each seek, half a second later, and "
                  "the last)");
  cmd->add_option("--out", o->out, "Output folder (default: a new folder in /tmp, printed at the end)");
  o->reader.add_to(*cmd);
  cmd->callback([o] { run_bench_stream(*o); });
}

}  // namespace volreel::cli
