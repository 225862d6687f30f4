// turbulence.cpp: pseudo-spectral DNS of forced isotropic turbulence in [0, 2π)³ (see
// turbulence.hpp for the method in one paragraph).
//
// Sources:
//  - Rotational form, Fourier–Galerkin projection and the 2/3 rule: Canuto, Hussaini, Quarteroni
//    & Zang, "Spectral Methods in Fluid Dynamics" (1988), §7.2–7.3; Orszag, J. Atmos. Sci. 28,
//    1074 (1971) for the truncation that makes quadratic products alias-free.
//  - Time stepping: Williamson, "Low-storage Runge–Kutta schemes", J. Comput. Phys. 35, 48–56
//    (1980), the third-order 2N-storage scheme A = (0, −5/9, −153/128), B = (1/3, 15/16, 8/15).
//  - Forcing f̂ = (P / 2E_f) û on 0 < |k| ≤ k_f, which injects exactly P: Lamorgese, Caughey &
//    Pope, Phys. Fluids 17, 015106 (2005), §II.
//  - Pressure from ∇²p = −∂i∂j(u_i u_j) and the Taylor microscale λ = (15νu'²/ε)^½, Re_λ = u'λ/ν:
//    Pope, "Turbulent Flows" (2000), eqs. 2.42 and 6.56–6.63; integral scale
//    L = (π / 2u'²) ∫E(k)/k dk: eq. 6.260.
//
// Storage: û is kept as Fourier coefficients (u(x) = Σ_k û_k e^{ik·x}, i.e. FFTW's forward
// transform divided by N³) of the r2c half spectrum. In FFTW's row-major terms the real array is
// [z][y][x] with x fastest, so the halved axis is k_x (0..N/2); modes with k_x = 0 or N/2 stand
// for themselves, all others also for their conjugate at −k, so they count twice in sums.
// Physical-space work arrays use FFTW's padded in-place layout, rows of N + 2 floats.
#include "volreel/datasets/turbulence.hpp"

#include <fftw3.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <limits>
#include <mutex>
#include <numbers>
#include <stdexcept>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/error.hpp"

namespace volreel::datasets {

TurbulenceVariable parse_turbulence_variable(const std::string& name) {
  if (name == "pressure" || name == "p") return TurbulenceVariable::pressure;
  if (name == "vorticity" || name == "vorticity_magnitude") {
    return TurbulenceVariable::vorticity_magnitude;
  }
  if (name == "u" || name == "velocity_x") return TurbulenceVariable::velocity_x;
  if (name == "v" || name == "velocity_y") return TurbulenceVariable::velocity_y;
  if (name == "w" || name == "velocity_z") return TurbulenceVariable::velocity_z;
  throw InputError("unknown turbulence variable '" + name +
                   "': expected pressure, vorticity, u, v or w");
}

std::string to_string(TurbulenceVariable variable) {
  switch (variable) {
    case TurbulenceVariable::pressure:
      return "pressure";
    case TurbulenceVariable::vorticity_magnitude:
      return "vorticity";
    case TurbulenceVariable::velocity_x:
      return "u";
    case TurbulenceVariable::velocity_y:
      return "v";
    case TurbulenceVariable::velocity_z:
      return "w";
  }
  return "?";
}

namespace {

constexpr double two_pi = 2.0 * std::numbers::pi;

/// Williamson (1980) third-order 2N-storage Runge–Kutta: q ← A_s q + dt·R(û); û ← û + B_s q.
constexpr std::array<float, 3> rk_a{0.0f, -5.0f / 9.0f, -153.0f / 128.0f};
constexpr std::array<float, 3> rk_b{1.0f / 3.0f, 15.0f / 16.0f, 8.0f / 15.0f};

/// Explicit RK3 is stable for real eigenvalues down to about −2.51/dt; the viscous limit keeps
/// ν·|k|²_max·dt at 2.0, leaving room for the advective part of the eigenvalues.
constexpr double viscous_stability = 2.0;

/// FFTW_ESTIMATE rather than FFTW_MEASURE: at N = 128 on 2 cores, measured plans made the 9
/// transforms of a stage 15 % faster (30 vs 36 ms) but cost 3 s to plan and may differ from run
/// to run, which would make runs with the same seed diverge (the flow is chaotic). Estimated
/// plans are the same every time.
constexpr unsigned planner_flags = FFTW_ESTIMATE;

/// Grids below this many points run on one thread: a 32³ step takes about 3 ms, less than what
/// OpenMP's spinning barriers cost when another process holds a core (a 32³ test ran 30× slower
/// with 2 threads on a busy 2-core machine). Larger grids suffer too under load (128³: 0.55 s
/// per step instead of 0.23 s on one thread); OMP_WAIT_POLICY=passive in the environment avoids
/// that at no measurable cost on an idle machine.
constexpr std::size_t threading_threshold = 64 * 64 * 64;

/// FFTW's planner (and plan destruction) is not thread-safe; every call goes through this lock.
std::mutex& fftw_planner_mutex() {
  static std::mutex mutex;
  return mutex;
}

struct FftwFree {
  void operator()(float* p) const noexcept { fftwf_free(p); }
};
using FftwBuffer = std::unique_ptr<float[], FftwFree>;

FftwBuffer allocate_floats(std::size_t count) {
  FftwBuffer buffer(fftwf_alloc_real(count));
  if (!buffer) throw std::bad_alloc();
  std::fill_n(buffer.get(), count, 0.0f);
  return buffer;
}

fftwf_complex* as_complex(float* p) {
  return reinterpret_cast<fftwf_complex*>(p);
}

void validate(const TurbulenceParams& p) {
  auto fail = [](const std::string& what) { throw InputError("turbulence: " + what); };
  if (p.size < 16 || p.size > 1024 || p.size % 2 != 0) {
    fail("grid size " + std::to_string(p.size) + " must be even and in 16..1024");
  }
  if (!(p.forcing_power >= 0.0) || !std::isfinite(p.forcing_power)) {
    fail("forcing power must be finite and >= 0");
  }
  if (!(p.forcing_kf > 0.0)) fail("forcing wavenumber k_f must be > 0");
  if (!(p.forcing_kf < static_cast<double>(p.size) / 3.0)) {
    fail("forcing wavenumber k_f must be below k_max = N/3");
  }
  if (!(p.kmax_eta > 0.0)) fail("k_max·eta must be > 0");
  if (!(p.viscosity >= 0.0)) fail("viscosity must be >= 0 (0: derive from k_max·eta)");
  if (!(p.cfl > 0.0 && p.cfl <= 2.0)) fail("CFL number must be in (0, 2]");
  if (!(p.initial_energy > 0.0) || !std::isfinite(p.initial_energy)) {
    fail("initial energy must be finite and > 0");
  }
  if (p.viscosity == 0.0 && p.forcing_power == 0.0) {
    fail("viscosity cannot be derived from k_max·eta without forcing power; set it explicitly");
  }
}

/// Spectral sums over the half spectrum (weights 1 or 2 as described at the top).
struct SpectralSums {
  double energy = 0;         ///< ½ Σ |û|²
  double k2_energy = 0;      ///< Σ |k|² ½|û|²  (ε = 2ν times this)
  double energy_over_k = 0;  ///< Σ ½|û|² / |k|
};

}  // namespace

struct TurbulenceSimulation::Impl {
  TurbulenceParams params;
  std::size_t n = 0;       ///< N
  std::size_t nh = 0;      ///< N/2 + 1: length of the halved k_x axis
  std::size_t row = 0;     ///< N + 2: padded length of a physical-space row
  std::size_t modes = 0;   ///< N·N·nh complex coefficients per field
  std::size_t stride = 0;  ///< floats per field, ≥ 2·modes, a multiple of 16 (64-byte alignment)
  double nu = 0;
  double kmax = 0;        ///< N/3
  double dt_viscous = 0;  ///< viscous stability limit
  float forced_k2 = 0;    ///< modes with 0 < |k|² ≤ forced_k2 are forced
  int threads = 1;        ///< OpenMP threads for loops and FFTs
  bool forcing = true;
  double time = 0;

