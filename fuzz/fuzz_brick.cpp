// fuzz_brick.cpp: one brick payload through the CPU reference decoder (check_ksvd_payload, then the
// decode) against the DCT basis, and as a zfp stream, as a brick of 36³ and of 12³ (the payload's
// entries depend on the brick size). Every outcome is a FormatError or finite values.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"

using namespace volreel::format;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const DictionaryFile dictionary = dct_dictionary(6, "fuzz");
  static const AtomTable atoms = atom_table(dictionary.atoms, dictionary.atom_count);
  if (size > (std::size_t{1} << 20)) return 0;
  std::vector<std::byte> bytes(size);
  if (size > 0) std::memcpy(bytes.data(), data, size);
  for (const BrickShape shape : {BrickShape{36}, BrickShape{12}}) {
    std::vector<float> out(shape.voxels());
    for (const Codec codec : {Codec::ksvd, Codec::zfp}) {
      try {
        decode_payload(bytes, codec, 1e-3, atoms, shape, out, "fuzz.vrf", 0);
        for (float v : out)
          if (!std::isfinite(v)) std::abort();  // a payload that passed decodes to finite values
      } catch (const FormatError&) {
      }
    }
  }
  return 0;
}
