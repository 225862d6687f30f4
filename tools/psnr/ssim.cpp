// ssim.cpp: structural similarity (Wang, Bovik, Sheikh, Simoncelli 2004, "Image quality
// assessment: from error visibility to structural similarity", eq. 13 with the Gaussian window
// of section III-C) in 1, 2 or 3 D, computed as scikit-image 0.19's
// structural_similarity(gaussian_weights=True, use_sample_covariance=False) does.
//
// scikit-image filters the five moments a, b, a², b², ab with scipy.ndimage.gaussian_filter
// (mode 'reflect'), forms the SSIM map and averages it over the voxels at least the filter
// radius r from every border. A voxel in that region only sees voxels inside the array, so the
// boundary mode never matters and only the cropped region is ever filtered here. The 3D Gaussian
// is separable: x, then y for a slab of up to 16 z slices into a ring of 2r + 16 filtered slices,
// then z for the output slices whose window is complete; memory is a few dozen slices of five
// doubles, not five whole volumes.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include "volreel/format/error.hpp"
#include "volreel/psnr/metrics.hpp"

namespace volreel::psnr {
namespace {

constexpr int kMoments = 5;                                // a, b, a², b², ab
constexpr std::size_t kSlabBytes = std::size_t{32} << 20;  // target size of the slab buffers
constexpr std::int64_t kMaxSlab = 16;                      // most slices filtered between barriers

/// Normalised Gaussian taps w[0..2r] for offsets −r..r, as scipy's _gaussian_kernel1d(order 0).
std::vector<double> gaussian_taps(double sigma, std::int64_t radius) {
  std::vector<double> taps(static_cast<std::size_t>(2 * radius + 1));
  double sum = 0;
  for (std::int64_t t = -radius; t <= radius; ++t) {
    const double x = static_cast<double>(t);
    const double w = std::exp(-0.5 / (sigma * sigma) * x * x);
    taps[static_cast<std::size_t>(t + radius)] = w;
    sum += w;
  }
  for (double& w : taps) w /= sum;
  return taps;
}

/// out[i] = Σ_t taps[t]·in[i + t·stride] for i in [0, n): one output row of a 1D correlation.
inline void correlate_row(double* __restrict out, const double* __restrict in, std::int64_t n,
                          const std::vector<double>& taps, std::int64_t stride) {
  const double w0 = taps[0];
  for (std::int64_t i = 0; i < n; ++i) out[i] = w0 * in[i];
  for (std::size_t t = 1; t < taps.size(); ++t) {
    const double w = taps[t];
    const double* __restrict src = in + static_cast<std::int64_t>(t) * stride;
    for (std::int64_t i = 0; i < n; ++i) out[i] += w * src[i];
  }
}

std::size_t to_size(std::int64_t v) {
  return static_cast<std::size_t>(v);
}

/// The Gaussian window's radius: int(truncate·sigma + 0.5) (options checked by the caller).
std::int64_t window_radius(const SsimOptions& options) {
  return static_cast<std::int64_t>(options.truncate * options.sigma + 0.5);
}

}  // namespace

std::string ssim_unfit(Dims dims, const SsimOptions& options) {
  if (!(options.sigma > 0) || !(options.truncate >= 0) ||
      !std::isfinite(options.sigma * options.truncate))
    return "";  // ssim refuses the options themselves
  const std::int64_t window = 2 * window_radius(options) + 1;
  const std::int64_t extent[3] = {dims.x, dims.y, dims.z};
  for (int a = 0; a < 3; ++a)
    if (extent[a] > 1 && extent[a] < window)
      return std::string("axis ") + "xyz"[a] + " has " + std::to_string(extent[a]) +
             " voxels, fewer than the " + std::to_string(window) + "-voxel window";
  return "";
}

double ssim(Dims dims, std::span<const float> original, std::span<const float> decoded,
            const SsimOptions& options) {
  // 1. Check the arguments and find the window radius of each axis (0 on axes of extent 1).
  if (dims.x <= 0 || dims.y <= 0 || dims.z <= 0) {
    throw InputError("SSIM: dimensions " + std::to_string(dims.x) + "x" + std::to_string(dims.y) +
                     "x" + std::to_string(dims.z) + " are not all positive");
  }
  if (original.size() != dims.voxels() || decoded.size() != dims.voxels()) {
    throw InputError("SSIM: dimensions " + std::to_string(dims.x) + "x" + std::to_string(dims.y) +
                     "x" + std::to_string(dims.z) + " need " + std::to_string(dims.voxels()) +
                     " values, got " + std::to_string(original.size()) + " original and " +
                     std::to_string(decoded.size()) + " decoded");
  }
  if (!(options.sigma > 0) || !(options.truncate >= 0) ||
      !std::isfinite(options.sigma * options.truncate)) {
    throw InputError("SSIM: sigma must be positive and truncate non-negative (got sigma " +
                     format::number_text(options.sigma) + ", truncate " +
                     format::number_text(options.truncate) + ")");
  }
  if (!(options.data_range >= 0) || !std::isfinite(options.data_range)) {
    throw InputError("SSIM: data range " + format::number_text(options.data_range) +
                     " is not a finite value >= 0");
  }
  const auto radius = window_radius(options);
  const std::int64_t extent[3] = {dims.x, dims.y, dims.z};
  if (const std::string unfit = ssim_unfit(dims, options); !unfit.empty())
    throw InputError("SSIM: " + unfit);
  std::int64_t r[3];
  for (int a = 0; a < 3; ++a) r[a] = extent[a] > 1 ? radius : 0;
  const std::int64_t nx = dims.x, ny = dims.y, nz = dims.z;
  const std::int64_t cx = nx - 2 * r[0], cy = ny - 2 * r[1], cz = nz - 2 * r[2];  // cropped extents

  // 2. Range of the original (for the default data range) and a check for non-finite values.
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  bool finite = true;
  for (std::size_t i = 0; i < original.size(); ++i) {
    finite = finite && std::isfinite(original[i]) && std::isfinite(decoded[i]);
    lo = std::min(lo, original[i]);
    hi = std::max(hi, original[i]);
  }
  if (!finite) {
    for (std::size_t i = 0; i < original.size(); ++i) {
      if (!std::isfinite(original[i]) || !std::isfinite(decoded[i])) {
        throw InputError(std::string("SSIM: ") +
                         (std::isfinite(original[i]) ? "decoded" : "original") + " value " +
                         std::to_string(i) + " is not finite");
      }
    }
  }
  double data_range = options.data_range;
  if (data_range == 0) data_range = static_cast<double>(hi) - static_cast<double>(lo);
  if (data_range == 0) data_range = 1;  // constant original: any scale will do, keep C1, C2 > 0
  const double c1 = (options.k1 * data_range) * (options.k1 * data_range);
  const double c2 = (options.k2 * data_range) * (options.k2 * data_range);

  const std::vector<double> wx = gaussian_taps(options.sigma, r[0]);
  const std::vector<double> wy = gaussian_taps(options.sigma, r[1]);
  const std::vector<double> wz = gaussian_taps(options.sigma, r[2]);

  // 3. Buffers: a slab of up to `slab` x-filtered slices (all rows, cropped x), a ring of
  //    2r + slab xy-filtered slices (cropped x and y), one SSIM sum per output row, and scratch
  //    rows per thread. Slabs keep the barriers few (two per slab: threads that lose their core
  //    on a busy machine hold the others up once per slab, not once per slice) and the memory
  //    bounded (about kSlabBytes, whatever the volume's depth).
  const std::size_t x_plane = to_size(ny * cx), xy_plane = to_size(cy * cx);
  const std::size_t slice_bytes = kMoments * sizeof(double) * (x_plane + xy_plane);
  const std::int64_t slab = std::clamp<std::int64_t>(
      static_cast<std::int64_t>(kSlabBytes / slice_bytes), 1, std::min<std::int64_t>(kMaxSlab, nz));
  const std::int64_t ring_slots = 2 * r[2] + slab;
  std::vector<double> x_filtered(to_size(slab) * kMoments * x_plane);
  std::vector<double> ring(to_size(ring_slots) * kMoments * xy_plane);
  std::vector<double> row_sums(to_size(cz * cy));
  int max_threads = 1;
#ifdef _OPENMP
  max_threads = omp_get_max_threads();
#endif
  const std::size_t row_stride = to_size(std::max(nx, cx));
  const std::size_t scratch_per_thread = kMoments * row_stride;
  std::vector<double> scratch(to_size(max_threads) * scratch_per_thread);
  const bool parallel = dims.voxels() >= 32768;
  // Rows per scheduling chunk: about 4096 output values, so chunks are cheap to hand out and
  // a thread that stalls delays at most one chunk.
  const std::int64_t chunk = std::max<std::int64_t>(1, 4096 / cx);

#pragma omp parallel if (parallel)
  {
    int thread = 0;
#ifdef _OPENMP
    thread = omp_get_thread_num();
#endif
    double* const rows = scratch.data() + to_size(thread) * scratch_per_thread;

    for (std::int64_t s0 = 0; s0 < nz; s0 += slab) {
      const std::int64_t s1 = std::min(nz, s0 + slab);

      // 4. x pass of input slices [s0, s1): the five moments of each row, filtered along x.
#pragma omp for schedule(dynamic, chunk)
      for (std::int64_t task = 0; task < (s1 - s0) * ny; ++task) {
        const std::int64_t s = s0 + task / ny, j = task % ny;
        const float* a = original.data() + to_size((s * ny + j) * nx);
        const float* b = decoded.data() + to_size((s * ny + j) * nx);
        double* ma = rows;
        double* mb = rows + row_stride;
        double* maa = rows + 2 * row_stride;
        double* mbb = rows + 3 * row_stride;
        double* mab = rows + 4 * row_stride;
        for (std::int64_t i = 0; i < nx; ++i) {
          const double va = static_cast<double>(a[i]), vb = static_cast<double>(b[i]);
          ma[i] = va;
          mb[i] = vb;
          maa[i] = va * va;
          mbb[i] = vb * vb;
          mab[i] = va * vb;
        }
        double* out = x_filtered.data() + to_size((s - s0) * kMoments) * x_plane + to_size(j * cx);
        for (int m = 0; m < kMoments; ++m) {
          correlate_row(out + to_size(m) * x_plane, rows + to_size(m) * row_stride, cx, wx, 1);
        }
      }  // implicit barrier: the x-filtered slab is complete

      // 5. y pass of the slab into ring slots s mod (2r + slab).
#pragma omp for schedule(dynamic, chunk)
      for (std::int64_t task = 0; task < (s1 - s0) * cy; ++task) {
        const std::int64_t s = s0 + task / cy, j = task % cy;
        const double* in =
            x_filtered.data() + to_size((s - s0) * kMoments) * x_plane + to_size(j * cx);
        double* out =
            ring.data() + to_size((s % ring_slots) * kMoments) * xy_plane + to_size(j * cx);
        for (int m = 0; m < kMoments; ++m) {
          correlate_row(out + to_size(m) * xy_plane, in + to_size(m) * x_plane, cx, wy, cx);
        }
      }  // implicit barrier: slots of [s0, s1) are complete

      // 6. z pass and SSIM map of every output slice k whose inputs k..k + 2r are now in the
      //    ring, summed per row. No barrier needed after it: the next step 4 writes only
      //    x_filtered, and ring slots are overwritten only after step 4's barrier.
      const std::int64_t k0 = std::max<std::int64_t>(0, s0 - 2 * r[2]), k1 = s1 - 2 * r[2];
      if (k1 <= k0) continue;
#pragma omp for schedule(dynamic, chunk) nowait
      for (std::int64_t task = 0; task < (k1 - k0) * cy; ++task) {
        const std::int64_t k = k0 + task / cy, j = task % cy;
        for (int m = 0; m < kMoments; ++m) {
          double* __restrict out = rows + to_size(m) * row_stride;
          for (std::int64_t t = 0; t < 2 * r[2] + 1; ++t) {
            const double w = wz[to_size(t)];
            const double* __restrict src =
                ring.data() + to_size(((k + t) % ring_slots) * kMoments + m) * xy_plane +
                to_size(j * cx);
            if (t == 0) {
              for (std::int64_t i = 0; i < cx; ++i) out[i] = w * src[i];
            } else {
              for (std::int64_t i = 0; i < cx; ++i) out[i] += w * src[i];
            }
          }
        }
        const double* ux = rows;
        const double* uy = rows + row_stride;
        const double* uxx = rows + 2 * row_stride;
        const double* uyy = rows + 3 * row_stride;
        const double* uxy = rows + 4 * row_stride;
        double sum = 0;
        for (std::int64_t i = 0; i < cx; ++i) {
          const double vx = uxx[i] - ux[i] * ux[i];
          const double vy = uyy[i] - uy[i] * uy[i];
          const double vxy = uxy[i] - ux[i] * uy[i];
          const double a1 = 2 * ux[i] * uy[i] + c1, a2 = 2 * vxy + c2;
          const double b1 = ux[i] * ux[i] + uy[i] * uy[i] + c1, b2 = vx + vy + c2;
          sum += (a1 * a2) / (b1 * b2);
        }
        row_sums[to_size(k * cy + j)] = sum;
      }
    }
  }

  // 7. Mean over the cropped region, rows added in a fixed order (independent of thread count).
  double total = 0;
  for (double row_sum : row_sums) total += row_sum;
  return total / (static_cast<double>(cx) * static_cast<double>(cy) * static_cast<double>(cz));
}

}  // namespace volreel::psnr
