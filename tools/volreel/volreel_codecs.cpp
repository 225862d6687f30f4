// volreel_codecs.cpp: volreel's own codecs as FrameCodecs for `bench rd`: each frame is encoded
// into a frame file in memory (exactly the bytes `volreel encode` writes) and decoded with the
// CPU reference decoder at full resolution. The dictionary file counts once (shared_bytes).
#include "volreel_codecs.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>

#include "volreel/encoder/encoder.hpp"
#include "volreel/format/decoder.hpp"

namespace volreel::cli {

namespace {

class VolreelCodec : public psnr::FrameCodec {
 public:
  VolreelCodec(std::shared_ptr<const dictionary::Dictionary> dictionary,
               std::size_t dictionary_bytes, encoder::CodingSettings settings, std::string family,
               std::string setting)
      : dictionary_(std::move(dictionary)),
        dictionary_bytes_(dictionary_bytes),
        encoder_(dictionary_.get(), settings),
        family_(std::move(family)),
        setting_(std::move(setting)) {}
  std::string family() const override { return family_; }
  std::string setting() const override { return setting_; }
  void compress(Dims dims, std::span<const float> frame,
                std::vector<std::uint8_t>& stream) override {
    volume_.dims = dims;
    volume_.data.assign(frame.begin(), frame.end());
    const std::vector<std::byte> bytes = encoder_.encode(frames_++, volume_);
    stream.resize(bytes.size());
    std::memcpy(stream.data(), bytes.data(), bytes.size());
  }
  void decompress(Dims, std::span<const std::uint8_t> stream, std::span<float> out) override {
    const format::FrameView view(std::as_bytes(stream), "<bench>");
    format::decode_level(view, view.level_count() - 1, encoder_.atoms(), out);
  }
  std::size_t shared_bytes() const override { return dictionary_bytes_; }

 private:
  std::shared_ptr<const dictionary::Dictionary> dictionary_;
  std::size_t dictionary_bytes_;
  encoder::FrameEncoder encoder_;
  std::string family_, setting_;
  Volume volume_;
  std::size_t frames_ = 0;
};

std::string setting_text(const char* format, double v) {
  char text[48];
  std::snprintf(text, sizeof text, format, v);
  return text;
}

}  // namespace

std::vector<std::unique_ptr<psnr::FrameCodec>> make_volreel_sweep(
    std::shared_ptr<const dictionary::Dictionary> dictionary, std::size_t dictionary_bytes,
    double value_min, double value_max, const VolreelSweep& sweep) {
  std::vector<std::unique_ptr<psnr::FrameCodec>> codecs;
  const double range = value_max - value_min;
  encoder::CodingSettings base;
  base.value_min = value_min;
  base.value_max = value_max;
  base.selection = sweep.selection;
  base.level_tolerance_factor = sweep.level_tolerance_factor;
  base.level_detail_ratio = sweep.level_detail_ratio;
  base.coef_step_factor = sweep.coef_step_factor;
  base.brick_size = sweep.brick_size;
  for (double relative : sweep.relative_tolerances) {
    for (double factor : sweep.lagrangian_factors) {
      auto s = base;
      s.tolerance = range * relative;
      s.rule = encoder::VariableRateRule::lagrangian;
      s.lagrangian_factor = factor;
      // Several k: one curve (family) per k, so the plot and the equal-bps table never mix them.
      std::string family = "volreel variable-rate";
      if (sweep.lagrangian_factors.size() > 1) family += setting_text(" k=%g", factor);
      codecs.push_back(std::make_unique<VolreelCodec>(dictionary, dictionary_bytes, s, family,
                                                      setting_text("eps=%.2e", s.tolerance)));
    }
    if (sweep.tolerance_rule) {
      auto s = base;
      s.tolerance = range * relative;
      s.rule = encoder::VariableRateRule::tolerance;
      codecs.push_back(std::make_unique<VolreelCodec>(dictionary, dictionary_bytes, s,
                                                      "volreel variable-rate eps-rule",
                                                      setting_text("eps=%.2e", s.tolerance)));
    }
  }
  for (int sparsity : sweep.fixed_sparsities) {
    auto s = base;
    s.fixed_sparsity = sparsity;
    codecs.push_back(std::make_unique<VolreelCodec>(
        dictionary, dictionary_bytes, s, "volreel fixed-rate", "S=" + std::to_string(sparsity)));
  }
  for (double relative : sweep.zfp_relative_accuracies) {
    auto s = base;
    s.codec = format::Codec::zfp;
    s.zfp_accuracy = range * relative;
    codecs.push_back(std::make_unique<VolreelCodec>(nullptr, 0, s, "volreel zfp-bricks",
                                                    setting_text("tol=%.2e", s.zfp_accuracy)));
  }
  return codecs;
}

}  // namespace volreel::cli