  FftwBuffer velocity;               ///< û: 3 fields
  FftwBuffer rk;                     ///< Williamson's second register q: 3 fields
  FftwBuffer work;                   ///< 6 fields, physical (padded) or spectral
  std::vector<float> wavenumber;     ///< signed k of FFT index i (valid for every axis)
  std::vector<unsigned char> kept;   ///< 1 if index i survives the 2/3 rule
  std::vector<std::size_t> forced;   ///< half-spectrum indices of the forced modes
  std::vector<float> forced_weight;  ///< 1 or 2: half-spectrum weight of each forced mode
  fftwf_plan forward = nullptr;      ///< r2c, in place, on any work field
  fftwf_plan inverse = nullptr;      ///< c2r, in place, on any work field

  explicit Impl(const TurbulenceParams& p);
  ~Impl();
  Impl(const Impl&) = delete;
  Impl& operator=(const Impl&) = delete;

  float* u_hat(std::size_t c) const { return velocity.get() + c * stride; }
  float* q_hat(std::size_t c) const { return rk.get() + c * stride; }
  float* field(std::size_t f) const { return work.get() + f * stride; }
  void to_physical(std::size_t f) const {
    fftwf_execute_dft_c2r(inverse, as_complex(field(f)), field(f));
  }
  void to_spectral(std::size_t f) const {
    fftwf_execute_dft_r2c(forward, field(f), as_complex(field(f)));
  }
  float weight(std::size_t ix) const { return (ix == 0 || ix == n / 2) ? 1.0f : 2.0f; }

  /// Calls f(m, ix, kx, ky, kz, keep) for every half-spectrum mode m, in parallel.
  template <class F>
  void for_each_mode(F&& f) const;
  /// Calls f(i, o) for every grid point: i in the padded work layout, o = x + N(y + Nz).
  template <class F>
  void for_each_point(F&& f) const;

  void set_velocity_from_work();
  float forcing_coefficient() const;
  float nonlinear_term();
  void update(std::size_t stage, float dt, float fcoef);
  SpectralSums sums() const;
  float max_abs_physical(std::size_t f) const;
  void copy_out(std::size_t f, std::span<float> out) const;
};

TurbulenceSimulation::Impl::Impl(const TurbulenceParams& p) : params(p) {
  validate(p);
  n = static_cast<std::size_t>(p.size);
  nh = n / 2 + 1;
  row = n + 2;
  modes = n * n * nh;
  stride = (2 * modes + 15) / 16 * 16;
  kmax = static_cast<double>(n) / 3.0;
  threads = n * n * n >= threading_threshold ? std::max(1, omp_get_max_threads()) : 1;
  nu = p.viscosity > 0.0 ? p.viscosity
                         : std::cbrt(p.forcing_power * std::pow(p.kmax_eta / kmax, 4.0));

  // Wavenumbers and the 2/3 rule: index i keeps its mode if 3|k| < N (Orszag 1971), so that no
  // alias of a quadratic product lands on a retained mode. The largest retained |k|² is 3K².
  wavenumber.resize(n);
  kept.resize(n);
  int largest_kept = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const int k = i <= n / 2 ? static_cast<int>(i) : static_cast<int>(i) - static_cast<int>(n);
    wavenumber[i] = static_cast<float>(k);
    kept[i] = 3 * std::abs(k) < static_cast<int>(n) ? 1 : 0;
    if (kept[i]) largest_kept = std::max(largest_kept, std::abs(k));
  }
  dt_viscous = viscous_stability / (nu * 3.0 * largest_kept * largest_kept);

