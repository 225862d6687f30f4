// code_statistics.hpp: where the bits of ksvd brick payloads go (headers, block entries, the
// code stream's atom gaps, magnitudes and signs), and the fewest bits that a coder using the
// same information as context could spend on the gaps and magnitudes: the empirical conditional
// entropy, a bound for any static code over those contexts (its tables not counted), which
// Rice codes (format/SPEC.md, "The codes") approach only where the values are near geometric.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <unordered_map>

#include "volreel/format/frame_file.hpp"

namespace volreel::format {

/// Counts of values per context, and their empirical conditional entropy.
class ContextCounts {
 public:
  void add(std::uint32_t context, std::uint32_t value, std::uint64_t count = 1);
  void merge(const ContextCounts& other);
  /// Σ over contexts and values of −n·log2(n / N_context): the bits of the values under the
  /// best static code per context.
  double entropy_bits() const;

 private:
  std::unordered_map<std::uint64_t, std::uint64_t> counts_;  ///< context << 32 | value → n
  std::unordered_map<std::uint32_t, std::uint64_t> totals_;  ///< context → N_context
};

/// Statistics of the ksvd payloads added (constant bricks and zfp streams are not counted).
struct CodeStatistics {
  std::uint64_t bricks = 0;  ///< ksvd payloads
  std::uint64_t blocks = 0;  ///< coded blocks (inside the payloads' boxes)
  std::uint64_t codes = 0;
  std::uint64_t payload_bits = 0;    ///< all of the payloads
  std::uint64_t header_bits = 0;     ///< the header words
  std::uint64_t entry_bits = 0;      ///< block entries, with their padding to a word
  std::uint64_t code_bits = 0;       ///< the code streams, without their padding
  std::uint64_t gap_bits = 0;        ///< of code_bits: the atom gaps' and runs' Rice codes
  std::uint64_t magnitude_bits = 0;  ///< of code_bits: the magnitudes' Rice codes
  std::uint64_t sign_bits = 0;       ///< of code_bits: one a code
  std::uint64_t escapes = 0;         ///< Rice codes stored as escapes (runs, gaps and magnitudes)
  /// Gaps in the context (floor(log2(s + 1)), floor(log2(previous atom + 2))): how many codes the
  /// block has and where in the dictionary the gap starts (s is in the block's entry; the
  /// previous atom is −1 before a block's first code).
  ContextCounts gaps;
  /// Magnitudes |q| − 1 in the context (atom band, floor(log2(s + 1))).
  ContextCounts magnitudes;

  /// Adds a ksvd payload (check_ksvd_payload's checks; FormatError naming `name` and `at`).
  void add(std::span<const std::byte> payload, std::uint32_t atom_count, BrickShape shape,
           const std::filesystem::path& name, std::uint64_t at);
  void merge(const CodeStatistics& other);
};

}  // namespace volreel::format
