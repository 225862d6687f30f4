// turbulence.hpp: pseudo-spectral direct numerical simulation of forced isotropic turbulence in
// a periodic box [0, 2π)³ — the kind of data in the MTV-Player paper's IsoTur set.
//
// Method: incompressible Navier–Stokes in rotational form, Fourier–Galerkin in space with the
// 2/3 rule (cubic truncation, k_max = N/3), third-order low-storage Runge–Kutta in time with the
// time step limited by CFL and viscous stability; forcing of the shells |k| ≤ k_f at constant
// power P; viscosity chosen from P so that k_max·η reaches the requested resolution.
// Single precision (FFTW3f), threaded with OpenMP.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "volreel/datasets/volume.hpp"

namespace volreel::datasets {

class RawSeriesWriter;

/// The field recorded from the simulation.
enum class TurbulenceVariable { pressure, vorticity_magnitude, velocity_x, velocity_y, velocity_z };
/// "pressure", "vorticity", "u", "v", "w" (also "velocity_x", ...); throws InputError otherwise.
TurbulenceVariable parse_turbulence_variable(const std::string& name);
std::string to_string(TurbulenceVariable variable);

struct TurbulenceParams {
  int size = 128;              ///< N: grid points per side, even, 16..1024
  double forcing_power = 0.1;  ///< P: injected power per unit mass (constant)
  double forcing_kf = 2.5;     ///< modes with 0 < |k| ≤ k_f are forced
  double kmax_eta = 1.0;  ///< target resolution k_max·η; sets ν = (P·(kmax_eta/k_max)⁴)^(1/3)
  double viscosity = 0.0;       ///< if > 0, overrides the value derived from kmax_eta
  double cfl = 0.5;             ///< Courant number: dt ≤ cfl·dx / max|u_i|
  double initial_energy = 0.5;  ///< kinetic energy of the random initial field (½⟨u·u⟩)
  std::uint64_t seed = 1;       ///< seed of the random-phase initial field
};

/// One running simulation. Not copyable (owns FFTW plans and large arrays). Not safe to use from
/// several threads at once: the const members share the simulation's scratch arrays too.
class TurbulenceSimulation {
 public:
  explicit TurbulenceSimulation(const TurbulenceParams& params);
  ~TurbulenceSimulation();
  TurbulenceSimulation(const TurbulenceSimulation&) = delete;
  TurbulenceSimulation& operator=(const TurbulenceSimulation&) = delete;

  /// Random solenoidal field with a model spectrum E(k) ∝ k⁴ exp(-2(k/k_p)²), k_p = 3,
  /// scaled to params.initial_energy. Resets time to 0. Deterministic for the seed.
  void initialize_random();
  /// Taylor–Green vortex u = A(sin x cos y cos z, −cos x sin y cos z, 0). Resets time to 0.
  void initialize_taylor_green(double amplitude);
  /// Turn forcing off (for decay tests) or on again (default on).
  void set_forcing(bool enabled);

  /// Advance by one step of at most max_dt (and at most the CFL/viscous limit). Returns the dt
  /// taken.
  double step(double max_dt);
  /// Advance exactly to simulated time t (last step shortened to land on it).
  void advance_to(double t);

  double time() const;
  double viscosity() const;
  int size() const;
  double kmax() const;            ///< N/3
  double kinetic_energy() const;  ///< ½⟨u·u⟩ (volume average)
  double dissipation() const;     ///< ε = 2ν Σ_k k² E(k) = ν⟨|ω|²⟩
  double injected_power() const;  ///< Σ Re(f̂·û*) at the current state (= P when forcing on)
  double kolmogorov_eta() const;  ///< (ν³/ε)^(1/4)
  double max_velocity() const;    ///< max over the grid of max(|u|,|v|,|w|) (physical space)
  /// max |∇·u| over the grid divided by max |∂u_i/∂x_j|: round-off level for a solenoidal field.
  double relative_divergence() const;
  /// Large-eddy turnover time L/u' with L = (π/(2u'²))Σ E(k)/k, u' = sqrt(2E/3).
  double eddy_turnover_time() const;

  /// Sample a variable on the N³ grid (x fastest) into out (size N³).
  void sample(TurbulenceVariable variable, std::span<float> out) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

struct TurbulenceRun {
  TurbulenceParams params;
  int frames = 64;               ///< time steps to record
  double frame_interval = 0.05;  ///< simulated time between records, in eddy-turnover times
  double spinup = 7.0;           ///< simulated time before the first record, in eddy-turnover times
                                 ///< (the start-up transient of ε settles after about 7)
  TurbulenceVariable variable = TurbulenceVariable::pressure;
  /// Decaying instead of forced: start from the Taylor–Green vortex (smooth, one large scale, of
  /// kinetic energy params.initial_energy) with the forcing off, so that the recorded flow goes
  /// from smooth to turbulent and then decays. The viscosity is still the one params give.
  bool decaying = false;
};

/// Summary printed at the end of a run and stored in series.json's "generator" object.
struct TurbulenceReport {
  double viscosity = 0, kmax_eta = 0, eddy_turnover_time = 0, taylor_reynolds = 0;
  double mean_dissipation = 0, injected_power = 0;  ///< averaged over the recorded interval
  double seconds = 0;                               ///< wall-clock time
  long steps = 0;
};

/// Spin up, then record run.frames frames through writer (which writes series.json at the end).
/// The eddy-turnover time used for spin-up and frame spacing is estimated from the model
/// spectrum before running and kept fixed, so timestamps are known in advance.
TurbulenceReport generate_turbulence(const TurbulenceRun& run, RawSeriesWriter& writer,
                                     const Progress& progress = {});

}  // namespace volreel::datasets