  forced_k2 = static_cast<float>(p.forcing_kf * p.forcing_kf);
  for (std::size_t iz = 0; iz < n; ++iz) {
    for (std::size_t iy = 0; iy < n; ++iy) {
      for (std::size_t ix = 0; ix < nh; ++ix) {
        const float k2 = wavenumber[ix] * wavenumber[ix] + wavenumber[iy] * wavenumber[iy] +
                         wavenumber[iz] * wavenumber[iz];
        if (k2 > 0.0f && k2 <= forced_k2 && kept[ix] && kept[iy] && kept[iz]) {
          forced.push_back(ix + nh * (iy + n * iz));
          forced_weight.push_back(weight(ix));
        }
      }
    }
  }

  velocity = allocate_floats(3 * stride);
  rk = allocate_floats(3 * stride);
  work = allocate_floats(6 * stride);

  // Plans are made once per simulation, on work field 0, and executed on every field through
  // the new-array interface (all fields share field 0's alignment because stride is a multiple
  // of 16 floats).
  static std::once_flag threads_once;
  static bool threads_ok = false;
  const int dims[3] = {p.size, p.size, p.size};
  {
    std::lock_guard<std::mutex> lock(fftw_planner_mutex());
    std::call_once(threads_once, [] { threads_ok = fftwf_init_threads() != 0; });
    if (threads_ok) fftwf_plan_with_nthreads(threads);
    forward = fftwf_plan_dft_r2c(3, dims, field(0), as_complex(field(0)), planner_flags);
    inverse = fftwf_plan_dft_c2r(3, dims, as_complex(field(0)), field(0), planner_flags);
    if (!forward || !inverse) {
      if (forward) fftwf_destroy_plan(forward);
      if (inverse) fftwf_destroy_plan(inverse);
      throw std::runtime_error("turbulence: FFTW could not make a " + std::to_string(p.size) +
                               "³ plan");
    }
  }
}

TurbulenceSimulation::Impl::~Impl() {
  std::lock_guard<std::mutex> lock(fftw_planner_mutex());
  if (forward) fftwf_destroy_plan(forward);
  if (inverse) fftwf_destroy_plan(inverse);
}

template <class F>
void TurbulenceSimulation::Impl::for_each_mode(F&& f) const {
  const auto nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for collapse(2) schedule(static) num_threads(threads)
  for (std::ptrdiff_t iz = 0; iz < nn; ++iz) {
    for (std::ptrdiff_t iy = 0; iy < nn; ++iy) {
      const auto z = static_cast<std::size_t>(iz), y = static_cast<std::size_t>(iy);
      const bool keep_zy = kept[z] && kept[y];
      const float ky = wavenumber[y], kz = wavenumber[z];
      const std::size_t base = nh * (y + n * z);
      for (std::size_t ix = 0; ix < nh; ++ix) {
        f(base + ix, ix, wavenumber[ix], ky, kz, keep_zy && kept[ix]);
      }
    }
  }
}

template <class F>
void TurbulenceSimulation::Impl::for_each_point(F&& f) const {
  const auto nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for collapse(2) schedule(static) num_threads(threads)
  for (std::ptrdiff_t iz = 0; iz < nn; ++iz) {
    for (std::ptrdiff_t iy = 0; iy < nn; ++iy) {
      const auto line = static_cast<std::size_t>(iy) + n * static_cast<std::size_t>(iz);
      for (std::size_t x = 0; x < n; ++x) f(x + row * line, x + n * line);
    }
  }
}

/// Work fields 0..2 hold a real velocity field (padded layout): transform it, normalise, apply
/// the 2/3 rule, remove the mean and project it onto divergence-free fields; store it as û.
void TurbulenceSimulation::Impl::set_velocity_from_work() {
  for (std::size_t c = 0; c < 3; ++c) to_spectral(c);
  const float scale = 1.0f / static_cast<float>(n * n * n);
  float* w[3] = {field(0), field(1), field(2)};
  float* u[3] = {u_hat(0), u_hat(1), u_hat(2)};
  for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool keep) {
    const float k2 = kx * kx + ky * ky + kz * kz;
    if (!keep || k2 == 0.0f) {
      for (std::size_t c = 0; c < 3; ++c) u[c][2 * m] = u[c][2 * m + 1] = 0.0f;
      return;
    }
    const float k[3] = {kx, ky, kz};
    for (std::size_t part = 0; part < 2; ++part) {
      const float kv =
          (kx * w[0][2 * m + part] + ky * w[1][2 * m + part] + kz * w[2][2 * m + part]) / k2;
      for (std::size_t c = 0; c < 3; ++c)
        u[c][2 * m + part] = scale * (w[c][2 * m + part] - k[c] * kv);
    }
  });
  std::fill_n(rk.get(), 3 * stride, 0.0f);
  time = 0.0;
}

