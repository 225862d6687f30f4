// metrics_test.cpp: unit tests of volreel::psnr's error metrics — PSNR/RMSE of known errors, the
// frame accumulator, SSIM against a brute-force direct-window reference, PNG input and output.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <ostream>
#include <string>
#include <vector>

#include "volreel/datasets/prng.hpp"
#include "volreel/psnr/metrics.hpp"

namespace {

using volreel::Dims;
using volreel::InputError;
using volreel::SplitMix64;
namespace psnr = volreel::psnr;
namespace image = volreel::image;

constexpr double kInf = std::numeric_limits<double>::infinity();

std::vector<float> uniform_values(std::size_t n, std::uint64_t seed, double lo, double hi) {
  SplitMix64 rng(seed);
  std::vector<float> values(n);
  for (float& v : values) v = static_cast<float>(rng.uniform(lo, hi));
  return values;
}

/// A smooth field with some texture on the grid dims, so that SSIM has structure to compare.
std::vector<float> smooth_field(Dims dims, std::uint64_t seed) {
  SplitMix64 rng(seed);
  std::vector<float> values(dims.voxels());
  for (std::int64_t k = 0; k < dims.z; ++k)
    for (std::int64_t j = 0; j < dims.y; ++j)
      for (std::int64_t i = 0; i < dims.x; ++i) {
        const double x = static_cast<double>(i), y = static_cast<double>(j),
                     z = static_cast<double>(k);
        values[dims.index(i, j, k)] = static_cast<float>(
            std::sin(0.3 * x) + std::cos(0.2 * y + 0.1 * z) + 0.05 * z + 0.2 * rng.uniform());
      }
  return values;
}

std::vector<float> add_noise(std::vector<float> values, double amplitude, std::uint64_t seed) {
  SplitMix64 rng(seed);
  for (float& v : values) v += static_cast<float>(amplitude * (2 * rng.uniform() - 1));
  return values;
}

// ---------------------------------------------------------------------------------------------
// PSNR, RMSE, maximum error

TEST(ErrorMetrics, ConstantOffsetGivesExactMse) {
  // Multiples of 1/1024 in [0, 10], so adding 0.5 is exact in float32; range is exactly 10.
  SplitMix64 rng(1);
  std::vector<float> original(10000), decoded(10000);
  for (float& v : original) v = static_cast<float>(rng.below(10241)) / 1024.0f;
  original[0] = 0.0f;
  original[1] = 10.0f;
  for (std::size_t i = 0; i < original.size(); ++i)
    decoded[i] = original[i] + (i % 2 ? 0.5f : -0.5f);

  const psnr::ErrorStats stats = psnr::compare(original, decoded);
  EXPECT_EQ(stats.count, 10000u);
  EXPECT_EQ(stats.original_min, 0.0);
  EXPECT_EQ(stats.original_max, 10.0);
  EXPECT_EQ(stats.range(), 10.0);
  EXPECT_DOUBLE_EQ(stats.mse, 0.25);
  EXPECT_DOUBLE_EQ(stats.rmse, 0.5);
  EXPECT_EQ(stats.max_abs_error, 0.5);
  EXPECT_NEAR(stats.psnr, 10.0 * std::log10(100.0 / 0.25), 1e-12);
  EXPECT_NEAR(stats.psnr_zfp, 20.0, 1e-12);  // 20·log10(10 / (2·0.5))
  EXPECT_NEAR(stats.psnr - stats.psnr_zfp, 20.0 * std::log10(2.0), 1e-12);
}

TEST(ErrorMetrics, ZfpDefinitionIsSixDecibelsBelow) {
  const std::vector<float> original = uniform_values(5000, 2, -3.0, 7.0);
  const std::vector<float> decoded = add_noise(original, 0.01, 3);
  const psnr::ErrorStats stats = psnr::compare(original, decoded);
  EXPECT_NEAR(stats.psnr - stats.psnr_zfp, 20.0 * std::log10(2.0), 1e-10);
  EXPECT_NEAR(stats.psnr, 10.0 * std::log10(stats.range() * stats.range() / stats.mse), 1e-12);
  EXPECT_NEAR(stats.rmse * stats.rmse, stats.mse, 1e-15);
  EXPECT_LE(stats.max_abs_error, 0.01 + 1e-6);
  EXPECT_GT(stats.max_abs_error, 0.009);
}

TEST(ErrorMetrics, AccumulatorOverFramesEqualsOneCompareOfTheConcatenation) {
  // Frames of different sizes and ranges; the sizes straddle the internal block size.
  const std::size_t sizes[] = {1000, 70000, 4096, 12345};
  std::vector<float> all_original, all_decoded;
  psnr::ErrorAccumulator accumulator;
  std::uint64_t seed = 10;
  double lo = -1, hi = 1;
  for (std::size_t n : sizes) {
    const std::vector<float> original = uniform_values(n, seed++, lo, hi);
    const std::vector<float> decoded = add_noise(original, 0.001 * hi, seed++);
    accumulator.add(original, decoded);
    all_original.insert(all_original.end(), original.begin(), original.end());
    all_decoded.insert(all_decoded.end(), decoded.begin(), decoded.end());
    lo *= 2;
    hi *= 3;
  }
  const psnr::ErrorStats frames = accumulator.result();
  const psnr::ErrorStats whole = psnr::compare(all_original, all_decoded);
  EXPECT_EQ(frames.count, whole.count);
  EXPECT_EQ(frames.original_min, whole.original_min);
  EXPECT_EQ(frames.original_max, whole.original_max);
  EXPECT_EQ(frames.max_abs_error, whole.max_abs_error);
  EXPECT_NEAR(frames.mse, whole.mse, 1e-12 * whole.mse);
  EXPECT_NEAR(frames.psnr, whole.psnr, 1e-10);
  EXPECT_NEAR(frames.psnr_zfp, whole.psnr_zfp, 1e-10);
}

TEST(ErrorMetrics, IdenticalArraysGiveInfinitePsnr) {
  const std::vector<float> values = uniform_values(3000, 4, 0, 1);
  const psnr::ErrorStats stats = psnr::compare(values, values);
  EXPECT_EQ(stats.mse, 0.0);
  EXPECT_EQ(stats.max_abs_error, 0.0);
  EXPECT_EQ(stats.psnr, kInf);
  EXPECT_EQ(stats.psnr_zfp, kInf);
}

TEST(ErrorMetrics, ConstantOriginal) {
  const std::vector<float> constant(100, 3.0f);
  std::vector<float> changed = constant;
  changed[7] = 4.0f;
  EXPECT_EQ(psnr::compare(constant, constant).psnr, kInf);  // no error: +inf whatever the range
  const psnr::ErrorStats stats = psnr::compare(constant, changed);
  EXPECT_EQ(stats.range(), 0.0);
  EXPECT_DOUBLE_EQ(stats.mse, 0.01);
  EXPECT_EQ(stats.psnr, -kInf);  // no signal but some error
  EXPECT_EQ(stats.psnr_zfp, -kInf);
}

TEST(ErrorMetrics, EmptyAccumulatorHasNoError) {
  const psnr::ErrorStats stats = psnr::ErrorAccumulator{}.result();
  EXPECT_EQ(stats.count, 0u);
  EXPECT_EQ(stats.mse, 0.0);
  EXPECT_EQ(stats.psnr, kInf);
}

TEST(ErrorMetrics, RejectsBadInput) {
  const std::vector<float> values = uniform_values(100, 5, 0, 1);
  EXPECT_THROW(psnr::compare(values, std::span<const float>(values).first(99)), InputError);
  for (float bad :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::vector<float> broken = values;
    broken[42] = bad;
    EXPECT_THROW(psnr::compare(broken, values), InputError);
    EXPECT_THROW(psnr::compare(values, broken), InputError);
    try {
      psnr::compare(values, broken);
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find("decoded value at index 42"), std::string::npos)
          << error.what();
    }
  }
}

