// bench_stream.hpp: the library side of `volreel bench stream` — the built-in bench tour and the
// analysis of a tour (its seeks, its fastest playback), the --bandwidth rate, the original series
// found from a container's manifest, the transfer function; the benchmark's settings and their
// checks, the RunSetup and scheduler settings made from them (the atlas-slot cap and the rule for
// requests in flight), the loop over tours and policies, the per-policy totals over the tours and
// the summary JSON. CPU only.
//
// `volreel bench stream` (docs/design.md, "Streaming"): a scripted tour (play forward, reverse,
// random seeks, camera moves) is replayed against a player's clock, by default a simulated one:
// frame k is drawn at tour time k/fps and the loader's link (bandwidth, latency) runs on the same
// clock, so a run is the same on any machine whatever the CPU renderer's speed, and the policies
// are compared without noise. With --clock wall each frame samples the tour at the wall-clock time
// since the start instead (the loader then runs in real time; results vary with the machine's
// load). Every frame runs the whole streaming loop on the CPU (loop::CpuFrameLoop):
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
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/cpu_render/tour.hpp"
#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/stream/priorities.hpp"
#include "volreel/stream/scheduler.hpp"
#include "volreel/stream/selection.hpp"
#include "volreel/stream_bench/run_summary.hpp"
#include "volreel/stream_bench/tour_run.hpp"

namespace volreel::stream_bench {

// ---------------------------------------------------------------------------------------------
// The tour, the link, the original series and the transfer function.

/// The built-in bench tour: play forward over half the timeline, reverse, then five random seeks
/// (each at least a quarter of the timeline away from the playhead) alternating pauses and
/// playback (normal, half and slow speed); the camera orbits once, rises and sinks, and zooms in
/// and out.
cpu_render::Tour bench_tour(const cpu_render::TourContext& context, double duration,
                            std::uint64_t seed, int width, int height);

/// Seeks of a tour: two playhead keys at the same time (a cut) — time and target keyframe.
std::vector<std::pair<double, double>> tour_seeks(const cpu_render::Tour& tour);

/// The tour's fastest playback, keyframes per tour second (0 when it never plays).
double tour_play_speed(const cpu_render::Tour& tour);

/// --bandwidth: a rate (20MB/s), unlimited (or 0), or a multiple of the playback data rate (0.5x).
/// Bytes per second, 0 for unlimited. Throws InputError naming --bandwidth.
double bench_bandwidth(const std::string& text, double playback_bytes_per_s);

/// "12.5 MB/s", or "unlimited" for a rate <= 0.
std::string rate_text(double bytes_per_s);

/// The paths inside a manifest's "source" ("raw series DIR", "raw file FILE (f32)", "HDF5 FILE
/// (datasets …)") and the encoder's "series" field.
std::vector<std::string> source_candidates(const format::Manifest& manifest);

/// Opens the original series: `series` (the --series path) when not empty, else the manifest's
/// source if that path exists (as given, or relative to the container's folder and its parent).
/// `options.dims` defaults to the container's. nullptr: none found (`note` says why).
std::unique_ptr<datasets::SeriesReader> open_original(const std::string& series,
                                                      datasets::OpenOptions options,
                                                      const format::Container& container,
                                                      std::string& note);

/// --transfer: "tour" (the tour's own: nullopt), "auto" (quantiles of the ground truth's middle
/// frame), or what the player takes (a preset name or a JSON file: loop::transfer_from_spec).
std::optional<cpu_render::TransferFunction> bench_transfer(const std::string& spec,
                                                           const format::Container& container,
                                                           GroundTruth& truth);

// ---------------------------------------------------------------------------------------------
// The settings.

/// What `volreel bench stream` runs with, besides the container, the original series, the output
/// folder and how to read the series.
struct BenchStreamSettings {
  std::string tour;      ///< tour JSON; empty: the built-in bench tour
  std::string transfer;  ///< empty: auto without a tour, the tour's with one
  std::string size = "192x192";
  std::string bandwidth = "20MB/s", latency = "50ms";
  std::string policy = "both";
  std::uint32_t atlas_slots = 2876;
  std::size_t max_in_flight = 0;  ///< 0: from the bandwidth (see scheduler_setup)
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
  std::string sse_priority =
      stream::PrioritySettings{}.sse_scope == stream::SseScope::node ? "node" : "level";
  double lookahead = stream::PrioritySettings{}.lookahead_s;
  double speculative_link = stream::SchedulerSettings{}.speculative_link_s;
  double ancestor_handicap = stream::SelectionSettings{}.ancestor_handicap;
  bool ray_feedback = stream::SchedulerSettings{}.ray_feedback;
  double lod_fade = stream::LodBlendSettings{}.fade_s;  ///< stream::LodBlendSettings
  double lod_fade_out = stream::LodBlendSettings{}.fade_out_s;
  bool spatial_blend = stream::LodBlendSettings{}.spatial;
  bool restricted = stream::PrioritySettings{}.restricted;
  bool restricted_drawing = stream::SelectionSettings{}.restricted;
  double step = 1.0;
  double upload_budget_mb = 64;
  std::uint64_t seed = 1;
  unsigned seeds = 1;  ///< built-in tours with seeds seed, seed + 1, ...
  std::size_t png_every = 0;