float TurbulenceSimulation::Impl::forcing_coefficient() const {
  if (!forcing || params.forcing_power == 0.0) return 0.0f;
  // Serial sum over the few forced modes, so the forcing does not depend on the thread count.
  double twice_forced_energy = 0.0;
  for (std::size_t j = 0; j < forced.size(); ++j) {
    const std::size_t m = forced[j];
    double s = 0.0;
    for (std::size_t c = 0; c < 3; ++c) {
      const double re = u_hat(c)[2 * m], im = u_hat(c)[2 * m + 1];
      s += re * re + im * im;
    }
    twice_forced_energy += static_cast<double>(forced_weight[j]) * s;
  }
  if (!(twice_forced_energy > 0.0)) return 0.0f;
  return static_cast<float>(params.forcing_power / twice_forced_energy);  // P / (2 E_f)
}

/// Leaves FFT(u × ω) (unnormalised) in work fields 3..5 and returns max_i |u_i| over the grid;
/// 6 inverse and 3 forward transforms.
float TurbulenceSimulation::Impl::nonlinear_term() {
  // 1. Spectral space: fields 0..2 ← û, fields 3..5 ← ω̂ = ik × û.
  float* w[6] = {field(0), field(1), field(2), field(3), field(4), field(5)};
  const float* u[3] = {u_hat(0), u_hat(1), u_hat(2)};
  for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool) {
    const std::size_t re = 2 * m, im = 2 * m + 1;
    for (std::size_t c = 0; c < 3; ++c) {
      w[c][re] = u[c][re];
      w[c][im] = u[c][im];
    }
    // i(a + ib) = −b + ia
    w[3][re] = -(ky * u[2][im] - kz * u[1][im]);
    w[3][im] = ky * u[2][re] - kz * u[1][re];
    w[4][re] = -(kz * u[0][im] - kx * u[2][im]);
    w[4][im] = kz * u[0][re] - kx * u[2][re];
    w[5][re] = -(kx * u[1][im] - ky * u[0][im]);
    w[5][im] = kx * u[1][re] - ky * u[0][re];
  });
  // 2. Six inverse transforms to physical space.
  for (std::size_t f = 0; f < 6; ++f) to_physical(f);
  // 3. Pointwise u × ω into fields 3..5, and max |u_i| for the CFL condition.
  float umax = 0.0f;
  long nonfinite = 0;
  const auto nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for collapse(2) schedule(static) num_threads(threads) reduction(max : umax) reduction(+ : nonfinite)
  for (std::ptrdiff_t iz = 0; iz < nn; ++iz) {
    for (std::ptrdiff_t iy = 0; iy < nn; ++iy) {
      const std::size_t base =
          row * (static_cast<std::size_t>(iy) + n * static_cast<std::size_t>(iz));
      for (std::size_t i = base; i < base + n; ++i) {
        const float ux = w[0][i], uy = w[1][i], uz = w[2][i];
        const float ox = w[3][i], oy = w[4][i], oz = w[5][i];
        w[3][i] = uy * oz - uz * oy;
        w[4][i] = uz * ox - ux * oz;
        w[5][i] = ux * oy - uy * ox;
        const float a = std::max(std::abs(ux), std::max(std::abs(uy), std::abs(uz)));
        umax = std::max(umax, a);
        nonfinite += (a <= std::numeric_limits<float>::max()) ? 0 : 1;
      }
    }
  }
  if (nonfinite > 0) {
    throw std::runtime_error(
        "turbulence: velocity became non-finite at t=" + format::number_text(time) +
        " (unstable time step? cfl=" + format::number_text(params.cfl) + ")");
  }
  // 4. Three forward transforms back to spectral space.
  for (std::size_t f = 3; f < 6; ++f) to_spectral(f);
  return umax;
}

/// One Williamson stage: R = P[FFT(u×ω)/N³] − ν|k|²û + f̂, truncated by the 2/3 rule;
/// q ← A_s q + dt R; û ← P[û + B_s q].
void TurbulenceSimulation::Impl::update(std::size_t stage, float dt, float fcoef) {
  const float a = rk_a[stage], b = rk_b[stage];
  const float scale = 1.0f / static_cast<float>(n * n * n);
  const float viscosity = static_cast<float>(nu);
  const float fk2 = forced_k2;
  float* u[3] = {u_hat(0), u_hat(1), u_hat(2)};
  float* q[3] = {q_hat(0), q_hat(1), q_hat(2)};
  const float* nl[3] = {field(3), field(4), field(5)};
  for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool keep) {
    const float k2 = kx * kx + ky * ky + kz * kz;
    if (!keep || k2 == 0.0f) {
      for (std::size_t c = 0; c < 3; ++c)
        u[c][2 * m] = u[c][2 * m + 1] = q[c][2 * m] = q[c][2 * m + 1] = 0.0f;
      return;
    }
    const float k[3] = {kx, ky, kz};
    // Linear part: viscosity and (on the forced shells) the constant-power forcing.
    const float linear = -viscosity * k2 + (k2 <= fk2 ? fcoef : 0.0f);
    for (std::size_t part = 0; part < 2; ++part) {
      const std::size_t i = 2 * m + part;
      // 1. Normalised nonlinear term and its projection P = I − kk/|k|².
      const float r[3] = {scale * nl[0][i], scale * nl[1][i], scale * nl[2][i]};
      const float kr = (kx * r[0] + ky * r[1] + kz * r[2]) / k2;
      float next[3];
      for (std::size_t c = 0; c < 3; ++c) {
        // 2. Right-hand side, register update, solution update.
        const float rhs = (r[c] - k[c] * kr) + linear * u[c][i];
        q[c][i] = a * q[c][i] + dt * rhs;
        next[c] = u[c][i] + b * q[c][i];
      }
      // 3. Re-project û so that round-off in the update cannot accumulate a divergence.
      const float kn = (kx * next[0] + ky * next[1] + kz * next[2]) / k2;
      for (std::size_t c = 0; c < 3; ++c) u[c][i] = next[c] - k[c] * kn;
    }
  });
}

