// crc32c.hpp: CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), the checksum of every volreel
// file. Check value: crc32c("123456789") == 0xE3069283.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace volreel::format {

/// CRC-32C of bytes, continuing from a previous result `crc` (0 to start), so that
/// crc32c(b, crc32c(a)) == crc32c(a followed by b). Software slice-by-8, about 1-2 GB/s.
std::uint32_t crc32c(std::span<const std::byte> bytes, std::uint32_t crc = 0) noexcept;

}  // namespace volreel::format
