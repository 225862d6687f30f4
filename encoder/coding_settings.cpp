// coding_settings.cpp: the names of the variable-rate rules and codecs, and the mean bits',
// coefficient bits' and brick size's text.
#include "volreel/encoder/coding_settings.hpp"

#include "volreel/format/brick_decode.h"

#include <cstdlib>

namespace volreel::encoder {

const char* rate_rule_name(VariableRateRule rule) {
  return rule == VariableRateRule::lagrangian ? "lagrangian" : "tolerance";
}

VariableRateRule rate_rule_from_name(const std::string& name) {
  if (name == "lagrangian") return VariableRateRule::lagrangian;
  if (name == "tolerance") return VariableRateRule::tolerance;
  throw InputError("--rate-rule must be lagrangian or tolerance, not '" + name + "'");
}

const char* codec_name(format::Codec codec) {
  return codec == format::Codec::ksvd ? "ksvd" : "zfp";
}

format::Codec codec_from_name(const std::string& name) {
  if (name == "ksvd") return format::Codec::ksvd;
  if (name == "zfp") return format::Codec::zfp;
  throw InputError("--codec must be ksvd or zfp, not '" + name + "'");
}

namespace {

/// "auto" (-1) or a whole number lo..hi; throws InputError naming `option` otherwise.
int bits_from_text(const std::string& text, const char* option, long lo, long hi) {
  if (text == "auto") return -1;
  char* end = nullptr;
  const long bits = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || bits < lo || bits > hi)
    throw InputError(std::string(option) + " must be auto or a whole number " + std::to_string(lo) +
                     ".." + std::to_string(hi) + ", not '" + text + "'");
  return static_cast<int>(bits);
}

}  // namespace

int mean_bits_from_text(const std::string& text) {
  return bits_from_text(text, "--mean-bits", 0, VR_MEAN_BITS);
}

int coef_bits_from_text(const std::string& text) {
  return bits_from_text(text, "--coef-bits", 1, 16);
}

std::uint32_t brick_size_from_text(const std::string& text) {
  if (text == "auto") return 0;
  char* end = nullptr;
  const long size = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || size < 0 ||
      !format::valid_brick_size(static_cast<std::uint64_t>(size)))
    throw InputError(
        "--brick-size must be auto or a multiple of 6 in 12..66 (stored voxels per "
        "brick axis, the interior 2 fewer), not '" +
        text + "'");
  return static_cast<std::uint32_t>(size);
}

}  // namespace volreel::encoder
