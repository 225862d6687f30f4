// fuzz_frame.cpp: a frame file — its index (header, levels, nodes, offsets, brick CRCs) and every
// brick through the CPU decoder. The index CRC is recomputed first when the header's offsets allow,
// so that mutations reach the checks behind it; every outcome is a FormatError or a valid frame.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/frame_file.hpp"

using namespace volreel::format;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const DictionaryFile dictionary = dct_dictionary(6, "fuzz");
  static const AtomTable atoms = atom_table(dictionary.atoms, dictionary.atom_count);
  std::vector<std::byte> bytes(size);
  if (size > 0) std::memcpy(bytes.data(), data, size);
  if (size >= sizeof(FrameHeader)) {
    FrameHeader h;
    std::memcpy(&h, bytes.data(), sizeof h);
    if (h.level_table_offset <= h.payload_offset && h.payload_offset <= size) {
      const std::uint32_t crc = crc32c(std::span<const std::byte>(bytes).subspan(
          h.level_table_offset, h.payload_offset - h.level_table_offset));
      std::memcpy(bytes.data() + offsetof(FrameHeader, index_crc), &crc, 4);
    }
  }
  try {
    const FrameView view(bytes, "fuzz.vrf");
    std::vector<float> brick(view.shape().voxels());
    for (std::uint32_t b = 0; b < view.brick_count(); ++b) {
      try {  // unchecked bytes first (past the brick CRC), then the checked path
        decode_payload(view.brick_bytes(b), view.codec(), view.header().codec_parameter, atoms,
                       view.shape(), brick, view.name(), view.brick_offset(b));
      } catch (const FormatError&) {
      }
    }
    for (std::uint32_t l = 0; l < view.level_count(); ++l) {
      const LevelEntry& e = view.level(l);
      if (std::uint64_t{e.dims[0]} * e.dims[1] * e.dims[2] > (std::uint64_t{1} << 22)) break;
      decode_level(view, l, atoms);
    }
    view.check_payload_crc();
  } catch (const FormatError&) {
  }
  // The index alone, as a remote reader holds it: the same checks with the file's size given.
  if (size >= sizeof(FrameHeader)) {
    FrameHeader h;
    std::memcpy(&h, bytes.data(), sizeof h);
    if (h.payload_offset <= size) {
      try {
        const FrameView index(std::span<const std::byte>(bytes).first(h.payload_offset), "fuzz.vrf",
                              size);
        for (std::uint32_t b = 0; b < index.brick_count(); ++b)
          if (index.brick_offset(b) + index.brick_payload_bytes(b) > size) std::abort();
        if (index.brick_count() > 0 && !index.has_payloads()) index.brick_bytes(0);
      } catch (const FormatError&) {
      }
    }
  }
  return 0;
}
