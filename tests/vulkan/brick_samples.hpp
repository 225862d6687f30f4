// brick_samples.hpp: random but valid brick payloads for the Vulkan tests — ksvd payloads that
// cover sparsities 0..255, every field width, the smallest and largest codes and atom indices,
// both signs of the
// dequantization values — and a random dictionary. Our own PRNG, fixed seeds.
#pragma once

#include <algorithm>
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

/// A ksvd payload. `style` picks the pattern: 0 random widths (mean bits 0..12, sparsity bits
/// 0..6, coefficient bits 1..16, atom bits from K up to 16), sparsities, codes and means; 1 every
/// block at sparsity 63; 2 every block at sparsity 0; 3 extreme fields (atoms 0 and K−1, values 0
/// and 2^16 − 1, 12-bit means 0 and 4095, sparsities up to 255 in 8-bit fields, 32-bit codes);
/// 4 like 0 with negative scales.
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
  const std::uint32_t least_atom_bits =
      std::max<std::uint32_t>(1, format::bits_for_count(atom_count));
  parts.mean_bits =
      style == 3 ? VR_MEAN_BITS : static_cast<std::uint32_t>(rng.below(VR_MEAN_BITS + 1));
  parts.sparsity_bits = style == 1   ? 6
                        : style == 2 ? 0
                        : style == 3 ? VR_MAX_SPARSITY_BITS
                                     : static_cast<std::uint32_t>(rng.below(7));
  parts.coef_bits = style == 3 ? VR_MAX_COEF_BITS : 1 + static_cast<std::uint32_t>(rng.below(16));
  parts.atom_bits = style == 3 ? VR_MAX_ATOM_BITS
                               : least_atom_bits + static_cast<std::uint32_t>(rng.below(
                                                       VR_MAX_ATOM_BITS - least_atom_bits + 1));
  const std::uint32_t most = (1u << parts.sparsity_bits) - 1u;
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
    std::uint32_t s = static_cast<std::uint32_t>(rng.below(std::uint64_t{std::min(most, 40u)} + 1));
    std::uint32_t mean = static_cast<std::uint32_t>(rng.below(std::uint64_t{1} << parts.mean_bits));
    if (style == 1) s = 63;
    if (style == 2) s = 0;
    if (style == 3) {
      s = b % 20 == 0 ? 255 : 1 + b % 15;
      mean = b % 2 ? (1u << VR_MEAN_BITS) - 1u : 0u;
    }
    parts.sparsity[b] = s;
    parts.mean[b] = mean;
    for (std::uint32_t k = 0; k < s; ++k) {
      std::uint32_t atom = static_cast<std::uint32_t>(rng.below(atom_count));
      std::uint32_t value =
          static_cast<std::uint32_t>(rng.below(std::uint64_t{1} << parts.coef_bits));
      if (style == 3) {
        atom = (b + k) % 2 ? atom_count - 1 : 0;
        value = (b + k) % 3 == 0 ? 0 : (1u << parts.coef_bits) - 1u;
      }
      parts.atoms.push_back(atom);
      parts.values.push_back(value);
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
