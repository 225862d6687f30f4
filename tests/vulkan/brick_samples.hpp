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

/// A ksvd payload. `style` picks the pattern: 0 random widths (mean bits 0..15, sparsity bits
/// 0..6, magnitude bits 1..16, atom bits from K up to 16), sparsities, codes and means; 1 every
/// block at sparsity 63; 2 every block at sparsity 0; 3 extreme fields (atoms 0 and K−1,
/// magnitudes 1 and 2^16, 15-bit means 0 and 32767, sparsities up to 255 in 8-bit fields,
/// escaped gaps and values); 4 like 0 with negative scales. Values of both signs, most small
/// (the entropy coder's common case), some at the largest magnitude (escapes). Styles 0 and 4:
/// half of the payloads code a random box of blocks (1..n on each axis; brick_decode.h,
/// vr_box_word), the others every block; style 3 codes all but the last layer of blocks in z.
/// Styles 0 and 4 take a random magnitude model 0..9, style 3 model 1; a third of styles 0 and 4
/// set the split flag (atoms from the band split on). Half of styles 0 and 4 name atoms mostly one
/// after another (runs, brick_decode.h's vr_read_gap) under a random run limit and parameter;
/// style 3 names mostly consecutive atoms in its blocks of 255 codes, under the largest limit and
/// parameter 0 (escaped run lengths).
inline std::vector<std::byte> random_ksvd_payload(SplitMix64& rng, std::uint32_t atom_count,
                                                  int style, format::BrickShape shape = {}) {
  const auto sign = [&] { return rng.below(2) ? 1.0f : -1.0f; };
  format::KsvdPayloadParts parts;
  parts.sparsity.assign(shape.blocks(), 0);
  parts.mean.assign(shape.blocks(), 0);
  parts.dequantization[0] = static_cast<float>(rng.uniform(-2, 2));
  parts.dequantization[1] = sign() * static_cast<float>(rng.uniform(1e-4, 1e-3));
  parts.dequantization[2] = sign() * static_cast<float>(rng.uniform(0.005, 0.03));
  if (style == 4) {
    parts.dequantization[1] = -std::abs(parts.dequantization[1]);
    parts.dequantization[2] = -std::abs(parts.dequantization[2]);
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
  parts.band_split = static_cast<std::uint32_t>(rng.below(atom_count + 1));
  // Styles 0 and 4: a third of the payloads name atoms from the band split on (the split flag).
  parts.from_split =
      (style == 0 || style == 4) && parts.band_split < atom_count && rng.below(3) == 0;
  const std::uint32_t first_atom = parts.from_split ? parts.band_split : 0;
  const std::uint32_t named = atom_count - first_atom;  // the atoms the codes may name
  const std::uint32_t most = std::min((1u << parts.sparsity_bits) - 1u, named);
  const std::int64_t largest = std::int64_t{1} << parts.coef_bits;
  const std::uint32_t n = shape.blocks_per_axis();
  if ((style == 0 || style == 4) && rng.below(2) == 1)
    for (std::uint32_t& a : parts.box) a = 1 + static_cast<std::uint32_t>(rng.below(n));
  if (style == 3) parts.box = {n, n, n - 1};
  const vr_uint box =
      vr_make_box(parts.box[0] == 0 ? n : parts.box[0], parts.box[1] == 0 ? n : parts.box[1],
                  parts.box[2] == 0 ? n : parts.box[2]);
  std::vector<std::uint32_t> order(atom_count);
  const bool runs = (style == 0 || style == 4) && rng.below(2) == 0;
  if (runs) {
    parts.run_limit = static_cast<int>(rng.below(VR_MAX_RUN_LIMIT + 1));
    parts.run_rice = static_cast<int>(rng.below(VR_MAX_RUN_RICE + 1));
  }
  if (style == 3) parts.run_limit = VR_MAX_RUN_LIMIT, parts.run_rice = 0;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b) {
    if (!vr_block_in_box(box, n, b)) continue;  // no entry, no codes
    std::uint32_t s = static_cast<std::uint32_t>(rng.below(std::uint64_t{std::min(most, 40u)} + 1));
    std::uint32_t mean = static_cast<std::uint32_t>(rng.below(std::uint64_t{1} << parts.mean_bits));
    if (style == 1) s = std::min(63u, atom_count);
    if (style == 2) s = 0;
    if (style == 3) {
      s = std::min(b % 20 == 0 ? 255 : 1 + b % 15, atom_count);
      mean = b % 2 ? (1u << VR_MEAN_BITS) - 1u : 0u;
    }
    parts.sparsity[b] = s;
    parts.mean[b] = mean;
    // s distinct atoms in increasing order: a partial shuffle, sorted (style 3: the first and the
    // last atom among them).
    s = std::min(s, named);
    for (std::uint32_t k = 0; k < named; ++k) order[k] = first_atom + k;
    for (std::uint32_t k = 0; k < s; ++k) std::swap(order[k], order[k + rng.below(named - k)]);
    std::sort(order.begin(), order.begin() + s);
    if (style == 3 && s >= 2) order[0] = 0, order[s - 1] = atom_count - 1;
    if (runs || (style == 3 && b % 20 == 0)) {
      // Mostly consecutive atoms from a random start, a few left out.
      std::uint32_t spare = named - s;
      std::uint32_t atom = first_atom + static_cast<std::uint32_t>(rng.below(spare / 4 + 1));
      spare -= atom - first_atom;
      for (std::uint32_t k = 0; k < s; ++k) {
        order[k] = atom;
        const std::uint32_t skip =
            rng.below(4) == 0 ? std::min(spare, static_cast<std::uint32_t>(rng.below(3))) : 0;
        atom += 1 + skip;
        spare -= skip;
      }
    }
    for (std::uint32_t k = 0; k < s; ++k) {
      std::int64_t value =
          rng.below(8) == 0
              ? largest
              : 1 + static_cast<std::int64_t>(
                        rng.below(static_cast<std::uint64_t>(std::min<std::int64_t>(largest, 8))));
      if (style == 3) value = (b + k) % 3 == 0 ? 1 : largest;
      parts.atoms.push_back(order[k]);
      parts.values.push_back(static_cast<std::int32_t>(rng.below(2) ? value : -value));
    }
  }
  // Every magnitude model (brick_decode.h, vr_magnitude_move), not only the fewest bits' choice.
  if (style == 0 || style == 4)
    parts.magnitude_model = static_cast<int>(rng.below(VR_MAX_MAGNITUDE_MODEL + 1));
  if (style == 3) parts.magnitude_model = 1;  // blocks of 255 codes move by +2, of 1 by +1
  return format::pack_ksvd_payload(parts);
}

/// A 4-byte constant payload.
inline std::vector<std::byte> constant_payload(float value) {
  std::vector<std::byte> payload(4);
  std::memcpy(payload.data(), &value, 4);
  return payload;
}

}  // namespace volreel::test