SpectralSums TurbulenceSimulation::Impl::sums() const {
  double energy = 0, k2_energy = 0, energy_over_k = 0;
  const float* u[3] = {u_hat(0), u_hat(1), u_hat(2)};
  const auto nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for collapse(2) schedule(static) num_threads(threads) reduction(+ : energy, k2_energy, energy_over_k)
  for (std::ptrdiff_t iz = 0; iz < nn; ++iz) {
    for (std::ptrdiff_t iy = 0; iy < nn; ++iy) {
      const auto z = static_cast<std::size_t>(iz), y = static_cast<std::size_t>(iy);
      const double kyz2 =
          static_cast<double>(wavenumber[y] * wavenumber[y] + wavenumber[z] * wavenumber[z]);
      const std::size_t base = nh * (y + n * z);
      for (std::size_t ix = 0; ix < nh; ++ix) {
        const std::size_t m = base + ix;
        double s = 0.0;
        for (std::size_t c = 0; c < 3; ++c) {
          const double re = u[c][2 * m], im = u[c][2 * m + 1];
          s += re * re + im * im;
        }
        if (s == 0.0) continue;
        const double kx = wavenumber[ix];
        const double k2 = kx * kx + kyz2;
        const double e = 0.5 * static_cast<double>(weight(ix)) * s;
        energy += e;
        k2_energy += k2 * e;
        if (k2 > 0.0) energy_over_k += e / std::sqrt(k2);
      }
    }
  }
  return {energy, k2_energy, energy_over_k};
}

float TurbulenceSimulation::Impl::max_abs_physical(std::size_t f) const {
  const float* w = field(f);
  float result = 0.0f;
  const auto nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for collapse(2) schedule(static) num_threads(threads) reduction(max : result)
  for (std::ptrdiff_t iz = 0; iz < nn; ++iz) {
    for (std::ptrdiff_t iy = 0; iy < nn; ++iy) {
      const std::size_t base =
          row * (static_cast<std::size_t>(iy) + n * static_cast<std::size_t>(iz));
      for (std::size_t i = base; i < base + n; ++i) result = std::max(result, std::abs(w[i]));
    }
  }
  return result;
}

void TurbulenceSimulation::Impl::copy_out(std::size_t f, std::span<float> out) const {
  const float* w = field(f);
  for_each_point([&](std::size_t i, std::size_t o) { out[o] = w[i]; });
}

TurbulenceSimulation::TurbulenceSimulation(const TurbulenceParams& params)
    : impl_(std::make_unique<Impl>(params)) {}

TurbulenceSimulation::~TurbulenceSimulation() = default;

void TurbulenceSimulation::initialize_random() {
  Impl& s = *impl_;
  // 1. White noise in physical space, component by component, x fastest: the same numbers for
  //    the same seed on every platform (SplitMix64, not <random>). Transforming real fields
  //    gives Hermitian-symmetric spectra without any bookkeeping.
  SplitMix64 rng(s.params.seed);
  for (std::size_t c = 0; c < 3; ++c) {
    float* w = s.field(c);
    std::fill_n(w, s.stride, 0.0f);
    for (std::size_t line = 0; line < s.n * s.n; ++line) {
      for (std::size_t x = 0; x < s.n; ++x) w[x + s.row * line] = static_cast<float>(rng.normal());
    }
  }
  // 2. Transform, truncate and project (set_velocity_from_work), then shape the spectrum:
  //    amplitude ∝ k·exp(−(k/k_p)²) makes the shell sum 4πk²|û|² ∝ k⁴exp(−2(k/k_p)²).
  s.set_velocity_from_work();
  constexpr float peak = 3.0f;
  float* u[3] = {s.u_hat(0), s.u_hat(1), s.u_hat(2)};
  s.for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool) {
    const float k = std::sqrt(kx * kx + ky * ky + kz * kz);
    const float shape = k * std::exp(-(k / peak) * (k / peak));
    for (std::size_t c = 0; c < 3; ++c) {
      u[c][2 * m] *= shape;
      u[c][2 * m + 1] *= shape;
    }
  });
  // 3. Scale to the requested kinetic energy.
  const double energy = s.sums().energy;
  const auto factor = static_cast<float>(std::sqrt(s.params.initial_energy / energy));
  for (std::size_t c = 0; c < 3; ++c) {
    float* p = u[c];
    for (std::size_t i = 0; i < 2 * s.modes; ++i) p[i] *= factor;
  }
}

void TurbulenceSimulation::initialize_taylor_green(double amplitude) {
  Impl& s = *impl_;
  const double h = two_pi / static_cast<double>(s.n);
  for (std::size_t c = 0; c < 3; ++c) std::fill_n(s.field(c), s.stride, 0.0f);
  float* w[3] = {s.field(0), s.field(1), s.field(2)};
  s.for_each_point([&](std::size_t i, std::size_t o) {
    const double x = h * static_cast<double>(o % s.n);
    const double y = h * static_cast<double>((o / s.n) % s.n);
    const double z = h * static_cast<double>(o / (s.n * s.n));
    w[0][i] = static_cast<float>(amplitude * std::sin(x) * std::cos(y) * std::cos(z));
    w[1][i] = static_cast<float>(-amplitude * std::cos(x) * std::sin(y) * std::cos(z));
  });
  s.set_velocity_from_work();
}

