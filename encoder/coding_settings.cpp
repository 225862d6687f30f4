// coding_settings.cpp: the names of the variable-rate rules and codecs, and the mean bits' text.
#include "volreel/encoder/coding_settings.hpp"

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

int mean_bits_from_text(const std::string& text) {
  if (text == "auto") return -1;
  char* end = nullptr;
  const long bits = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || bits < 0 || bits > 12)
    throw InputError("--mean-bits must be auto or a whole number 0..12, not '" + text + "'");
  return static_cast<int>(bits);
}

}  // namespace volreel::encoder
