// zfp_codec.cpp: libzfp as a FrameCodec, in fixed-accuracy and fixed-rate modes — the
// reference codec volreel is measured against.
#include <zfp.h>

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "volreel/psnr/rate_distortion.hpp"

namespace volreel::psnr {

namespace {

/// Owns the zfp objects of one call.
struct ZfpSession {
  zfp_field* field = nullptr;
  zfp_stream* zfp = nullptr;
  bitstream* bits = nullptr;
  ~ZfpSession() {
    if (bits) stream_close(bits);
    if (zfp) zfp_stream_close(zfp);
    if (field) zfp_field_free(field);
  }
};

class ZfpCodec final : public FrameCodec {
 public:
  enum class Mode { accuracy, rate };
  ZfpCodec(Mode mode, double parameter) : mode_(mode), parameter_(parameter) {}

  std::string family() const override { return mode_ == Mode::accuracy ? "zfp fixed-accuracy" : "zfp fixed-rate"; }
  std::string setting() const override {
    char text[48];
    if (mode_ == Mode::accuracy)
      std::snprintf(text, sizeof text, "tol=%.3g", parameter_);
    else
      std::snprintf(text, sizeof text, "rate=%g", parameter_);
    return text;
  }

  void compress(Dims dims, std::span<const float> frame, std::vector<std::uint8_t>& stream) override {
    ZfpSession s;
    s.field = zfp_field_3d(const_cast<float*>(frame.data()), zfp_type_float, static_cast<std::size_t>(dims.x),
                           static_cast<std::size_t>(dims.y), static_cast<std::size_t>(dims.z));
    s.zfp = zfp_stream_open(nullptr);
    configure(s.zfp);
    stream.resize(zfp_stream_maximum_size(s.zfp, s.field));
    s.bits = stream_open(stream.data(), stream.size());
    zfp_stream_set_bit_stream(s.zfp, s.bits);
    const std::size_t size = zfp_compress(s.zfp, s.field);
    if (size == 0) throw std::runtime_error("zfp_compress failed (" + setting() + ")");
    stream.resize(size);
  }

  void decompress(Dims dims, std::span<const std::uint8_t> stream, std::span<float> out) override {
    ZfpSession s;
    s.field = zfp_field_3d(out.data(), zfp_type_float, static_cast<std::size_t>(dims.x), static_cast<std::size_t>(dims.y),
                           static_cast<std::size_t>(dims.z));
    s.zfp = zfp_stream_open(nullptr);
    configure(s.zfp);
    s.bits = stream_open(const_cast<std::uint8_t*>(stream.data()), stream.size());
    zfp_stream_set_bit_stream(s.zfp, s.bits);
    if (zfp_decompress(s.zfp, s.field) == 0) throw std::runtime_error("zfp_decompress failed (" + setting() + ")");
  }

 private:
  void configure(zfp_stream* zfp) const {
    if (mode_ == Mode::accuracy)
      zfp_stream_set_accuracy(zfp, parameter_);
    else
      zfp_stream_set_rate(zfp, parameter_, zfp_type_float, 3, zfp_false);
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
