// zfp_codec.cpp: libzfp as a FrameCodec, in fixed-accuracy and fixed-rate modes — the
// reference codec volreel is measured against.
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "volreel/format/zfp_stream.hpp"
#include "volreel/psnr/rate_distortion.hpp"

namespace volreel::psnr {

namespace {

class ZfpCodec final : public FrameCodec {
 public:
  enum class Mode { accuracy, rate };
  ZfpCodec(Mode mode, double parameter) : mode_(mode), parameter_(parameter) {}

  std::string family() const override {
    return mode_ == Mode::accuracy ? "zfp fixed-accuracy" : "zfp fixed-rate";
  }
  std::string setting() const override {
    char text[48];
    if (mode_ == Mode::accuracy)
      std::snprintf(text, sizeof text, "tol=%.3g", parameter_);
    else
      std::snprintf(text, sizeof text, "rate=%g", parameter_);
    return text;
  }

  void compress(Dims dims, std::span<const float> frame,
                std::vector<std::uint8_t>& stream) override {
    format::ZfpStream zfp = open(dims);
    stream.resize(zfp.maximum_size());
    const std::size_t size = zfp.compress(frame.data(), stream.data(), stream.size());
    if (size == 0) throw std::runtime_error("zfp_compress failed (" + setting() + ")");
    stream.resize(size);
  }

  void decompress(Dims dims, std::span<const std::uint8_t> stream, std::span<float> out) override {
    format::ZfpStream zfp = open(dims);
    if (zfp.decompress(stream.data(), stream.size(), out.data()) == 0)
      throw std::runtime_error("zfp_decompress failed (" + setting() + ")");
  }

 private:
  format::ZfpStream open(Dims dims) const {
    return format::ZfpStream(mode_ == Mode::accuracy ? format::ZfpMode::accuracy(parameter_)
                                                     : format::ZfpMode::rate(parameter_),
                             static_cast<std::size_t>(dims.x), static_cast<std::size_t>(dims.y),
                             static_cast<std::size_t>(dims.z));
  }

  Mode mode_;
  double parameter_;
};

}  // namespace

std::unique_ptr<FrameCodec> make_zfp_accuracy(double tolerance) {
  return std::make_unique<ZfpCodec>(ZfpCodec::Mode::accuracy, tolerance);
}

std::unique_ptr<FrameCodec> make_zfp_rate(double bits_per_value) {
  return std::make_unique<ZfpCodec>(ZfpCodec::Mode::rate, bits_per_value);
}

std::vector<std::unique_ptr<FrameCodec>> make_zfp_sweep(double value_range) {
  std::vector<std::unique_ptr<FrameCodec>> codecs;
  const double range = value_range > 0 ? value_range : 1.0;
  for (int k = -1; k <= 12; ++k) codecs.push_back(make_zfp_accuracy(range * std::ldexp(1.0, -k)));
  for (double rate : {0.125, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0}) codecs.push_back(make_zfp_rate(rate));
  return codecs;
}

}  // namespace volreel::psnr