void TurbulenceSimulation::set_forcing(bool enabled) {
  impl_->forcing = enabled;
}

double TurbulenceSimulation::step(double max_dt) {
  Impl& s = *impl_;
  if (!(max_dt > 0.0))
    throw std::invalid_argument("TurbulenceSimulation::step: max_dt must be > 0");
  double dt = 0.0;
  for (std::size_t stage = 0; stage < 3; ++stage) {
    const float umax = s.nonlinear_term();
    if (stage == 0) {
      // dt = min(max_dt, cfl·dx / max|u_i|, 2 / (ν |k|²_max)), fixed for the three stages.
      const double dx = two_pi / static_cast<double>(s.n);
      const double dt_cfl = umax > 0.0f ? s.params.cfl * dx / static_cast<double>(umax)
                                        : std::numeric_limits<double>::infinity();
      dt = std::min({max_dt, dt_cfl, s.dt_viscous});
    }
    s.update(stage, static_cast<float>(dt), s.forcing_coefficient());
  }
  s.time += dt;
  return dt;
}

void TurbulenceSimulation::advance_to(double t) {
  Impl& s = *impl_;
  while (s.time < t) {
    const double remaining = t - s.time;
    if (remaining <= 1e-12 * std::max(1.0, std::abs(t))) break;
    if (step(remaining) >= remaining) break;
  }
  s.time = std::max(s.time, t);
}

double TurbulenceSimulation::time() const {
  return impl_->time;
}
double TurbulenceSimulation::viscosity() const {
  return impl_->nu;
}
int TurbulenceSimulation::size() const {
  return impl_->params.size;
}
double TurbulenceSimulation::kmax() const {
  return impl_->kmax;
}
double TurbulenceSimulation::kinetic_energy() const {
  return impl_->sums().energy;
}
double TurbulenceSimulation::dissipation() const {
  return 2.0 * impl_->nu * impl_->sums().k2_energy;
}

double TurbulenceSimulation::injected_power() const {
  const Impl& s = *impl_;
  // Σ Re(f̂·û*) over the full spectrum, with f̂ = (P / 2E_f) û on the forced modes.
  const double fcoef = static_cast<double>(s.forcing_coefficient());
  double power = 0.0;
  for (std::size_t j = 0; j < s.forced.size(); ++j) {
    const std::size_t m = s.forced[j];
    for (std::size_t c = 0; c < 3; ++c) {
      const double re = s.u_hat(c)[2 * m], im = s.u_hat(c)[2 * m + 1];
      power += static_cast<double>(s.forced_weight[j]) * fcoef * (re * re + im * im);
    }
  }
  return power;
}

double TurbulenceSimulation::kolmogorov_eta() const {
  const double eps = dissipation();
  return eps > 0.0 ? std::pow(impl_->nu * impl_->nu * impl_->nu / eps, 0.25)
                   : std::numeric_limits<double>::infinity();
}

double TurbulenceSimulation::max_velocity() const {
  const Impl& s = *impl_;
  float result = 0.0f;
  for (std::size_t c = 0; c < 3; ++c) {
    std::copy_n(s.u_hat(c), 2 * s.modes, s.field(0));
    s.to_physical(0);
    result = std::max(result, s.max_abs_physical(0));
  }
  return static_cast<double>(result);
}

double TurbulenceSimulation::relative_divergence() const {
  const Impl& s = *impl_;
  const float* u[3] = {s.u_hat(0), s.u_hat(1), s.u_hat(2)};
  float* w[4] = {s.field(0), s.field(1), s.field(2), s.field(3)};
  // ∂u_i/∂x_j for each i (fields 0..2), and ∇·u (field 3) with the first batch.
  float gradient_max = 0.0f;
  for (std::size_t i = 0; i < 3; ++i) {
    s.for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool) {
      const float k[3] = {kx, ky, kz};
      const float re = u[i][2 * m], im = u[i][2 * m + 1];
      for (std::size_t j = 0; j < 3; ++j) {
        w[j][2 * m] = -k[j] * im;
        w[j][2 * m + 1] = k[j] * re;
      }
      if (i == 0) {
        w[3][2 * m] = -(kx * u[0][2 * m + 1] + ky * u[1][2 * m + 1] + kz * u[2][2 * m + 1]);
        w[3][2 * m + 1] = kx * u[0][2 * m] + ky * u[1][2 * m] + kz * u[2][2 * m];
      }
    });
    for (std::size_t j = 0; j < 3; ++j) {
      s.to_physical(j);
      gradient_max = std::max(gradient_max, s.max_abs_physical(j));
    }
  }
  // Field 3 still holds the divergence's spectrum (only fields 0..2 were transformed).
  s.to_physical(3);
  const float divergence_max = s.max_abs_physical(3);
  return gradient_max > 0.0f
             ? static_cast<double>(divergence_max) / static_cast<double>(gradient_max)
             : 0.0;
}

double TurbulenceSimulation::eddy_turnover_time() const {
  const SpectralSums sum = impl_->sums();
  const double u2 = 2.0 * sum.energy / 3.0;  // u'²
  if (!(u2 > 0.0)) return std::numeric_limits<double>::infinity();
  const double integral_scale = std::numbers::pi / (2.0 * u2) * sum.energy_over_k;
  return integral_scale / std::sqrt(u2);
}

