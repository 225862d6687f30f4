// fuzz_brick.cpp: one brick payload through the CPU reference decoder (check_ksvd_payload, then the
// decode) against the DCT basis, and as a zfp stream, as a brick of 36³ and of 12³ (the payload's
// entries depend on the brick size). Every outcome is a FormatError or finite values. As a ksvd
// payload it is also decoded beside a valid one with the codes of both read in step
// (decode_payloads), before it and after it: the same values bit for bit, or the same error.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"

using namespace volreel::format;

namespace {

const AtomTable& atoms() {
  static const DictionaryFile dictionary = dct_dictionary(6, "fuzz");
  static const AtomTable table = atom_table(dictionary.atoms, dictionary.atom_count);
  return table;
}

/// A valid payload of a brick of `shape`: every block coded, 0..6 codes each of the DCT basis.
std::vector<std::byte> valid_payload(BrickShape shape) {
  KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 0);
  p.mean.assign(shape.blocks(), 0);
  p.dequantization[0] = 0.5f;
  p.dequantization[1] = 0.01f;
  p.dequantization[2] = 0.001f;
  p.mean_bits = 4;
  p.sparsity_bits = 3;
  p.coef_bits = 6;
  p.atom_bits = 8;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b) {
    p.sparsity[b] = b % 7;
    p.mean[b] = b % 16;
    for (std::uint32_t k = 0; k < p.sparsity[b]; ++k) {
      p.atoms.push_back(30 * k + b % 30);
      p.values.push_back(k % 2 ? static_cast<int>(b % 64) + 1 : -static_cast<int>(k) - 1);
    }
  }
  return pack_ksvd_payload(p);
}

/// The payload decoded beside a valid one, before and after it, against decode_payload's
/// outcome (`alone`: its values, or `error` its error).
void in_step(const std::vector<std::byte>& bytes, BrickShape shape, const std::vector<float>& alone,
             const std::string& error) {
  const std::vector<std::byte> valid = valid_payload(shape);
  std::vector<float> valid_alone(shape.voxels());
  decode_payload(valid, Codec::ksvd, 0, atoms(), shape, valid_alone, "valid", 0);
  for (int order = 0; order < 2; ++order) {
    std::vector<float> out(shape.voxels()), other(shape.voxels());
    const PayloadJob fuzzed{bytes, out, "fuzz.vrf", 0};
    const PayloadJob good{valid, other, "valid", 0};
    const PayloadJob jobs[2] = {order == 0 ? fuzzed : good, order == 0 ? good : fuzzed};
    std::string found;
    try {
      decode_payloads(jobs, Codec::ksvd, atoms(), shape);
    } catch (const FormatError& e) {
      found = e.what();
    }
    if (found != error) std::abort();
    if (error.empty() && (std::memcmp(out.data(), alone.data(), 4 * out.size()) != 0 ||
                          std::memcmp(other.data(), valid_alone.data(), 4 * out.size()) != 0))
      std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size > (std::size_t{1} << 20)) return 0;
  std::vector<std::byte> bytes(size);
  if (size > 0) std::memcpy(bytes.data(), data, size);
  for (const BrickShape shape : {BrickShape{36}, BrickShape{12}}) {
    std::vector<float> out(shape.voxels());
    for (const Codec codec : {Codec::ksvd, Codec::zfp}) {
      std::string error;
      try {
        decode_payload(bytes, codec, 1e-3, atoms(), shape, out, "fuzz.vrf", 0);
        for (float v : out)
          if (!std::isfinite(v)) std::abort();  // a payload that passed decodes to finite values
      } catch (const FormatError& e) {
        error = e.what();
      }
      if (codec == Codec::ksvd) in_step(bytes, shape, out, error);
    }
  }
  return 0;
}