  /// Throws InputError naming the first bad option (--size, a malformed --bandwidth rate,
  /// --latency, --duration, ...); nothing is read.
  void check() const;
  std::pair<int, int> image_size() const;                ///< --size
  double latency_s() const;                              ///< --latency
  std::vector<stream::PriorityPolicy> policies() const;  ///< --policy
  /// --transfer, or its default ("auto" without --tour, "tour" with one).
  std::string transfer_spec() const;
};

/// The output folder: `out` (created; InputError if it is a file), or a new one in /tmp when empty.
std::filesystem::path bench_out_dir(const std::string& out);

/// The scheduler's settings for a run with `settings` over `index`, and what was derived.
struct SchedulerSetup {
  stream::SchedulerSettings settings;
  double brick_bytes = 1;     ///< mean compressed bytes of a keyframe node
  bool atlas_capped = false;  ///< atlas_slots lowered to the container's keyframe nodes
};

/// The settings' priorities, link and budgets. More atlas slots than keyframe nodes are capped
/// (they change nothing but cost memory); requests in flight, unless given: what the link delivers
/// in latency + 0.5 s, in 32..4096 mean bricks (1024 with an unlimited link), since arrivals are
/// taken once per rendered frame and the CPU renders far fewer frames per second than a GPU player.
SchedulerSetup scheduler_setup(const BenchStreamSettings& settings, double bandwidth_bytes_per_s,
                               double latency_s, const stream::SpatialIndex& index);

/// The RunSetup of everything but the tour: render options (step, background), the clock, the
/// scheduler's settings.
RunSetup run_setup(const BenchStreamSettings& settings, const format::Container& container,
                   const stream::SpatialIndex& index, std::size_t index_errors,
                   const stream::SchedulerSettings& scheduler, int width, int height,
                   std::optional<cpu_render::TransferFunction> transfer);

/// The run's link and data rates.
struct BenchLink {
  double bandwidth_bytes_per_s = 0, latency_s = 0, playback_bytes_per_s = 0;
};

/// Everything a benchmark runs with, prepared from its settings (prepare_bench).
struct BenchPlan {
  std::unique_ptr<format::Container> container;
  cpu_render::TourContext context;
  std::unique_ptr<cpu_render::Tour> tour;  ///< the first tour (--tour, or the built-in one)
  int width = 0, height = 0;
  double play_speed = 0;  ///< the tour's fastest playback, keyframes per second
  BenchLink link;         ///< playback_bytes_per_s: every brick at play_speed
  std::filesystem::path out;
  std::unique_ptr<GroundTruth> truth;
  std::string truth_note;  ///< where the ground truth comes from
  std::string transfer_spec;
  std::unique_ptr<stream::SpatialIndex> index;
  SchedulerSetup scheduler;
  RunSetup setup;  ///< without its tour (run_tours sets each)
};

/// Checks `settings`, opens the container (InputError unless a container folder with frames, or
/// `source` when given: a remote one), makes
/// the first tour, the link, the output folder (bench_out_dir), the ground truth (open_original
/// with `series` and `options`), the transfer function, the spatial index (its warnings on stderr)
/// and the RunSetup.
BenchPlan prepare_bench(const BenchStreamSettings& settings, const std::string& container,
                        const std::string& series, const datasets::OpenOptions& options,
                        const std::string& out,
                        std::shared_ptr<const format::ContainerSource> source = nullptr);

// ---------------------------------------------------------------------------------------------
// The runs.

/// The runs of one tour, one per policy.
struct TourRuns {
  std::uint64_t seed = 0;
  std::vector<RunResult> runs;
};

/// Runs one long step (`title`, progress in `unit`): calls `step` with the progress to report.
using StageRunner = std::function<void(const std::string& title, const std::string& unit,
                                       const std::function<void(const Progress&)>& step)>;

/// Every tour (the first is `first`; with settings.seeds > 1 the built-in tours of seeds seed + 1,
/// ...) with every policy: run_tour, measure, the CSV; each tour's files in `out`, or
/// out/seed_S with several. `tour_done` is called after each tour.
std::vector<TourRuns> run_tours(const BenchStreamSettings& settings, RunSetup setup,
                                const cpu_render::Tour& first,
                                const cpu_render::TourContext& context, GroundTruth& truth,
                                const std::filesystem::path& out, const StageRunner& stage,
                                const std::function<void(const TourRuns&)>& tour_done);

/// One policy over the tours: the mean of the tours' mean image PSNRs, the frames with holes after
/// the first root brick, and whether every tour's first root arrived.
struct PolicyTotals {
  double mean_psnr = 0;
  std::size_t holes = 0, frames = 0;
  bool roots = true;
};

/// nullopt when no run has policy `name` ("patent", "nearest").
std::optional<PolicyTotals> policy_totals(const std::vector<TourRuns>& tours,
                                          const std::string& name);

/// summary.json without the targets: the settings, the runs ("runs" with one tour, "tours" with
/// several).
nlohmann::json bench_summary_json(const BenchStreamSettings& settings, const std::string& container,
                                  const RunSetup& setup, const BenchLink& link, bool original_truth,
                                  const std::vector<TourRuns>& tours);

/// The header of a run on stdout: the machine, the input, the ground truth, the tour and clock, the
/// renderer, the link, the patent policy's settings.
void print_bench_header(const BenchPlan& plan, const BenchStreamSettings& settings,
                        const std::string& container, const std::string& machine);

/// The checks: the patent's mean image PSNR above the baseline's, no hole after the first root
/// brick (printed, and set as summary's target_higher_psnr and target_no_holes); `several`: over
/// several tours.
void print_checks(nlohmann::json& summary, const std::optional<PolicyTotals>& patent,
                  const std::optional<PolicyTotals>& nearest, bool several, bool original_truth);

/// With several tours: each tour's mean image PSNR per policy, their difference, and the means.
void print_tour_table(const std::vector<TourRuns>& tours, const std::optional<PolicyTotals>& patent,
                      const std::optional<PolicyTotals>& nearest);

}  // namespace volreel::stream_bench