void TurbulenceSimulation::sample(TurbulenceVariable variable, std::span<float> out) const {
  const Impl& s = *impl_;
  if (out.size() != s.n * s.n * s.n) {
    throw std::invalid_argument("TurbulenceSimulation::sample: output has " +
                                std::to_string(out.size()) +
                                " values, expected N³ = " + std::to_string(s.n * s.n * s.n));
  }
  const float* u[3] = {s.u_hat(0), s.u_hat(1), s.u_hat(2)};
  float* w[6] = {s.field(0), s.field(1), s.field(2), s.field(3), s.field(4), s.field(5)};
  switch (variable) {
    case TurbulenceVariable::velocity_x:
    case TurbulenceVariable::velocity_y:
    case TurbulenceVariable::velocity_z: {
      const std::size_t c = variable == TurbulenceVariable::velocity_x   ? 0
                            : variable == TurbulenceVariable::velocity_y ? 1
                                                                         : 2;
      std::copy_n(u[c], 2 * s.modes, w[0]);
      s.to_physical(0);
      s.copy_out(0, out);
      return;
    }
    case TurbulenceVariable::vorticity_magnitude: {
      // ω̂ = ik × û, three inverse transforms, |ω| pointwise.
      s.for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool) {
        const std::size_t re = 2 * m, im = 2 * m + 1;
        w[0][re] = -(ky * u[2][im] - kz * u[1][im]);
        w[0][im] = ky * u[2][re] - kz * u[1][re];
        w[1][re] = -(kz * u[0][im] - kx * u[2][im]);
        w[1][im] = kz * u[0][re] - kx * u[2][re];
        w[2][re] = -(kx * u[1][im] - ky * u[0][im]);
        w[2][im] = kx * u[1][re] - ky * u[0][re];
      });
      for (std::size_t c = 0; c < 3; ++c) s.to_physical(c);
      s.for_each_point([&](std::size_t i, std::size_t o) {
        out[o] = std::sqrt(w[0][i] * w[0][i] + w[1][i] * w[1][i] + w[2][i] * w[2][i]);
      });
      return;
    }
    case TurbulenceVariable::pressure: {
      // 1. Velocity in physical space (fields 0..2).
      for (std::size_t c = 0; c < 3; ++c) std::copy_n(u[c], 2 * s.modes, w[c]);
      for (std::size_t c = 0; c < 3; ++c) s.to_physical(c);
      // 2. Products u_i u_j: fields 0..5 ← xx, yy, zz, xy, xz, yz.
      s.for_each_point([&](std::size_t i, std::size_t) {
        const float ux = w[0][i], uy = w[1][i], uz = w[2][i];
        w[0][i] = ux * ux;
        w[1][i] = uy * uy;
        w[2][i] = uz * uz;
        w[3][i] = ux * uy;
        w[4][i] = ux * uz;
        w[5][i] = uy * uz;
      });
      for (std::size_t f = 0; f < 6; ++f) s.to_spectral(f);
      // 3. p̂ = −k_i k_j (u_i u_j)^ / |k|², truncated by the 2/3 rule (the retained modes are
      //    alias-free), mean zero; into field 0.
      const float scale = 1.0f / static_cast<float>(s.n * s.n * s.n);
      s.for_each_mode([&](std::size_t m, std::size_t, float kx, float ky, float kz, bool keep) {
        const float k2 = kx * kx + ky * ky + kz * kz;
        for (std::size_t part = 0; part < 2; ++part) {
          const std::size_t i = 2 * m + part;
          if (!keep || k2 == 0.0f) {
            w[0][i] = 0.0f;
            continue;
          }
          const float kk = kx * kx * w[0][i] + ky * ky * w[1][i] + kz * kz * w[2][i] +
                           2.0f * (kx * ky * w[3][i] + kx * kz * w[4][i] + ky * kz * w[5][i]);
          w[0][i] = -scale * kk / k2;
        }
      });
      s.to_physical(0);
      s.copy_out(0, out);
      return;
    }
  }
}

