// frame_edit.hpp: deliberate edits of frame files for tests of what readers refuse.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::test {

/// Recomputes every brick CRC, the index CRC and the file CRC after a deliberate edit, so that
/// what a reader reports is the edited field, not a checksum.
inline void reseal_frame(std::vector<std::byte>& bytes) {
  format::FrameHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  for (std::uint32_t b = 0; b < h.brick_count; ++b) {
    std::uint64_t begin, end;
    std::memcpy(&begin, bytes.data() + h.brick_offsets_offset + 8 * b, 8);
    std::memcpy(&end, bytes.data() + h.brick_offsets_offset + 8 * (b + 1), 8);
    const std::uint32_t crc = format::crc32c(
        std::span<const std::byte>(bytes).subspan(h.payload_offset + begin, end - begin));
    std::memcpy(bytes.data() + h.brick_crcs_offset + 4 * b, &crc, 4);
  }
  const std::uint32_t index = format::crc32c(std::span<const std::byte>(bytes).subspan(
      h.level_table_offset, h.payload_offset - h.level_table_offset));
  std::memcpy(bytes.data() + offsetof(format::FrameHeader, index_crc), &index, 4);
  const std::uint32_t file =
      format::crc32c(std::span<const std::byte>(bytes).first(bytes.size() - 4));
  std::memcpy(bytes.data() + bytes.size() - 4, &file, 4);
}

}  // namespace volreel::test
