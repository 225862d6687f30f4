// metrics.hpp: error metrics between an original and a reconstructed volume, sequence or image.
//
// Definitions (docs/design.md, "Metrics"):
//   PSNR      = 10·log10((max − min)² / MSE), max/min of the ORIGINAL (the MTV-Player paper's);
//   PSNR(zfp) = 20·log10((max − min) / (2·RMSE)), what zfp and TTHRESH print: 6.02 dB lower;
//   SSIM      = Wang et al. 2004 with a Gaussian window (σ = 1.5, truncated at 3.5σ: 11 taps),
//               constants K1 = 0.01, K2 = 0.03, population covariances, mirror ('reflect')
//               boundaries, mean over the voxels at least the window radius from every border —
//               scikit-image's structural_similarity(gaussian_weights=True) in 1, 2 or 3 D.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "volreel/datasets/volume.hpp"
#include "volreel/image/image.hpp"

namespace volreel::psnr {

struct ErrorStats {
  std::size_t count = 0;  ///< values compared
  double original_min = 0, original_max = 0;
  double mse = 0, rmse = 0, max_abs_error = 0;
  double psnr = 0;      ///< MTV definition, dB; +inf when MSE = 0, −inf when range = 0 < MSE
  double psnr_zfp = 0;  ///< zfp's definition, dB
  double range() const { return original_max - original_min; }
};

/// Accumulates squared errors over any number of frames; the range is that of all originals seen.
/// An accumulator with nothing added reports count 0, MSE 0 and PSNR +inf.
class ErrorAccumulator {
 public:
  /// original and decoded must have equal size; non-finite values throw InputError.
  void add(std::span<const float> original, std::span<const float> decoded);
  ErrorStats result() const;

 private:
  std::size_t count_ = 0;
  double sum_squared_ = 0, max_abs_ = 0;
  double min_ = 0, max_ = 0;
};

ErrorStats compare(std::span<const float> original, std::span<const float> decoded);
/// The same errors with PSNR rated against another value range [min, max] (a frame against its
/// sequence's, as encode's --psnr and a container's value range do).
ErrorStats against_range(ErrorStats stats, double min, double max);

struct SsimOptions {
  double sigma = 1.5;
  double truncate = 3.5;  ///< window radius = int(truncate·sigma + 0.5)
  double k1 = 0.01, k2 = 0.03;
  double data_range = 0;  ///< L in C1 = (K1·L)²; 0 means max − min of the original (1 if 0)
};

/// Why SSIM cannot be computed on arrays of shape dims: "axis x has 7 voxels, fewer than the
/// 11-voxel window" where an axis of extent > 1 is shorter than the window; empty where it can.
std::string ssim_unfit(Dims dims, const SsimOptions& options = {});

/// SSIM of two arrays of shape dims (x fastest). Axes of extent 1 are neither filtered nor
/// cropped, so a Dims{w, h, 1} is a 2D image. Throws InputError if an axis of extent > 1 is
/// shorter than the window, if a size does not match dims or a value is not finite.
/// Computed in double; the result does not depend on the thread count. OpenMP-parallel.
double ssim(Dims dims, std::span<const float> original, std::span<const float> decoded,
            const SsimOptions& options = {});

struct ImageComparison {
  double psnr = 0;  ///< 10·log10(255² / MSE) over the colour channels (8-bit data range)
  double ssim = 0;  ///< grayscale SSIM of each colour channel with data range 255, averaged
  double mse = 0;
  int colour_channels = 0;  ///< those compared: an alpha channel (of 2 or 4) is left out
};
/// Images must have equal width, height and channels (InputError otherwise).
ImageComparison compare_images(const image::Image& original, const image::Image& decoded);

}  // namespace volreel::psnr
