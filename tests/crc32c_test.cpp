// crc32c_test.cpp: CRC-32C against the standard check value, the iSCSI test vectors (RFC 3720
// B.4) and a bitwise reference on every length and alignment.
#include <gtest/gtest.h>

#include <cstring>
#include <string_view>
#include <vector>

#include "volreel/datasets/prng.hpp"
#include "volreel/format/crc32c.hpp"

namespace {

using volreel::format::crc32c;

std::uint32_t crc_of(const std::vector<std::uint8_t>& bytes) {
  return crc32c(std::as_bytes(std::span(bytes.data(), bytes.size())));
}

/// One bit at a time, straight from the definition (reflected polynomial 0x82F63B78).
std::uint32_t bitwise_crc32c(const std::uint8_t* p, std::size_t n) {
  std::uint32_t c = 0xFFFFFFFFu;
  for (std::size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int bit = 0; bit < 8; ++bit) c = (c & 1u) ? (c >> 1) ^ 0x82F63B78u : c >> 1;
  }
  return ~c;
}

TEST(Crc32c, CheckValue) {
  constexpr std::string_view text = "123456789";
  EXPECT_EQ(crc32c(std::as_bytes(std::span(text.data(), text.size()))), 0xE3069283u);
  EXPECT_EQ(crc32c({}), 0u);
}

TEST(Crc32c, IscsiVectors) {
  std::vector<std::uint8_t> zeros(32, 0x00), ones(32, 0xFF), up(32), down(32);
  for (std::uint8_t i = 0; i < 32; ++i) {
    up[i] = i;
    down[i] = static_cast<std::uint8_t>(31 - i);
  }
  EXPECT_EQ(crc_of(zeros), 0x8A9136AAu);
  EXPECT_EQ(crc_of(ones), 0x62A8AB43u);
  EXPECT_EQ(crc_of(up), 0x46DD794Eu);
  EXPECT_EQ(crc_of(down), 0x113FDB5Cu);
}

TEST(Crc32c, MatchesBitwiseOnEveryLengthAndAlignment) {
  volreel::SplitMix64 rng(3);
  std::vector<std::uint8_t> data(300);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng.next());
  for (std::size_t offset = 0; offset < 8; ++offset)
    for (std::size_t n = 0; n + offset <= data.size(); n += (n < 40 ? 1 : 13)) {
      const auto bytes = std::as_bytes(std::span(data.data() + offset, n));
      ASSERT_EQ(crc32c(bytes), bitwise_crc32c(data.data() + offset, n))
          << "offset " << offset << " length " << n;
    }
}

TEST(Crc32c, ContinuesAcrossPieces) {
  volreel::SplitMix64 rng(4);
  std::vector<std::uint8_t> data(1000);
  for (auto& b : data) b = static_cast<std::uint8_t>(rng.next());
  const auto all = std::as_bytes(std::span(data.data(), data.size()));
  for (std::size_t split : {0u, 1u, 7u, 8u, 9u, 500u, 999u, 1000u})
    EXPECT_EQ(crc32c(all.subspan(split), crc32c(all.first(split))), crc32c(all))
        << "split at " << split;
}

}  // namespace