// ---------------------------------------------------------------------------------------------
// SSIM

/// scipy.ndimage's 'reflect' boundary (d c b a | a b c d | d c b a) for any offset.
std::int64_t reflect(std::int64_t i, std::int64_t n) {
  const std::int64_t period = 2 * n;
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - 1 - i;
}

/// Brute-force SSIM: every voxel's five moments from a direct (2r+1)³ weighted window with
/// reflected indices, the whole SSIM map, then the mean over the region cropped by r on every
/// axis of extent > 1. Slow and obvious, independent of ssim.cpp's separable ring buffer.
double reference_ssim(Dims dims, const std::vector<float>& a, const std::vector<float>& b,
                      const psnr::SsimOptions& options) {
  const auto radius = static_cast<std::int64_t>(options.truncate * options.sigma + 0.5);
  std::vector<double> taps;
  double tap_sum = 0;
  for (std::int64_t t = -radius; t <= radius; ++t) {
    taps.push_back(std::exp(-0.5 * static_cast<double>(t * t) / (options.sigma * options.sigma)));
    tap_sum += taps.back();
  }
  for (double& w : taps) w /= tap_sum;
  const std::int64_t rx = dims.x > 1 ? radius : 0, ry = dims.y > 1 ? radius : 0,
                     rz = dims.z > 1 ? radius : 0;
  auto tap = [&](std::int64_t offset, std::int64_t r) {
    return r == 0 ? 1.0 : taps[static_cast<std::size_t>(offset + radius)];
  };

  double lo = kInf, hi = -kInf;
  for (float v : a) {
    lo = std::min(lo, static_cast<double>(v));
    hi = std::max(hi, static_cast<double>(v));
  }
  const double range = options.data_range > 0 ? options.data_range : hi - lo;
  const double c1 = std::pow(options.k1 * range, 2), c2 = std::pow(options.k2 * range, 2);

  double sum = 0;
  std::size_t count = 0;
  for (std::int64_t k = 0; k < dims.z; ++k)
    for (std::int64_t j = 0; j < dims.y; ++j)
      for (std::int64_t i = 0; i < dims.x; ++i) {
        double ux = 0, uy = 0, uxx = 0, uyy = 0, uxy = 0;
        for (std::int64_t dz = -rz; dz <= rz; ++dz)
          for (std::int64_t dy = -ry; dy <= ry; ++dy)
            for (std::int64_t dx = -rx; dx <= rx; ++dx) {
              const double w = tap(dx, rx) * tap(dy, ry) * tap(dz, rz);
              const std::size_t n = dims.index(reflect(i + dx, dims.x), reflect(j + dy, dims.y),
                                               reflect(k + dz, dims.z));
              const double va = static_cast<double>(a[n]), vb = static_cast<double>(b[n]);
              ux += w * va;
              uy += w * vb;
              uxx += w * va * va;
              uyy += w * vb * vb;
              uxy += w * va * vb;
            }
        const double vx = uxx - ux * ux, vy = uyy - uy * uy, vxy = uxy - ux * uy;
        const double s =
            ((2 * ux * uy + c1) * (2 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
        const bool inside =
            i >= rx && i < dims.x - rx && j >= ry && j < dims.y - ry && k >= rz && k < dims.z - rz;
        if (inside) {
          sum += s;
          ++count;
        }
      }
  return sum / static_cast<double>(count);
}

struct SsimCase {
  const char* name;
  Dims dims;
  double sigma, truncate;
};

void PrintTo(const SsimCase& c, std::ostream* os) {
  *os << c.name << " " << c.dims.x << "x" << c.dims.y << "x" << c.dims.z << " sigma " << c.sigma;
}

class SsimAgainstBruteForce : public testing::TestWithParam<SsimCase> {};

TEST_P(SsimAgainstBruteForce, MatchesDirectWindow) {
  const SsimCase& c = GetParam();
  psnr::SsimOptions options;
  options.sigma = c.sigma;
  options.truncate = c.truncate;
  const std::vector<float> original = smooth_field(c.dims, 20);
  const std::vector<float> decoded = add_noise(original, 0.3, 21);
  const double fast = psnr::ssim(c.dims, original, decoded, options);
  const double slow = reference_ssim(c.dims, original, decoded, options);
  EXPECT_NEAR(fast, slow, 1e-12);
  EXPECT_LT(fast, 0.99);
  EXPECT_GT(fast, 0.0);
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, SsimAgainstBruteForce,
    testing::Values(SsimCase{"cube_default_window", {14, 12, 13}, 1.5, 3.5},
                    SsimCase{"smallest_default_window", {11, 11, 11}, 1.5, 3.5},
                    SsimCase{"several_slabs", {12, 11, 40}, 1.5, 3.5},  // ring wraps
                    SsimCase{"narrow_window", {10, 12, 9}, 1.0, 4.0},   // r = 4: 9 taps
                    SsimCase{"image", {23, 17, 1}, 1.5, 3.5},
                    SsimCase{"xz_plane", {19, 1, 15}, 1.5, 3.5},
                    SsimCase{"line", {40, 1, 1}, 1.5, 3.5},
                    SsimCase{"column", {1, 1, 30}, 1.5, 3.5}),
    [](const testing::TestParamInfo<SsimCase>& param_info) {
      return std::string(param_info.param.name);
    });

TEST(Ssim, IdenticalArraysGiveOne) {
  const Dims dims{20, 18, 16};
  const std::vector<float> values = smooth_field(dims, 30);
  EXPECT_DOUBLE_EQ(psnr::ssim(dims, values, values), 1.0);
  const std::vector<float> constant(dims.voxels(), 2.5f);  // range 0: still 1, not NaN
  EXPECT_DOUBLE_EQ(psnr::ssim(dims, constant, constant), 1.0);
}

TEST(Ssim, DecreasesWithNoise) {
  const Dims dims{32, 24, 20};
  const std::vector<float> original = smooth_field(dims, 40);
  double previous = 1.0;
  for (double amplitude : {0.01, 0.05, 0.2, 0.5, 1.0}) {
    const double value = psnr::ssim(dims, original, add_noise(original, amplitude, 41));
    EXPECT_LT(value, previous) << "noise amplitude " << amplitude;
    previous = value;
  }
}

TEST(Ssim, TwoDimensionalDataInAnyOrientation) {
  // The same w × h samples as Dims{w, h, 1}, {1, w, h} and {w, 1, h} (identical memory layout
  // in the first two), and as a one-channel image scaled to 8 bits.
  const std::int64_t w = 29, h = 21;
  std::vector<float> original = smooth_field(Dims{w, h, 1}, 50);
  for (float& v : original) v = std::round(std::clamp(60.0f * v + 128.0f, 0.0f, 255.0f));
  std::vector<float> decoded = add_noise(original, 12.0, 51);
  for (float& v : decoded) v = std::round(std::clamp(v, 0.0f, 255.0f));

  psnr::SsimOptions options;
  options.data_range = 255;
  const double xy = psnr::ssim(Dims{w, h, 1}, original, decoded, options);
  EXPECT_DOUBLE_EQ(psnr::ssim(Dims{1, w, h}, original, decoded, options), xy);
  EXPECT_DOUBLE_EQ(psnr::ssim(Dims{w, 1, h}, original, decoded, options), xy);
  EXPECT_NEAR(reference_ssim(Dims{w, h, 1}, original, decoded, options), xy, 1e-12);

  image::Image a{static_cast<int>(w), static_cast<int>(h), 1, {}}, b = a;
  for (float v : original) a.pixels.push_back(static_cast<std::uint8_t>(v));
  for (float v : decoded) b.pixels.push_back(static_cast<std::uint8_t>(v));
  EXPECT_DOUBLE_EQ(psnr::compare_images(a, b).ssim, xy);
}

TEST(Ssim, RejectsBadInput) {
  const std::vector<float> values = uniform_values(10 * 20 * 20, 60, 0, 1);
  EXPECT_THROW(psnr::ssim(Dims{10, 20, 20}, values, values), InputError);  // x shorter than 11
  EXPECT_NO_THROW(psnr::ssim(Dims{1, 20, 200}, values, values));           // x not filtered
  EXPECT_THROW(psnr::ssim(Dims{20, 20, 20}, values, values), InputError);  // wrong size
  std::vector<float> broken = values;
  broken[5] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_THROW(psnr::ssim(Dims{1, 20, 200}, values, broken), InputError);
  psnr::SsimOptions options;
  options.sigma = 0;
  EXPECT_THROW(psnr::ssim(Dims{1, 20, 200}, values, values, options), InputError);
}

// ---------------------------------------------------------------------------------------------
// Images

/// A scratch directory for one test, removed with everything in it at the end of the test.
class ImageFiles : public testing::Test {
 protected:
  void SetUp() override {
    const testing::TestInfo* info = testing::UnitTest::GetInstance()->current_test_info();
    directory_ =
        std::filesystem::temp_directory_path() /
        (std::string("volreel_metrics_test_") + info->name() + "_" +
         std::to_string(SplitMix64(reinterpret_cast<std::uintptr_t>(this)).next() % 1000000));
    std::filesystem::create_directories(directory_);
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }
  std::filesystem::path directory_;
};

image::Image random_image(int width, int height, int channels, std::uint64_t seed) {
  SplitMix64 rng(seed);
  image::Image image{width, height, channels, {}};
  image.pixels.resize(static_cast<std::size_t>(width * height * channels));
  for (auto& p : image.pixels) p = static_cast<std::uint8_t>(rng.below(256));
  return image;
}

TEST_F(ImageFiles, PngRoundTripForEveryChannelCount) {
  for (int channels = 1; channels <= 4; ++channels) {
    SCOPED_TRACE("channels " + std::to_string(channels));
    const image::Image picture =
        random_image(37, 23, channels, static_cast<std::uint64_t>(70 + channels));
    const std::filesystem::path path = directory_ / ("image" + std::to_string(channels) + ".png");
    image::write_png(path, picture);
    EXPECT_FALSE(std::filesystem::exists(path.string() + ".tmp"));
    const image::Image back = image::read_png(path);
    EXPECT_EQ(back.width, 37);
    EXPECT_EQ(back.height, 23);
    EXPECT_EQ(back.channels, channels);
    EXPECT_EQ(back.pixels, picture.pixels);
  }
}

TEST_F(ImageFiles, DamagedPngGivesInputErrorNamingTheFile) {
  const std::filesystem::path good = directory_ / "good.png";
  image::write_png(good, random_image(64, 48, 3, 80));
  std::vector<char> bytes(std::filesystem::file_size(good));
  std::ifstream(good, std::ios::binary)
      .read(bytes.data(), static_cast<std::streamsize>(bytes.size()));

  auto write_bytes = [&](const std::string& name, const std::vector<char>& content) {
    const std::filesystem::path path = directory_ / name;
    std::ofstream(path, std::ios::binary)
        .write(content.data(), static_cast<std::streamsize>(content.size()));
    return path;
  };
  auto expect_input_error = [](const std::filesystem::path& path) {
    try {
      image::read_png(path);
      ADD_FAILURE() << path << " was read without error";
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find(path.filename().string()), std::string::npos)
          << error.what();
    }
  };

  std::vector<char> truncated(bytes.begin(),
                              bytes.begin() + static_cast<std::ptrdiff_t>(bytes.size() / 2));
  expect_input_error(write_bytes("truncated.png", truncated));
  std::vector<char> header_only(bytes.begin(), bytes.begin() + 20);
  expect_input_error(write_bytes("header_only.png", header_only));
  std::vector<char> corrupt = bytes;
  for (std::size_t i = 100; i < 110; ++i)
    corrupt[i] = static_cast<char>(corrupt[i] ^ 0x5a);  // inside IDAT
  expect_input_error(write_bytes("corrupt.png", corrupt));
  expect_input_error(
      write_bytes("text.png", std::vector<char>{'n', 'o', 't', ' ', 'a', ' ', 'P', 'N', 'G'}));
  expect_input_error(directory_ / "missing.png");
}

TEST(Images, CompareKnownDifference) {
  image::Image a = random_image(40, 30, 3, 90);
  for (auto& p : a.pixels) p = static_cast<std::uint8_t>(std::min<int>(p, 254));
  image::Image b = a;
  for (auto& p : b.pixels) ++p;
  const psnr::ImageComparison same = psnr::compare_images(a, a);
  EXPECT_EQ(same.psnr, kInf);
  EXPECT_EQ(same.mse, 0.0);
  EXPECT_DOUBLE_EQ(same.ssim, 1.0);
  const psnr::ImageComparison offset = psnr::compare_images(a, b);
  EXPECT_EQ(offset.mse, 1.0);
  EXPECT_NEAR(offset.psnr, 10.0 * std::log10(255.0 * 255.0), 1e-12);
  EXPECT_LT(offset.ssim, 1.0);
  EXPECT_GT(offset.ssim, 0.99);
}

TEST(Images, AnAlphaChannelIsLeftOut) {
  // RGBA: the colour channels as the RGB image of them; the alpha (differing here) not counted.
  const image::Image rgb_a = random_image(40, 30, 3, 93), rgb_b = random_image(40, 30, 3, 94);
  const auto with_alpha = [](const image::Image& rgb, std::uint8_t alpha) {
    image::Image rgba = rgb;
    rgba.channels = 4;
    rgba.pixels.clear();
    for (std::size_t i = 0; i < rgb.pixels.size(); i += 3)
      rgba.pixels.insert(rgba.pixels.end(),
                         {rgb.pixels[i], rgb.pixels[i + 1], rgb.pixels[i + 2], alpha});
    return rgba;
  };
  const psnr::ImageComparison rgb = psnr::compare_images(rgb_a, rgb_b);
  const psnr::ImageComparison rgba =
      psnr::compare_images(with_alpha(rgb_a, 255), with_alpha(rgb_b, 0));
  EXPECT_EQ(rgba.colour_channels, 3);
  EXPECT_DOUBLE_EQ(rgba.mse, rgb.mse);
  EXPECT_DOUBLE_EQ(rgba.psnr, rgb.psnr);
  EXPECT_DOUBLE_EQ(rgba.ssim, rgb.ssim);
}

TEST(Images, MismatchedSizesGiveInputError) {
  const image::Image a = random_image(40, 30, 3, 91);
  EXPECT_THROW(psnr::compare_images(a, random_image(41, 30, 3, 92)), InputError);
  EXPECT_THROW(psnr::compare_images(a, random_image(40, 31, 3, 92)), InputError);
  EXPECT_THROW(psnr::compare_images(a, random_image(40, 30, 4, 92)), InputError);
  image::Image short_pixels = a;
  short_pixels.pixels.pop_back();
  EXPECT_THROW(psnr::compare_images(a, short_pixels), InputError);
}

}  // namespace
