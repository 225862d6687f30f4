// coding_settings.cpp: the names of the variable-rate rules and codecs.
#include "volreel/encoder/coding_settings.hpp"

namespace volreel::encoder {

const char* rate_rule_name(VariableRateRule rule) {
  return rule == VariableRateRule::lagrangian ? "lagrangian" : "tolerance";
}

const char* codec_name(format::Codec codec) {
  return codec == format::Codec::ksvd ? "ksvd" : "zfp";
}

}  // namespace volreel::encoder
