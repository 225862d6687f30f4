// cmd_gen.cpp: `volreel gen turbulence|analytic` — make datasets in the raw series format;
// `volreel gen mosaic` — a large container for the player's benchmarks.
#include <algorithm>
#include <charconv>
#include <cstdio>
#include <memory>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/mosaic.hpp"
#include "volreel/datasets/turbulence.hpp"

namespace volreel::cli {

namespace {

struct TurbulenceOptions {
  datasets::TurbulenceRun run;
  std::string variable = "pressure";
  std::string out;
  bool overwrite = false;
};

void run_turbulence(const TurbulenceOptions& o) {
  const StopOnSignal stop;  // Ctrl-C removes what was written
  datasets::TurbulenceRun run = o.run;
  run.variable = datasets::parse_turbulence_variable(o.variable);
  const int n = run.params.size;
  if (n < 16 || n > 1024 || n % 2 != 0)
    throw InputError("--size must be even and between 16 and 1024 (got " + std::to_string(n) + ")");
  if (run.frame_interval <= 0) throw InputError("--interval must be positive");
  datasets::RawSeriesWriter writer(o.out, Dims{n, n, n}, datasets::to_string(run.variable),
                                   o.overwrite);
  std::printf(
      "volreel gen turbulence: %d^3 grid, %d frames of %s every %.3g eddy-turnover times after "
      "%.3g of spin-up -> %s\n",
      n, run.frames, o.variable.c_str(), run.frame_interval, run.spinup, o.out.c_str());
  ProgressBar bar("simulating", "time units");
  const datasets::TurbulenceReport r = datasets::generate_turbulence(run, writer, bar.progress());
  bar.finish();
  std::printf(
      "viscosity %.4g, k_max*eta %.3f, Taylor Reynolds number %.1f, eddy-turnover time %.3f\n",
      r.viscosity, r.kmax_eta, r.taylor_reynolds, r.eddy_turnover_time);
  if (r.injected_power > 0)
    std::printf(
        "energy balance over the recording: injected power %.5g, dissipation %.5g (ratio %.3f)\n",
        r.injected_power, r.mean_dissipation, r.mean_dissipation / r.injected_power);
  else  // decaying: nothing forces the flow
    std::printf("energy over the recording: no forcing (decaying), dissipation %.5g\n",
                r.mean_dissipation);
  std::printf("%ld time steps in %.1f s; wrote %s/series.json\n", r.steps, r.seconds,
              o.out.c_str());
}

struct AnalyticOptions {
  std::string field = "blobs", dims, out;
  int size = 64;
  std::size_t frames = 16;
  std::uint64_t seed = 1;
  bool overwrite = false;
};

void run_analytic(const AnalyticOptions& o) {
  const StopOnSignal stop;  // Ctrl-C removes what was written
  datasets::AnalyticParams params;
  params.field = datasets::parse_analytic_field(o.field);
  params.dims = o.dims.empty() ? Dims{o.size, o.size, o.size} : parse_dims(o.dims);
  check_frame_voxels(params.dims, "--size " + std::to_string(o.size));
  params.frames = o.frames;
  params.seed = o.seed;
  datasets::RawSeriesWriter writer(o.out, params.dims, "analytic-" + o.field, o.overwrite);
  ProgressBar bar("generating", "frames");
  datasets::generate_analytic(params, writer, bar.progress());
  bar.finish();
  std::printf("wrote %zu frames of %s (%s) to %s\n", params.frames, o.field.c_str(),
              to_string(params.dims).c_str(), o.out.c_str());
}

struct MosaicOptions {
  std::string from, size, out;
  std::size_t frames = 0;
  std::uint32_t max_keyframe_gap = 8;
  std::size_t pool = 8;
  int threads = 0;
};

/// "N" (a cube) or "XxYxZ".
std::array<std::uint32_t, 3> parse_mosaic_size(const std::string& text) {
  std::uint64_t n = 0;
  const char* end = text.data() + text.size();
  const auto [next, ec] = std::from_chars(text.data(), end, n);
  if (ec == std::errc() && next == end) {
    if (n == 0 || n > (1u << 20))
      throw InputError("--size must be 1..1048576 voxels a side (got " + text + ")");
    const auto side = static_cast<std::uint32_t>(n);
    return {side, side, side};
  }
  if (text.find_first_not_of("0123456789") == std::string::npos)
    throw InputError("--size '" + text + "' is too large");
  const Dims d = parse_dims(text);
  return {static_cast<std::uint32_t>(d.x), static_cast<std::uint32_t>(d.y),
          static_cast<std::uint32_t>(d.z)};
}

void run_mosaic(const MosaicOptions& o) {
  const StopOnSignal stop;  // Ctrl-C removes what was written
  datasets::MosaicParams p;
  p.source = o.from;
  p.out = o.out;
  p.dims = parse_mosaic_size(o.size);
  if (o.max_keyframe_gap < 1 || o.max_keyframe_gap > 65535)
    throw InputError("--max-keyframe-gap must be 1..65535 (got " +
                     std::to_string(o.max_keyframe_gap) + ")");
  if (o.pool < 1) throw InputError("--pool must be at least 1 (got 0)");
  if (o.threads < 0)
    throw InputError("--threads must be 0 (all) or more (got " + std::to_string(o.threads) + ")");
  p.frames = o.frames;
  p.max_keyframe_gap = o.max_keyframe_gap;
  p.pool_bricks = o.pool;
  p.threads = o.threads;
  p.program_version = VOLREEL_VERSION;
  std::printf("volreel gen mosaic: %ux%ux%u, %zu frames, keyframes every %u, bricks of %s -> %s\n",
              p.dims[0], p.dims[1], p.dims[2], p.frames, p.max_keyframe_gap, o.from.c_str(),
              o.out.c_str());
  std::fflush(stdout);
  ProgressBar bar("writing", "frames");
  const datasets::MosaicReport r = datasets::write_mosaic(p, bar.progress());
  bar.finish();
  const auto [smallest, largest] =
      std::minmax_element(r.pool_brick_bytes.begin(), r.pool_brick_bytes.end());
  std::printf("%zu nodes a frame in %zu levels; a pool of %zu bricks of %zu..%zu bytes\n",
              r.nodes_per_frame, r.levels, r.pool_brick_bytes.size(), *smallest, *largest);
  const double node_steps = static_cast<double>(r.nodes_per_frame) * static_cast<double>(p.frames);
  std::printf(
      "wrote %s: %llu bytes (%.2f MB a frame), %llu bricks stored (%.1f %% of node-steps) in "
      "%.1f s\n",
      o.out.c_str(), static_cast<unsigned long long>(r.container_bytes),
      static_cast<double>(r.container_bytes) / 1e6 / static_cast<double>(p.frames),
      static_cast<unsigned long long>(r.bricks), 100.0 * static_cast<double>(r.bricks) / node_steps,
      r.seconds);
}

}  // namespace

void add_gen_command(CLI::App& app) {
  CLI::App* gen = app.add_subcommand("gen",
                                     "Generate a dataset in volreel's raw series format "
                                     "(series.json + one float32 file per frame),\nor (gen "
                                     "mosaic) a large container for the player's benchmarks");
  gen->require_subcommand(1);

  auto t = std::make_shared<TurbulenceOptions>();
  CLI::App* turb = gen->add_subcommand("turbulence",
                                       "Forced isotropic turbulence: a pseudo-spectral DNS in a "
                                       "periodic box (FFTW3 + OpenMP, 2/3 dealiasing, RK3,\n"
                                       "constant-power forcing of the lowest wavenumbers, "
                                       "viscosity for k_max*eta >= 1, CFL-limited steps).");
  turb->add_option("--size", t->run.params.size, "Grid points per side N (even, 16..1024)")
      ->capture_default_str();
  turb->add_option("--frames", t->run.frames, "Frames to record")
      ->check(in_range(1, 1e6))
      ->capture_default_str();
  turb->add_option("--out", t->out, "Output directory")->required();
  turb->add_option("--variable", t->variable, "Recorded field: pressure, vorticity, u, v or w")
      ->capture_default_str();
  turb->add_option("--interval", t->run.frame_interval,
                   "Simulated time between frames, in large-eddy turnover times")
      ->capture_default_str();
  turb->add_option("--spinup", t->run.spinup,
                   "Simulated time before the first frame, in large-eddy turnover times")
      ->capture_default_str();
  turb->add_option("--power", t->run.params.forcing_power,
                   "Injected power per unit mass P (> 0; the viscosity follows from it and "
                   "--kmax-eta)")
      ->check(positive())
      ->capture_default_str();
  turb->add_option("--kmax-eta", t->run.params.kmax_eta,
                   "Resolution target k_max*eta that sets the viscosity")
      ->capture_default_str();
  turb->add_option("--cfl", t->run.params.cfl, "Courant number of the time step")
      ->capture_default_str();
  turb->add_option("--seed", t->run.params.seed, "Seed of the random initial field")
      ->check(seed_number())
      ->capture_default_str();
  turb->add_flag(
      "--decaying", t->run.decaying,
      "Decaying flow: start from the smooth Taylor-Green vortex with the forcing off, so "
      "that the frames go from\nsmooth to turbulent (use --spinup 0 and an --interval "
      "of about 0.5 to see the transition)");
  turb->add_flag("--overwrite", t->overwrite, "Replace an existing series in --out");
  turb->callback([t] { run_turbulence(*t); });

  auto a = std::make_shared<AnalyticOptions>();
  CLI::App* analytic = gen->add_subcommand("analytic",
                                           "Small deterministic time-varying fields for tests: "
                                           "moving blobs, a rotating pattern, drifting noise, "
                                           "a plume rising into a still box");
  analytic
      ->add_option("--field", a->field,
                   "blobs, rotating, noise or plume (a plume rising into a still box)")
      ->capture_default_str();
  CLI::Option* analytic_size = analytic->add_option("--size", a->size, "Voxels per side of a cube")
                                   ->check(CLI::Range(1, 1 << 20))
                                   ->capture_default_str();
  analytic->add_option("--dims", a->dims, "XxYxZ instead of a cube, e.g. 96x64x48")
      ->excludes(analytic_size);
  analytic->add_option("--frames", a->frames, "Frames")
      ->check(in_range(1, 1e8))
      ->capture_default_str();
  analytic->add_option("--seed", a->seed, "Seed")->check(seed_number())->capture_default_str();
  analytic->add_option("--out", a->out, "Output directory")->required();
  analytic->add_flag("--overwrite", a->overwrite, "Replace an existing series in --out");
  analytic->callback([a] { run_analytic(*a); });

  auto m = std::make_shared<MosaicOptions>();
  CLI::App* mosaic = gen->add_subcommand(
      "mosaic",
      "A large container for measuring the player's indexing and scheduling at scale (e.g. "
      "10,000 frames of 1024^3),\nwritten in minutes instead of encoded in days. Its frame files "
      "are real and valid (volreel verify accepts\nthem): every node of the octree of --size, "
      "keyframes every --max-keyframe-gap frames with about 1 node in 4\nstoring a brick in the "
      "frames between. But the bricks repeat a few bricks of --from (the --pool smallest\n"
      "distinct bricks of its first 4 frames, non-constant ones first, chosen for a small "
      "container: node\ntables alone cost 16 bytes a node a frame), picked by a hash of the "
      "node and the keyframe stretch: no\ndata to look at for science. Codec, dictionary, "
      "tolerance and value range are the source's.");
  mosaic->add_option("--from", m->from, "Source container (NAME.vreel) whose bricks are repeated")
      ->required();
  mosaic->add_option("--size", m->size, "Voxels: N (a cube) or XxYxZ")->required();
  mosaic->add_option("--frames", m->frames, "Frames (time steps)")
      ->check(in_range(1, 1e8))
      ->required();
  mosaic
      ->add_option("--max-keyframe-gap", m->max_keyframe_gap,
                   "G: frames 0, T-1 and every multiple of G store every node (as volreel encode)")
      ->capture_default_str();
  mosaic->add_option("--pool", m->pool, "Distinct source bricks repeated (the smallest)")
      ->capture_default_str();
  mosaic->add_option("--threads", m->threads, "Frames written at once (0: one per core)")
      ->capture_default_str();
  mosaic->add_option("--out", m->out, "The new container (must not exist: never overwritten)")
      ->required();
  mosaic->callback([m] { run_mosaic(*m); });
}

}  // namespace volreel::cli
