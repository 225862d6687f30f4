// image.hpp: 8-bit images and their PNG files — what the renderers produce, the player's
// screenshots and the image metrics (volreel::psnr) all use.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace volreel::image {

/// An 8-bit image: channels 1 (gray), 2 (gray+alpha), 3 (RGB) or 4 (RGBA), rows top to bottom.
struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<std::uint8_t> pixels;  ///< width·height·channels, interleaved
};

/// Throws InputError, its text starting with `what`, unless the size is positive, channels is 1
/// to 4 and pixels holds width·height·channels bytes.
void validate_image(const Image& image, const std::string& what);

/// Read a PNG of any bit depth/colour type, converted to 8 bits per channel (palette → RGB,
/// 16-bit → 8-bit). Throws InputError naming the file on any failure.
Image read_png(const std::filesystem::path& path);

/// Write an 8-bit PNG, to a temporary name renamed when complete. Throws InputError for an
/// invalid image, std::runtime_error naming the file on I/O failure.
void write_png(const std::filesystem::path& path, const Image& image);

}  // namespace volreel::image
