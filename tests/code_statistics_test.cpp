// code_statistics_test.cpp: `volreel bench codes`' accounting of a ksvd payload's bits and the
// empirical entropy it compares the Rice codes with.
#include <gtest/gtest.h>

#include <cmath>

#include "volreel/format/brick_decode.h"
#include "volreel/format/code_statistics.hpp"
#include "volreel/format/decoder.hpp"

namespace volreel {
namespace {

TEST(ContextCounts, EntropyIsThatOfEachContextsValues) {
  format::ContextCounts c;
  for (int i = 0; i < 4; ++i) c.add(0, 5);  // one value: no information
  EXPECT_DOUBLE_EQ(c.entropy_bits(), 0.0);
  c.add(1, 0);
  c.add(1, 1);  // two values, equally often: a bit each
  EXPECT_DOUBLE_EQ(c.entropy_bits(), 2.0);
  c.add(2, 7, 3);  // a third context with a single value adds nothing
  EXPECT_DOUBLE_EQ(c.entropy_bits(), 2.0);
  format::ContextCounts twice;
  twice.merge(c);
  twice.merge(c);  // the same frequencies, twice the values
  EXPECT_DOUBLE_EQ(twice.entropy_bits(), 4.0);
  format::ContextCounts pooled;  // the values of contexts 0 and 1 in one context
  for (int i = 0; i < 4; ++i) pooled.add(0, 5);
  pooled.add(0, 0);
  pooled.add(0, 1);
  EXPECT_NEAR(pooled.entropy_bits(), -4 * std::log2(4.0 / 6) - 2 * std::log2(1.0 / 6), 1e-12);
}

/// A 12³ brick (8 blocks) whose codes are known: block 0 three neighbouring atoms, block 1 two far
/// apart, block 2 thirty atoms of the highest band, one of them far larger than the rest, the
/// other blocks none.
format::KsvdPayloadParts known_parts() {
  format::KsvdPayloadParts p;
  p.sparsity.assign(8, 0);
  p.mean.assign(8, 0);
  p.dequantization[0] = 0.5f;
  p.dequantization[1] = 0.01f;
  p.dequantization[2] = 0.001f;
  p.mean_bits = 4;
  p.sparsity_bits = 5;
  p.coef_bits = 16;
  p.atom_bits = 8;
  p.sparsity[0] = 3;
  p.sparsity[1] = 2;
  p.sparsity[2] = 30;
  p.atoms = {0, 1, 2, 5, 40};
  p.values = {1, -1, 1, 3, -100};
  for (std::uint32_t i = 0; i < 30; ++i) {
    p.atoms.push_back(100 + i);
    p.values.push_back(i == 7 ? 60000 : 1);
  }
  return p;
}

TEST(CodeStatistics, SplitsTheCodeBitsIntoGapsMagnitudesAndSigns) {
  format::KsvdPayloadParts parts = known_parts();
  parts.run_limit = 0;  // every gap a Rice code of its own
  const std::vector<std::byte> payload = format::pack_ksvd_payload(parts);
  const format::BrickShape shape{12};
  const format::KsvdPayloadLayout layout =
      format::check_ksvd_payload(payload, 216, shape, "known", 0);
  format::CodeStatistics s;
  s.add(payload, 216, shape, "known", 0);
  EXPECT_EQ(s.bricks, 1u);
  EXPECT_EQ(s.blocks, 8u);
  EXPECT_EQ(s.codes, 35u);
  EXPECT_EQ(s.payload_bits, 8 * payload.size());
  EXPECT_EQ(s.header_bits, 32u * VR_HEADER_WORDS);
  // 8 entries of 9 bits: 72 bits, 3 words.
  EXPECT_EQ(s.entry_bits, 96u);
  EXPECT_EQ(s.code_bits, layout.code_bits);
  EXPECT_EQ(s.gap_bits + s.magnitude_bits + s.sign_bits, layout.code_bits);
  EXPECT_EQ(s.sign_bits, 35u);
  // The packer gives the highest band's magnitudes (29 of them 0) Rice parameter 0, so 59,999 is
  // stored as an escape; and the gaps parameter 0 too (32 of the 35 gaps are 0), so block 2's
  // first gap, 100, is the other escape.
  const format::KsvdPayloadParts stored = format::unpack_ksvd_payload(payload, 216, shape, "", 0);
  ASSERT_EQ(stored.band_rice[7], 0);
  ASSERT_EQ(vr_gap_rice(layout.word, 30), 0u);
  EXPECT_EQ(s.escapes, 2u);
  EXPECT_EQ(s.header_bits + s.entry_bits + (s.code_bits + 31) / 32 * 32, s.payload_bits);
  // One brick's Rice codes are one prefix code per context: never fewer bits than the entropy.
  EXPECT_LE(s.gaps.entropy_bits(), static_cast<double>(s.gap_bits));
  EXPECT_LE(s.magnitudes.entropy_bits(), static_cast<double>(s.magnitude_bits));
  EXPECT_GT(s.magnitudes.entropy_bits(), 0.0);

  format::CodeStatistics merged;
  merged.merge(s);
  merged.merge(s);
  EXPECT_EQ(merged.codes, 70u);
  EXPECT_EQ(merged.escapes, 4u);
  EXPECT_DOUBLE_EQ(merged.gaps.entropy_bits(), 2 * s.gaps.entropy_bits());

  // The packer's own choice codes the runs of consecutive atoms (0, 1, 2 and 100..129) by their
  // lengths: the gaps take fewer bits, and the parts still add up to the stream.
  const std::vector<std::byte> with_runs = format::pack_ksvd_payload(known_parts());
  const format::KsvdPayloadLayout runs_layout =
      format::check_ksvd_payload(with_runs, 216, shape, "runs", 0);
  ASSERT_GT(vr_box_run_limit(runs_layout.box_word), 0u);
  format::CodeStatistics r;
  r.add(with_runs, 216, shape, "runs", 0);
  EXPECT_EQ(r.gap_bits + r.magnitude_bits + r.sign_bits, runs_layout.code_bits);
  EXPECT_LT(r.gap_bits, s.gap_bits);
  EXPECT_EQ(r.magnitude_bits, s.magnitude_bits);
  EXPECT_EQ(format::unpack_ksvd_payload(with_runs, 216, shape, "", 0).atoms, parts.atoms);
}

TEST(CodeStatistics, ADamagedPayloadIsAnErrorNamingIt) {
  std::vector<std::byte> payload = format::pack_ksvd_payload(known_parts());
  payload.resize(payload.size() - 4);
  format::CodeStatistics s;
  try {
    s.add(payload, 216, format::BrickShape{12}, "frames/000001.vrf", 1000);
    FAIL() << "a truncated payload was counted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("frames/000001.vrf"), std::string::npos) << e.what();
  }
  EXPECT_EQ(s.bricks, 0u);
}

}  // namespace
}  // namespace volreel
