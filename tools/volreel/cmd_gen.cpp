// cmd_gen.cpp: `volreel gen turbulence|analytic` — make datasets in the raw series format.
#include <cstdio>
#include <memory>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/datasets/analytic.hpp"
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
  datasets::TurbulenceRun run = o.run;
  run.variable = datasets::parse_turbulence_variable(o.variable);
  const int n = run.params.size;
  if (n < 16 || n > 1024 || n % 2 != 0)
    throw InputError("--size must be even and between 16 and 1024 (got " + std::to_string(n) + ")");
  if (run.frames < 1) throw InputError("--frames must be at least 1");
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
  std::printf(
      "energy balance over the recording: injected power %.5g, dissipation %.5g (ratio %.3f)\n",
      r.injected_power, r.mean_dissipation, r.mean_dissipation / r.injected_power);
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
  datasets::AnalyticParams params;
  params.field = datasets::parse_analytic_field(o.field);
  params.dims = o.dims.empty() ? Dims{o.size, o.size, o.size} : parse_dims(o.dims);
  params.frames = o.frames;
  params.seed = o.seed;
  if (params.frames < 1) throw InputError("--frames must be at least 1");
  datasets::RawSeriesWriter writer(o.out, params.dims, "analytic-" + o.field, o.overwrite);
  ProgressBar bar("generating", "frames");
  datasets::generate_analytic(params, writer, bar.progress());
  bar.finish();
  std::printf("wrote %zu frames of %s (%s) to %s\n", params.frames, o.field.c_str(),
              to_string(params.dims).c_str(), o.out.c_str());
}

}  // namespace

void add_gen_command(CLI::App& app) {
  CLI::App* gen = app.add_subcommand("gen",
                                     "Generate a dataset in volreel's raw series format "
                                     "(series.json + one float32 file per frame)");
  gen->require_subcommand(1);

  auto t = std::make_shared<TurbulenceOptions>();
  CLI::App* turb = gen->add_subcommand("turbulence",
                                       "Forced isotropic turbulence: a pseudo-spectral DNS in a "
                                       "periodic box (FFTW3 + OpenMP, 2/3 dealiasing, RK3,\n"
                                       "constant-power forcing of the lowest wavenumbers, "
                                       "viscosity for k_max*eta >= 1, CFL-limited steps).");
  turb->add_option("--size", t->run.params.size, "Grid points per side N (even, 16..1024)")
      ->capture_default_str();
  turb->add_option("--frames", t->run.frames, "Frames to record")->capture_default_str();
  turb->add_option("--out", t->out, "Output directory")->required();
  turb->add_option("--variable", t->variable, "Recorded field: pressure, vorticity, u, v or w")
      ->capture_default_str();
  turb->add_option("--interval", t->run.frame_interval,
                   "Simulated time between frames, in large-eddy turnover times")
      ->capture_default_str();
  turb->add_option("--spinup", t->run.spinup,
                   "Simulated time before the first frame, in large-eddy turnover times")
      ->capture_default_str();
  turb->add_option("--power", t->run.params.forcing_power, "Injected power per unit mass P")
      ->capture_default_str();
  turb->add_option("--kmax-eta", t->run.params.kmax_eta,
                   "Resolution target k_max*eta that sets the viscosity")
      ->capture_default_str();
  turb->add_option("--cfl", t->run.params.cfl, "Courant number of the time step")
      ->capture_default_str();
  turb->add_option("--seed", t->run.params.seed, "Seed of the random initial field")
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
  analytic->add_option("--size", a->size, "Voxels per side of a cube")->capture_default_str();
  analytic->add_option("--dims", a->dims, "XxYxZ instead of a cube, e.g. 96x64x48");
  analytic->add_option("--frames", a->frames, "Frames")->capture_default_str();
  analytic->add_option("--seed", a->seed, "Seed")->capture_default_str();
  analytic->add_option("--out", a->out, "Output directory")->required();
  analytic->add_flag("--overwrite", a->overwrite, "Replace an existing series in --out");
  analytic->callback([a] { run_analytic(*a); });
}

}  // namespace volreel::cli
