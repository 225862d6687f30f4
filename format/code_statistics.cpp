// code_statistics.cpp: see code_statistics.hpp.
#include "volreel/format/code_statistics.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>

#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"

namespace volreel::format {

void ContextCounts::add(std::uint32_t context, std::uint32_t value, std::uint64_t count) {
  counts_[(std::uint64_t{context} << 32) | value] += count;
  totals_[context] += count;
}

void ContextCounts::merge(const ContextCounts& other) {
  for (const auto& [key, n] : other.counts_)
    add(static_cast<std::uint32_t>(key >> 32), static_cast<std::uint32_t>(key), n);
}

double ContextCounts::entropy_bits() const {
  double bits = 0;
  for (const auto& [key, n] : counts_) {
    const double total = static_cast<double>(totals_.at(static_cast<std::uint32_t>(key >> 32)));
    bits -= static_cast<double>(n) * std::log2(static_cast<double>(n) / total);
  }
  return bits;
}

void CodeStatistics::add(std::span<const std::byte> payload, std::uint32_t atom_count,
                         BrickShape shape, const std::filesystem::path& name, std::uint64_t at) {
  // The parts, after check_ksvd_payload's checks; then the header words they came from.
  const KsvdPayloadParts parts = unpack_ksvd_payload(payload, atom_count, shape, name, at);
  vr_uint words[VR_HEADER_WORDS];
  std::memcpy(words, payload.data(), sizeof words);
  const vr_uint layout_word = words[3], band_word = words[4], box_word = words[5];
  const vr_uint n = shape.blocks_per_axis(), entries = vr_box_entries(box_word);
  bricks += 1;
  blocks += entries;
  payload_bits += 8 * std::uint64_t{payload.size()};
  header_bits += 32 * std::uint64_t{VR_HEADER_WORDS};
  entry_bits += 32 * std::uint64_t{vr_code_first_word(layout_word, entries) - VR_HEADER_WORDS};
  std::size_t k = 0;
  for (vr_uint b = 0; b < shape.blocks(); ++b) {
    if (!vr_block_in_box(box_word, n, b)) continue;
    const vr_uint s = parts.sparsity[b];
    const vr_uint gap_rice = s > 0 ? vr_gap_rice(layout_word, s) : 0;
    const vr_uint block_band_word = vr_block_band_word(band_word, box_word, s);
    const std::uint32_t s_class = vr_highest_bit(s + 1);
    // Before the block's first code: the atom before the first it may name (−1 without the flag);
    // the gaps' context counts from there.
    const std::uint32_t first_atom = vr_block_first_atom(layout_word, box_word);
    std::uint32_t previous = first_atom - 1u;
    BlockGaps block_gaps(parts.atoms.data() + k, s, first_atom, vr_box_run_limit(box_word));
    for (vr_uint i = 0; i < s; ++i, ++k) {
      const std::uint32_t atom = parts.atoms[k];
      const std::uint32_t gap = atom - previous - 1;
      const std::uint32_t magnitude = static_cast<std::uint32_t>(std::abs(parts.values[k])) - 1;
      const vr_uint magnitude_rice = vr_band_rice(layout_word, block_band_word, atom);
      // The gap's codes: a run length, a Rice value, both or neither (in a run).
      const BlockGaps::Codes gap_codes = block_gaps.next();
      std::uint64_t gap_length = 0;
      if (gap_codes.run >= 0) {
        const auto run = static_cast<std::uint32_t>(gap_codes.run);
        gap_length += rice_bits(run, vr_box_run_rice(box_word), VR_MAX_SPARSITY_BITS);
        escapes += (run >> vr_box_run_rice(box_word)) >= VR_ESCAPE_ZEROS;
      }
      if (gap_codes.gap >= 0) {
        const auto value = static_cast<std::uint32_t>(gap_codes.gap);
        gap_length += rice_bits(value, gap_rice, parts.atom_bits);
        escapes += (value >> gap_rice) >= VR_ESCAPE_ZEROS;
      }
      const std::uint64_t magnitude_length = rice_bits(magnitude, magnitude_rice, parts.coef_bits);
      gap_bits += gap_length;
      magnitude_bits += magnitude_length;
      sign_bits += 1;
      code_bits += gap_length + magnitude_length + 1;  // the code stream is nothing else
      escapes += (magnitude >> magnitude_rice) >= VR_ESCAPE_ZEROS;
      gaps.add((s_class << 8) | vr_highest_bit(previous - first_atom + 2), gap);
      magnitudes.add((vr_atom_band(layout_word, atom) << 8) | s_class, magnitude);
      previous = atom;
    }
  }
  codes += k;
}

void CodeStatistics::merge(const CodeStatistics& o) {
  bricks += o.bricks;
  blocks += o.blocks;
  codes += o.codes;
  payload_bits += o.payload_bits;
  header_bits += o.header_bits;
  entry_bits += o.entry_bits;
  code_bits += o.code_bits;
  gap_bits += o.gap_bits;
  magnitude_bits += o.magnitude_bits;
  sign_bits += o.sign_bits;
  escapes += o.escapes;
  gaps.merge(o.gaps);
  magnitudes.merge(o.magnitudes);
}

}  // namespace volreel::format
