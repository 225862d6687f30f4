// image_metrics.cpp: the PSNR and SSIM of two 8-bit images, defined as scikit-image's
// peak_signal_noise_ratio(data_range=255) and structural_similarity(channel_axis=2,
// gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=255).
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "volreel/psnr/metrics.hpp"

namespace volreel::psnr {

ImageComparison compare_images(const image::Image& original, const image::Image& decoded) {
  image::validate_image(original, "original image");
  image::validate_image(decoded, "decoded image");
  if (original.width != decoded.width || original.height != decoded.height ||
      original.channels != decoded.channels) {
    throw InputError("compare images: original is " + std::to_string(original.width) + "x" +
                     std::to_string(original.height) + "x" + std::to_string(original.channels) +
                     " (width x height x channels) but decoded is " +
                     std::to_string(decoded.width) + "x" + std::to_string(decoded.height) + "x" +
                     std::to_string(decoded.channels));
  }
  // The colour channels: gray, gray + alpha, RGB or RGBA; the alpha channel (how a PNG writer
  // composites, not the picture) is left out.
  const auto channels = static_cast<std::size_t>(original.channels);
  const std::size_t colour = channels == 2 || channels == 4 ? channels - 1 : channels;
  // 1. MSE over every colour channel of every pixel (exact: integer sum of squares).
  std::uint64_t sum_squared = 0;
  for (std::size_t i = 0; i < original.pixels.size(); ++i) {
    if (i % channels >= colour) continue;
    const int d = int{original.pixels[i]} - int{decoded.pixels[i]};
    sum_squared += static_cast<std::uint64_t>(d * d);
  }
  ImageComparison result;
  result.colour_channels = static_cast<int>(colour);
  result.mse = static_cast<double>(sum_squared) /
               static_cast<double>(original.pixels.size() / channels * colour);
  result.psnr = result.mse == 0 ? std::numeric_limits<double>::infinity()
                                : 10.0 * std::log10(255.0 * 255.0 / result.mse);

  // 2. SSIM of each channel as a 2D array with data range 255, averaged over channels.
  const Dims dims{original.width, original.height, 1};
  std::vector<float> a(dims.voxels()), b(dims.voxels());
  SsimOptions options;
  options.data_range = 255;
  double ssim_sum = 0;
  for (std::size_t c = 0; c < colour; ++c) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      a[i] = original.pixels[i * channels + c];
      b[i] = decoded.pixels[i * channels + c];
    }
    ssim_sum += ssim(dims, a, b, options);
  }
  result.ssim = ssim_sum / static_cast<double>(colour);
  return result;
}

}  // namespace volreel::psnr
