// brick_samples.hpp: random but valid brick payloads for the Vulkan tests — ksvd payloads that
// cover sparsity 0..15, the smallest and largest codes and atom indices, both signs of the
// dequantization values — and a random dictionary. Our own PRNG, fixed seeds.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "volreel/datasets/prng.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"

namespace volreel::test {

/// K atoms of 216 values in [-0.2, 0.2).
inline std::vector<float> random_atoms(SplitMix64& rng, std::uint32_t count) {
  std::vector<float> atoms(std::size_t{count} * VR_BLOCK_LENGTH);
  for (float& a : atoms) a = static_cast<float>(rng.uniform(-0.2, 0.2));
  return atoms;
}

/// A ksvd payload. `style` picks the pattern: 0 random sparsities, codes and mean bits (0..12),
/// 1 every block at sparsity 15, 2 every block at sparsity 0, 3 extreme codes (atoms 0 and K−1,
/// values 0 and 63, 12-bit means 0 and 4095), 4 like 0 with negative scales.
inline std::vector<std::byte> random_ksvd_payload(SplitMix64& rng, std::uint32_t atom_count,
                                                  int style) {
  const auto sign = [&] { return rng.below(2) ? 1.0f : -1.0f; };
  format::KsvdPayloadParts parts;
  parts.dequantization[0] = static_cast<float>(rng.uniform(-2, 2));
  parts.dequantization[1] = sign() * static_cast<float>(rng.uniform(1e-4, 1e-3));
  parts.dequantization[2] = static_cast<float>(rng.uniform(-0.5, 0.5));
  parts.dequantization[3] = sign() * static_cast<float>(rng.uniform(0.005, 0.03));
  if (style == 4) {
    parts.dequantization[1] = -std::abs(parts.dequantization[1]);
    parts.dequantization[3] = -std::abs(parts.dequantization[3]);
  }
  parts.mean_bits =
      style == 3 ? VR_MEAN_BITS : static_cast<std::uint32_t>(rng.below(VR_MEAN_BITS + 1));
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
    std::uint32_t s = static_cast<std::uint32_t>(rng.below(16));
    std::uint32_t mean = static_cast<std::uint32_t>(rng.below(std::uint64_t{1} << parts.mean_bits));
    if (style == 1) s = 15;
    if (style == 2) s = 0;
    if (style == 3) {
      s = 1 + b % 15;
      mean = b % 2 ? (1u << VR_MEAN_BITS) - 1u : 0u;
    }
    parts.sparsity[b] = s;
    parts.mean[b] = mean;
    for (std::uint32_t k = 0; k < s; ++k) {
      std::uint32_t atom = static_cast<std::uint32_t>(rng.below(atom_count));
      std::uint32_t value = static_cast<std::uint32_t>(rng.below(64));
      if (style == 3) {
        atom = (b + k) % 2 ? atom_count - 1 : 0;
        value = (b + k) % 3 == 0 ? 0 : 63;
      }
      parts.codes.push_back(static_cast<std::uint16_t>((atom << 6) | value));
    }
  }
  return format::pack_ksvd_payload(parts);
}

/// A 4-byte constant payload.
inline std::vector<std::byte> constant_payload(float value) {
  std::vector<std::byte> payload(4);
  std::memcpy(payload.data(), &value, 4);
  return payload;
}

}  // namespace volreel::test
