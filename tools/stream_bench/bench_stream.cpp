// bench_stream.cpp: the built-in bench tour, tour analysis, the link, the original series, the
// settings of `volreel bench stream` and the loop over its tours and policies.
#include "volreel/stream_bench/bench_stream.hpp"

#include <stdlib.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>
#include <tuple>

#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/stream_bench/run_report.hpp"

namespace volreel::stream_bench {

namespace {

namespace fs = std::filesystem;

[[noreturn]] void bad(const std::string& option, const std::string& expected,
                      const std::string& found) {
  throw InputError(option + ": expected " + expected + ", found '" + found + "'");
}

/// A finite number > 0 and nothing else; nullopt otherwise.
std::optional<double> positive_number(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v) || !(v > 0))
    return std::nullopt;
  return v;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// The tour, the link, the original series and the transfer function.

cpu_render::Tour bench_tour(const cpu_render::TourContext& context, double duration,
                            std::uint64_t seed, int width, int height) {
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
  const Key keys[] = {{0, 0, 1},       {0.25, 15, 1},   {0.5, -10, 1},
                      {0.6, -10, 0.6}, {0.75, 10, 0.6}, {1, 0, 1}};
  nlohmann::json camera = nlohmann::json::array();
  for (const Key& k : keys)
    camera.push_back({{"t", k.at * d},
                      {"azimuth", az + 360.0 * k.at},
                      {"elevation", el + k.elevation},
                      {"distance", f.distance * k.zoom},
                      {"target", {f.target.x, f.target.y, f.target.z}},
                      {"fov", glm::degrees(f.fov_y)}});
  const nlohmann::json json = {
      {"duration", d},           {"fps", 30},
      {"size", {width, height}}, {"camera", camera},
      {"segments", segments},    {"transfer", {{{"t", 0}, {"preset", "cool-warm"}}}}};
  return cpu_render::Tour::from_json(json, context, "bench tour");
}

std::vector<std::pair<double, double>> tour_seeks(const cpu_render::Tour& tour) {
  std::vector<std::pair<double, double>> seeks;
  const auto& keys = tour.playhead_keys();
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (keys[i].time == keys[i - 1].time && keys[i].keyframe != keys[i - 1].keyframe)
      seeks.emplace_back(keys[i].time, keys[i].keyframe);
  return seeks;
}

double tour_play_speed(const cpu_render::Tour& tour) {
  double speed = 0;
  const auto& keys = tour.playhead_keys();
  for (std::size_t i = 1; i < keys.size(); ++i)
    if (keys[i].time > keys[i - 1].time)
      speed = std::max(speed, std::abs(keys[i].keyframe - keys[i - 1].keyframe) /
                                  (keys[i].time - keys[i - 1].time));
  return speed;
}

double bench_bandwidth(const std::string& text, double playback_bytes_per_s) {
  if (text == "unlimited") return 0;
  if (!text.empty() && (text.back() == 'x' || text.back() == 'X')) {
    const std::optional<double> factor = positive_number(text.substr(0, text.size() - 1));
    if (!factor)
      bad("--bandwidth",
          "a multiple of the playback data rate such as 0.5x, or a rate such as 20MB/s", text);
    if (!(playback_bytes_per_s > 0))
      throw InputError(
          "--bandwidth " + text +
          ": the tour never plays, so there is no playback data rate; give a rate such as 1MB/s");
    return *factor * playback_bytes_per_s;
  }
  return loop::parse_bandwidth(text);
}

/// The path inside a manifest's "source" ("raw series DIR", "raw file FILE (f32)", "raw files
/// PATTERN (N files, f32)", "HDF5 FILE (datasets …)", "NetCDF FILE (variable …)") or the
/// encoder's "series" field.
std::vector<std::string> source_candidates(const format::Manifest& m) {
  std::vector<std::string> out;
  std::string s = m.source;
  for (const char* prefix : {"raw series ", "raw files ", "raw file ", "HDF5 ", "NetCDF "})
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

/// Opens the original series: --series, else the manifest's source where a path of that name
/// holds a series of the container's size (relative to the folder holding the container, then to
/// the one above it, then as given: a relative source is relative to where the encode ran, most
/// often next to the container; the current folder may hold another series of that name; for a
/// container read over HTTP, an absolute path only). nullptr: none found (`note` says why).
std::unique_ptr<datasets::SeriesReader> open_original(const std::string& series,
                                                      datasets::OpenOptions options,
                                                      const format::Container& container,
                                                      std::string& note) {
  const format::Manifest& m = container.manifest();
  // A raw file or pattern without --dims has the container's.
  const auto open = [&](const fs::path& p) {
    datasets::OpenOptions o = options;
    if (!o.dims && !datasets::describes_itself(p)) o.dims = Dims{m.dims[0], m.dims[1], m.dims[2]};
    return datasets::open_series(p, o);
  };
  if (!series.empty()) {
    if (!fs::exists(series) && series.find_first_of("*?[") == std::string::npos)
      throw InputError("--series " + series + ": no such file or folder");
    note = "--series " + series;
    return open(series);
  }
  // A container read over HTTP: the source where it is an absolute path on this machine.
  const auto local = container.source().local_directory();
  const fs::path dir = local ? fs::absolute(*local).lexically_normal() : fs::path();
  for (const std::string& c : source_candidates(m)) {
    if (!local && fs::path(c).is_relative()) continue;
    std::vector<fs::path> tries;
    if (fs::path(c).is_relative()) {
      tries.push_back(dir.parent_path() / c);
      tries.push_back(dir.parent_path().parent_path() / c);
    }
    tries.push_back(fs::path(c));
    for (const fs::path& p : tries) {
      const bool pattern = p.string().find_first_of("*?[") != std::string::npos;
      if (!fs::exists(p) && !pattern) continue;
      try {
        auto reader = open(p);
        const Dims d = reader->info().dims;
        if (d.x != static_cast<std::int64_t>(m.dims[0]) ||
            d.y != static_cast<std::int64_t>(m.dims[1]) ||
            d.z != static_cast<std::int64_t>(m.dims[2]) ||
            reader->info().frames < container.frame_count()) {
          note = "the manifest's source " + p.string() + " is another series (" +
                 std::to_string(d.x) + "x" + std::to_string(d.y) + "x" + std::to_string(d.z) +
                 ", " + std::to_string(reader->info().frames) + " frames)";
          continue;
        }
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
std::optional<cpu_render::TransferFunction> bench_transfer(const std::string& spec,
                                                           const format::Container& container,
                                                           GroundTruth& truth) {
  const format::Manifest& m = container.manifest();
  if (spec == "tour") return std::nullopt;
  if (spec == "auto")
    return cpu_render::TransferFunction::from_quantiles(
        truth.frame(container.frame_count() / 2), static_cast<float>(m.value_min),
        static_cast<float>(m.value_max),
        (double(m.dims[0]) + double(m.dims[1]) + double(m.dims[2])) / 3.0);
  return loop::transfer_from_spec(spec, container, "--transfer");
}

std::string rate_text(double bytes_per_s) {
  if (!(bytes_per_s > 0)) return "unlimited";
  char s[32];
  std::snprintf(s, sizeof s, "%g MB/s", bytes_per_s * 1e-6);
  return s;
}

// ---------------------------------------------------------------------------------------------
// The settings.

void BenchStreamSettings::check() const {
  const BenchStreamSettings& o = *this;
  loop::parse_size(o.size);
  if (o.bandwidth.empty() || (o.bandwidth.back() != 'x' && o.bandwidth.back() != 'X'))
    bench_bandwidth(o.bandwidth, 0);  // a malformed rate is reported before any work
  loop::parse_latency(o.latency);
  if (!(o.duration > 0) || o.duration > 3600)
    bad("--duration", "seconds in (0, 3600]", format::number_text(o.duration));
  if (o.clock != "simulated" && o.clock != "wall") bad("--clock", "simulated or wall", o.clock);
  if (!(o.fps > 0) || o.fps > 240)
    bad("--fps", "frames per second in (0, 240]", format::number_text(o.fps));
  if (!(o.sse_target > 0) || !std::isfinite(o.sse_target))
    bad("--sse-target", "pixels per voxel > 0", format::number_text(o.sse_target));
  if (!(o.sse_weight >= 0) || !std::isfinite(o.sse_weight))
    bad("--sse-weight", "a weight >= 0", format::number_text(o.sse_weight));
  if (!(o.temporal_exponent > 0) || o.temporal_exponent > 64)
    bad("--temporal-exponent", "an exponent in (0, 64]", format::number_text(o.temporal_exponent));
  if (!(o.temporal_lerp_min >= 0 && o.temporal_lerp_min <= 1))
    bad("--temporal-lerp-min", "a weight in [0, 1]", format::number_text(o.temporal_lerp_min));
  if (!(o.ancestor_handicap >= 0) || o.ancestor_handicap > 64)
    bad("--ancestor-handicap", "an exponent in [0, 64]", format::number_text(o.ancestor_handicap));
  if (!(o.speculative_link >= 0) || o.speculative_link > 60)
    bad("--speculative-link", "seconds in [0, 60]", format::number_text(o.speculative_link));
  if (!(o.lod_fade >= 0) || o.lod_fade > 60)
    bad("--lod-fade", "seconds in [0, 60]", format::number_text(o.lod_fade));
  if (!(o.lod_fade_out >= 0) || o.lod_fade_out > 60)
    bad("--lod-fade-out", "seconds in [0, 60]", format::number_text(o.lod_fade_out));
  if (!(o.lookahead >= 0) || o.lookahead > 60)
    bad("--lookahead", "seconds in [0, 60]", format::number_text(o.lookahead));
  if (!(o.step > 0) || !std::isfinite(o.step))
    bad("--step", "a ray step in voxels > 0", format::number_text(o.step));
  if (o.atlas_slots < 1 || o.atlas_slots > (1u << 16))
    bad("--atlas-slots", "1..65536 slots", std::to_string(o.atlas_slots));
  if (!(o.upload_budget_mb > 0))
    bad("--upload-budget", "MB per frame > 0", format::number_text(o.upload_budget_mb));
  if (o.io_threads < 1 || o.io_threads > 64)
    bad("--io-threads", "1..64", std::to_string(o.io_threads));
  if (o.seeds < 1 || o.seeds > 100) bad("--seeds", "1..100 tours", std::to_string(o.seeds));
  if (o.seeds > 1 && !o.tour.empty())
    throw InputError("--seeds " + std::to_string(o.seeds) +
                     ": several seeds vary the built-in tour; drop --tour or --seeds");
  // The built-in tour's length and seeks; a tour file has its own (a value other than the
  // default is what tells that one was given).
  if (!o.tour.empty() && o.duration != BenchStreamSettings{}.duration)
    throw InputError("--duration with --tour " + o.tour +
                     ": the length of the built-in tour; a tour file gives its own \"duration\"");
  if (!o.tour.empty() && o.seed != BenchStreamSettings{}.seed)
    throw InputError("--seed with --tour " + o.tour +
                     ": the seed of the built-in tour's seeks; a tour file gives its own seeks");
  policies();
}

std::pair<int, int> BenchStreamSettings::image_size() const {
  return loop::parse_size(size);
}

double BenchStreamSettings::latency_s() const {
  return loop::parse_latency(latency);
}

std::vector<stream::PriorityPolicy> BenchStreamSettings::policies() const {
  if (policy == "both")
    return {stream::PriorityPolicy::patent, stream::PriorityPolicy::nearest_keyframe_first};
  if (policy == "patent") return {stream::PriorityPolicy::patent};
  if (policy == "nearest") return {stream::PriorityPolicy::nearest_keyframe_first};
  bad("--policy", "both, patent or nearest", policy);
}

std::string BenchStreamSettings::transfer_spec() const {
  return !transfer.empty() ? transfer : tour.empty() ? "auto" : "tour";
}

fs::path bench_out_dir(const std::string& out) {
  if (out.empty()) {
    char pattern[] = "/tmp/volreel-bench-stream-XXXXXX";
    if (!::mkdtemp(pattern)) throw InputError("cannot create a temporary folder in /tmp");
    return pattern;
  }
  if (fs::exists(out) && !fs::is_directory(out))
    throw InputError("--out " + out + ": exists and is not a folder");
  format::detail::check_writable(out, "--out");
  fs::create_directories(out);
  return out;
}

SchedulerSetup scheduler_setup(const BenchStreamSettings& o, double bandwidth, double latency,
                               const stream::SpatialIndex& index) {
  SchedulerSetup r;
  stream::SchedulerSettings& ss = r.settings;
  ss.atlas_slots = o.atlas_slots;
  ss.priority.sse_target = o.sse_target;
  ss.priority.sse_weight = o.sse_weight;
  ss.priority.temporal_lerp_min = o.temporal_lerp_min;
  ss.priority.temporal_exponent = o.temporal_exponent;
  ss.priority.due_window = o.due_window;
  ss.priority.sse_scope =
      o.sse_priority == "node" ? stream::SseScope::node : stream::SseScope::level;
  ss.priority.lookahead_s = o.lookahead;
  ss.speculative_link_s = o.speculative_link;
  ss.selection.ancestor_handicap = o.ancestor_handicap;
  ss.ray_feedback = o.ray_feedback;
  ss.lod_blend.spatial = o.spatial_blend;
  ss.priority.restricted = o.restricted;
  ss.selection.restricted = o.restricted_drawing;
  ss.lod_blend.fade_s = o.lod_fade;
  ss.lod_blend.fade_out_s = o.lod_fade_out;
  ss.upload_budget_bytes = static_cast<std::uint64_t>(o.upload_budget_mb * 1e6);
  ss.loader.bandwidth_bytes_per_s = bandwidth;
  ss.loader.latency_s = latency;
  ss.loader.threads = o.io_threads;
  const std::size_t keyframe_nodes = index.keyframe_count();
  {
    std::uint64_t total = 0;
    for (std::uint32_t n = 0; n < index.node_count(); ++n)
      index.for_each_keyframe(n, [&](const stream::KeyframeNode& k) { total += k.bytes; });
    if (keyframe_nodes > 0)
      r.brick_bytes = static_cast<double>(total) / static_cast<double>(keyframe_nodes);
  }
  r.atlas_capped = keyframe_nodes > 0 && ss.atlas_slots > keyframe_nodes;
  if (r.atlas_capped) ss.atlas_slots = static_cast<std::uint32_t>(keyframe_nodes);
  ss.loader.max_in_flight = o.max_in_flight > 0 ? o.max_in_flight
                            : bandwidth > 0
                                ? static_cast<std::size_t>(std::clamp(
                                      bandwidth * (latency + 0.5) / r.brick_bytes, 32.0, 4096.0))
                                : 1024;
  return r;
}

RunSetup run_setup(const BenchStreamSettings& o, const format::Container& container,
                   const stream::SpatialIndex& index, std::size_t index_errors,
                   const stream::SchedulerSettings& scheduler, int width, int height,
                   std::optional<cpu_render::TransferFunction> transfer) {
  RunSetup setup;
  setup.container = &container;
  setup.index = &index;
  setup.index_errors = index_errors;
  setup.width = width;
  setup.height = height;
  setup.transfer = std::move(transfer);
  setup.render.step = o.step;
  setup.simulated_fps = o.clock == "simulated" ? o.fps : 0;
  setup.render.background = {0.06f, 0.06f, 0.08f};
  setup.settings = scheduler;
  setup.settings.loader.reader = container.source().brick_reader();
  return setup;
}

BenchPlan prepare_bench(const BenchStreamSettings& s, const std::string& container_path,
                        const std::string& series, const datasets::OpenOptions& options,
                        const std::string& out,
                        std::shared_ptr<const format::ContainerSource> source) {
  s.check();
  BenchPlan plan;
  std::tie(plan.width, plan.height) = s.image_size();
  plan.link.latency_s = s.latency_s();
  if (source) {
    plan.container = std::make_unique<format::Container>(std::move(source));
  } else {
    if (!fs::is_directory(container_path))
      throw InputError(container_path + ": not a container folder (NAME.vreel)");
    plan.container = std::make_unique<format::Container>(container_path);
  }
  const format::Container& container = *plan.container;
  if (container.frame_count() == 0)
    throw InputError(container_path + ": the container has no frames");
  plan.context = cpu_render::TourContext::of(container.manifest());
  plan.tour = std::make_unique<cpu_render::Tour>(
      s.tour.empty() ? bench_tour(plan.context, s.duration, s.seed, plan.width, plan.height)
                     : cpu_render::Tour::load(s.tour, plan.context));
  // Playing every brick of the volume at the tour's fastest speed needs this many bytes per second.
  plan.play_speed = tour_play_speed(*plan.tour);
  plan.link.playback_bytes_per_s = static_cast<double>(container.total_bytes()) /
                                   static_cast<double>(container.frame_count()) * plan.play_speed;
  plan.link.bandwidth_bytes_per_s = bench_bandwidth(s.bandwidth, plan.link.playback_bytes_per_s);
  plan.out = bench_out_dir(out);
  plan.truth = std::make_unique<GroundTruth>(
      container, open_original(series, options, container, plan.truth_note));
  plan.transfer_spec = s.transfer_spec();
  auto transfer = bench_transfer(plan.transfer_spec, container, *plan.truth);
  std::vector<std::string> index_errors;
  plan.index =
      std::make_unique<stream::SpatialIndex>(stream::build_spatial_index(container, &index_errors));
  for (const std::string& e : index_errors)
    std::fprintf(stderr, "volreel: warning: %s\n", e.c_str());
  plan.scheduler =
      scheduler_setup(s, plan.link.bandwidth_bytes_per_s, plan.link.latency_s, *plan.index);
  plan.setup = run_setup(s, container, *plan.index, index_errors.size(), plan.scheduler.settings,
                         plan.width, plan.height, std::move(transfer));
  return plan;
}

// ---------------------------------------------------------------------------------------------
// The runs.

std::vector<TourRuns> run_tours(const BenchStreamSettings& o, RunSetup setup,
                                const cpu_render::Tour& first,
                                const cpu_render::TourContext& context, GroundTruth& truth,
                                const fs::path& out, const StageRunner& stage,
                                const std::function<void(const TourRuns&)>& tour_done) {
  std::vector<TourRuns> tours;
  for (unsigned i = 0; i < o.seeds; ++i) {
    TourRuns& tr = tours.emplace_back();
    tr.seed = o.seed + i;
    const cpu_render::Tour tour_i =
        i == 0 ? first : bench_tour(context, o.duration, tr.seed, setup.width, setup.height);
    const fs::path dir = o.seeds > 1 ? out / ("seed_" + std::to_string(tr.seed)) : out;
    fs::create_directories(dir);
    {
      std::ofstream t(dir / "tour.json");
      t << tour_i.to_json().dump(1) << '\n';
      if (!t) throw InputError("writing " + (dir / "tour.json").string() + " failed");
    }
    setup.tour = &tour_i;
    const auto tour_seeks_i = tour_seeks(tour_i);
    for (const stream::PriorityPolicy p : o.policies()) {
      stage(std::string("streaming (") + policy_name(p) + ")", "s",
            [&](const Progress& progress) { tr.runs.push_back(run_tour(setup, p, progress)); });
      stage("ground truth (" + tr.runs.back().name + ")", "frames", [&](const Progress& progress) {
        measure(tr.runs.back(), setup, truth, tour_seeks_i, dir, o.png_every, progress);
      });
      write_csv(dir / ("stream_" + tr.runs.back().name + ".csv"), tr.runs.back(), tour_seeks_i);
    }
    setup.tour = nullptr;
    if (tour_done) tour_done(tr);
  }
  return tours;
}

std::optional<PolicyTotals> policy_totals(const std::vector<TourRuns>& tours,
                                          const std::string& name) {
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
}

nlohmann::json bench_summary_json(const BenchStreamSettings& o, const std::string& container,
                                  const RunSetup& setup, const BenchLink& link, bool original_truth,
                                  const std::vector<TourRuns>& tours) {
  const stream::SchedulerSettings& ss = setup.settings;
  nlohmann::json summary = {
      {"container", container},
      {"bandwidth_bytes_per_s", link.bandwidth_bytes_per_s},
      {"latency_s", link.latency_s},
      {"playback_bytes_per_s", link.playback_bytes_per_s},
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
      {"ray_feedback", o.ray_feedback},
      {"lod_fade_s", o.lod_fade},
      {"lod_fade_out_s", o.lod_fade_out},
      {"spatial_blend", o.spatial_blend},
      {"restricted", o.restricted},
      {"restricted_drawing", o.restricted_drawing},
      {"size", {setup.width, setup.height}},
      {"ground_truth", original_truth ? "original series" : "container finest level"}};
  if (tours.size() == 1) {
    summary["runs"] = nlohmann::json::array();
    for (const RunResult& r : tours.front().runs) summary["runs"].push_back(summary_json(r));
  } else {
    summary["tours"] = nlohmann::json::array();
    for (const TourRuns& tr : tours) {
      nlohmann::json t = {{"seed", tr.seed}, {"runs", nlohmann::json::array()}};
      for (const RunResult& r : tr.runs) t["runs"].push_back(summary_json(r));
      summary["tours"].push_back(t);
    }
  }
  return summary;
}

void print_bench_header(const BenchPlan& plan, const BenchStreamSettings& s,
                        const std::string& container_path, const std::string& machine) {
  const format::Container& container = *plan.container;
  const format::Manifest& m = container.manifest();
  const cpu_render::Tour& tour = *plan.tour;
  const RunSetup& setup = plan.setup;
  const stream::SchedulerSettings& ss = setup.settings;
  const auto [bandwidth, latency, playback_rate] = plan.link;
  const double play_speed = plan.play_speed;
  const GroundTruth& truth = *plan.truth;
  const std::string& transfer_spec = plan.transfer_spec;
  const auto seeks = tour_seeks(tour);
  std::printf("volreel bench stream\nmachine: %s\n", machine.c_str());
  std::printf(
      "input:   %s: %ux%ux%u, %zu frames, %u levels, %s, %s in all (mean brick %.0f bytes)\n",
      container_path.c_str(), m.dims[0], m.dims[1], m.dims[2], container.frame_count(),
      truth.geometry().levels, m.codec == format::Codec::ksvd ? "ksvd" : "zfp",
      mb_text(static_cast<double>(container.total_bytes())).c_str(), plan.scheduler.brick_bytes);
  std::printf("truth:   %s\n", truth.original()
                                   ? ("the original series (" + plan.truth_note + ")").c_str()
                                   : plan.truth_note.c_str());
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
      "render:  CPU ray caster, %dx%d, step %g voxel, transfer function: %s\n", plan.width,
      plan.height, s.step,
      transfer_spec == "auto" ? "auto (quantiles of the middle frame)" : transfer_spec.c_str());
  std::printf(
      "stream:  bandwidth %s, latency %g ms, %zu requests in flight at most, %u atlas slots%s, SSE "
      "target %g px\n",
      rate_text(bandwidth).c_str(), latency * 1e3, ss.loader.max_in_flight, ss.atlas_slots,
      plan.scheduler.atlas_capped ? " (every brick of the container)" : "", s.sse_target);
  if (playback_rate > 0)
    std::printf(
        "         playing the whole volume at the tour's fastest speed (%.3g keyframes/s) needs "
        "%s: the link "
        "carries %s of it\n",
        play_speed, rate_text(playback_rate).c_str(),
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
}

void print_checks(nlohmann::json& summary, const std::optional<PolicyTotals>& patent,
                  const std::optional<PolicyTotals>& nearest, bool several, bool original_truth) {
  const char* over = several ? " (mean over the tours)" : "";
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
    if (patent->roots)
      std::printf(
          "  patent: no frame with a hole after the first root brick arrived: %s (%zu of %zu "
          "frames have holes)\n",
          no_holes ? "yes" : "NO", patent->holes, patent->frames);
    else
      std::printf(
          "  patent: no frame with a hole after the first root brick arrived: NO (the root brick "
          "never arrived%s: nothing was drawn)\n",
          several ? " in a tour" : "");
    summary["target_no_holes"] = no_holes;
  }
  if (!original_truth)
    std::printf(
        "  (ground truth is the container's own decode, so PSNR measures streaming loss only)\n");
}

void print_tour_table(const std::vector<TourRuns>& tours, const std::optional<PolicyTotals>& patent,
                      const std::optional<PolicyTotals>& nearest) {
  std::printf("\n  %-10s %16s %24s %12s\n", "tour seed", "patent [0045]", "nearest-keyframe-first",
              "difference");
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

}  // namespace volreel::stream_bench