TurbulenceReport generate_turbulence(const TurbulenceRun& run, RawSeriesWriter& writer,
                                     const Progress& progress) {
  const auto start = std::chrono::steady_clock::now();
  if (run.frames < 1) throw InputError("turbulence: frames must be >= 1");
  if (!(run.frame_interval > 0.0)) throw InputError("turbulence: frame interval must be > 0");
  if (!(run.spinup >= 0.0)) throw InputError("turbulence: spin-up must be >= 0");
  const auto side = static_cast<std::int64_t>(run.params.size);
  if (writer.dims() != Dims{side, side, side}) {
    throw InputError("turbulence: writer expects " + to_string(writer.dims()) +
                     " voxels but the grid is " + to_string(Dims{side, side, side}));
  }

  TurbulenceSimulation sim(run.params);
  if (run.decaying) {
    // ½⟨u·u⟩ of the Taylor–Green vortex of amplitude A is A²/8.
    sim.initialize_taylor_green(std::sqrt(8.0 * run.params.initial_energy));
    sim.set_forcing(false);
  } else {
    sim.initialize_random();
  }
  // The turnover time of the initial model-spectrum field fixes spin-up and frame spacing.
  const double turnover = sim.eddy_turnover_time();
  const double spinup_time = run.spinup * turnover;
  const double interval = run.frame_interval * turnover;
  const double total = spinup_time + static_cast<double>(run.frames - 1) * interval;
  const double kmax = sim.kmax();
  const double nu = sim.viscosity();

  TurbulenceReport report;
  report.viscosity = nu;
  report.eddy_turnover_time = turnover;

  // Time integrals over the recorded interval (trapezoidal in the steps).
  double dissipation = sim.dissipation();
  double power = sim.injected_power();
  double integral_dissipation = 0, integral_power = 0, integral_energy = 0, integral_turnover = 0;
  double energy = sim.kinetic_energy();
  double turnover_now = sim.eddy_turnover_time();
  double recording_energy_start = 0;
  bool recording = false;
  int frame = 0;

  auto status = [&] {
    char text[96];
    const double eta = dissipation > 0.0 ? std::pow(nu * nu * nu / dissipation, 0.25) : 0.0;
    std::snprintf(
        text, sizeof text, "t=%.2f kmax·η=%.2f %s", sim.time(), kmax * eta,
        recording
            ? ("frame " + std::to_string(frame + 1) + "/" + std::to_string(run.frames)).c_str()
            : "spin-up");
    return std::string(text);
  };
  auto advance = [&](double target) {
    while (sim.time() < target) {
      const double remaining = target - sim.time();
      if (remaining <= 1e-12 * std::max(1.0, target)) break;
      const double dt = sim.step(remaining);
      ++report.steps;
      const double next_dissipation = sim.dissipation();
      const double next_power = sim.injected_power();
      const double next_energy = sim.kinetic_energy();
      const double next_turnover = sim.eddy_turnover_time();
      if (recording) {
        integral_dissipation += 0.5 * dt * (dissipation + next_dissipation);
        integral_power += 0.5 * dt * (power + next_power);
        integral_energy += 0.5 * dt * (energy + next_energy);
        integral_turnover += 0.5 * dt * (turnover_now + next_turnover);
      }
      dissipation = next_dissipation;
      power = next_power;
      energy = next_energy;
      turnover_now = next_turnover;
      progress.report(sim.time(), total, status());
    }
  };

  advance(spinup_time);
  recording = true;
  recording_energy_start = energy;
  const std::size_t voxels = Dims{side, side, side}.voxels();
  std::vector<float> buffer(voxels);
  for (frame = 0; frame < run.frames; ++frame) {
    const double timestamp = static_cast<double>(frame) * interval;
    advance(spinup_time + timestamp);
    sim.sample(run.variable, buffer);
    writer.write_frame(static_cast<std::size_t>(frame), timestamp, buffer);
  }
  frame = run.frames - 1;

  const double span = static_cast<double>(run.frames - 1) * interval;
  const double mean_energy = span > 0.0 ? integral_energy / span : energy;
  report.mean_dissipation = span > 0.0 ? integral_dissipation / span : dissipation;
  report.injected_power = span > 0.0 ? integral_power / span : power;
  report.kmax_eta = kmax * std::pow(nu * nu * nu / report.mean_dissipation, 0.25);
  const double u2 = 2.0 * mean_energy / 3.0;
  const double taylor_scale = std::sqrt(15.0 * nu * u2 / report.mean_dissipation);
  report.taylor_reynolds = std::sqrt(u2) * taylor_scale / nu;
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  const TurbulenceParams& p = run.params;
  nlohmann::json generator = {
      {"method", "pseudo-spectral DNS of forced isotropic turbulence"},
      {"scheme",
       "Fourier-Galerkin, rotational form, 2/3-rule truncation (|k_i| < N/3), "
       "Williamson (1980) low-storage RK3, FFTW3 single precision"},
      {"box", "[0, 2pi)^3"},
      {"grid", p.size},
      {"variable", to_string(run.variable)},
      {"viscosity", nu},
      {"forcing", "f = P/(2 E_f) u on 0 < |k| <= k_f (constant power)"},
      {"forcing_power", p.forcing_power},
      {"forcing_kf", p.forcing_kf},
      {"kmax", kmax},
      {"kmax_eta_target", p.kmax_eta},
      {"kmax_eta", report.kmax_eta},
      {"taylor_reynolds", report.taylor_reynolds},
      {"mean_energy", mean_energy},
      {"mean_dissipation", report.mean_dissipation},
      {"injected_power", report.injected_power},
      {"energy_change_rate", span > 0.0 ? (energy - recording_energy_start) / span : 0.0},
      {"eddy_turnover_time", turnover},
      {"eddy_turnover_time_measured", span > 0.0 ? integral_turnover / span : turnover_now},
      {"spinup_time", spinup_time},
      {"frame_interval_time", interval},
      {"dt_policy",
       "min(cfl*dx/max|u_i|, " + format::number_text(viscous_stability) + "/(nu*|k|^2_max))"},
      {"cfl", p.cfl},
      {"initial_spectrum",
       run.decaying ? "Taylor-Green vortex, decaying (no forcing)" : "E(k) ~ k^4 exp(-2 (k/3)^2)"},
      {"initial_energy", p.initial_energy},
      {"seed", p.seed},
      {"steps", report.steps},
      {"threads",
       Dims{side, side, side}.voxels() >= threading_threshold ? omp_get_max_threads() : 1},
      {"wall_seconds", report.seconds},
  };
  writer.set_spacing({two_pi / static_cast<double>(p.size), two_pi / static_cast<double>(p.size),
                      two_pi / static_cast<double>(p.size)});
  writer.set_generator(std::move(generator));
  writer.finish();
  progress.report(total, total, status());
  return report;
}

}  // namespace volreel::datasets
