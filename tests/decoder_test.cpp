// decoder_test.cpp: the CPU reference decoder's sum of a block's codes, atom by atom for learned
// atoms and as a separable transform for the DCT basis, against the sum in double precision.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>

#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"

namespace volreel {
namespace {

/// `learned` random unit-norm atoms followed by the DCT basis, as a container stores them.
format::DictionaryFile learned_and_dct(std::uint32_t learned, std::uint32_t seed) {
  format::DictionaryFile d;
  d.block_size = VR_BLOCK_SIZE;
  d.atom_count = learned;
  d.program_version = "test";
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal;
  d.atoms.resize(std::size_t{learned} * VR_BLOCK_LENGTH);
  for (std::uint32_t a = 0; a < learned; ++a) {
    float* atom = d.atoms.data() + std::size_t{a} * VR_BLOCK_LENGTH;
    double norm = 0;
    for (vr_uint v = 0; v < VR_BLOCK_LENGTH; ++v) {
      atom[v] = normal(rng);
      norm += double{atom[v]} * double{atom[v]};
    }
    for (vr_uint v = 0; v < VR_BLOCK_LENGTH; ++v)
      atom[v] = static_cast<float>(double{atom[v]} / std::sqrt(norm));
  }
  return format::with_dct_atoms(std::move(d));
}

/// A 12³ brick (8 blocks): block 0 learned atoms only, block 1 a single DCT atom, block 2 the DCT
/// atoms of one z frequency (w = 2) only, block 3 no code, blocks 4..7 random atoms of both kinds
/// (up to 120 of the 235), with coefficients up to ±1000 steps.
format::KsvdPayloadParts mixed_parts(std::uint32_t learned, std::uint32_t seed) {
  const std::uint32_t count = learned + format::dct_basis_atoms;
  format::KsvdPayloadParts p;
  p.sparsity.assign(8, 0);
  p.mean.assign(8, 0);
  p.dequantization[0] = -3.0f;
  p.dequantization[1] = 0.002f;
  p.dequantization[2] = 0.0137f;
  p.mean_bits = 12;
  p.sparsity_bits = 8;
  p.coef_bits = 10;
  p.atom_bits = format::bits_for_count(count);
  p.band_split = learned;
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> value(-1000, 1000);
  std::uniform_int_distribution<std::uint32_t> mean(0, 4095);
  const auto frequencies = format::block_dct_frequencies(VR_BLOCK_SIZE);
  for (std::uint32_t b = 0; b < 8; ++b) {
    std::vector<std::uint32_t> atoms;
    if (b == 0) {
      for (std::uint32_t a = 0; a < learned; a += 2) atoms.push_back(a);
    } else if (b == 1) {
      atoms.push_back(learned + 100);
    } else if (b == 2) {
      for (std::uint32_t j = 0; j < format::dct_basis_atoms; ++j)
        if (frequencies[j][2] == 2) atoms.push_back(learned + j);
    } else if (b >= 4) {
      std::vector<std::uint32_t> all(count);
      std::iota(all.begin(), all.end(), 0u);
      std::shuffle(all.begin(), all.end(), rng);
      atoms.assign(all.begin(), all.begin() + 30 * (b - 3));
      std::sort(atoms.begin(), atoms.end());
    }
    p.sparsity[b] = static_cast<std::uint32_t>(atoms.size());
    p.mean[b] = mean(rng);
    for (std::uint32_t a : atoms) {
      int q = value(rng);
      p.atoms.push_back(a);
      p.values.push_back(q == 0 ? 1 : q);
    }
  }
  return p;
}

TEST(Decoder, TheDctBasisSumsAsASeparableTransform) {
  for (const std::uint32_t learned : {0u, 20u}) {
    const format::DictionaryFile d = learned_and_dct(learned, 3 + learned);
    const format::KsvdPayloadParts parts = mixed_parts(learned, 7 + learned);
    const std::vector<std::byte> payload = format::pack_ksvd_payload(parts);
    const format::BrickShape shape{12};
    const format::AtomTable separable = format::atom_table(d.atoms, d.atom_count);
    ASSERT_TRUE(separable.dct_basis);
    format::AtomTable atom_by_atom = separable;
    atom_by_atom.dct_basis = false;
    std::vector<float> fast(shape.voxels()), dense(shape.voxels());
    format::decode_payload(payload, format::Codec::ksvd, 0, separable, shape, fast, "mixed", 0);
    format::decode_payload(payload, format::Codec::ksvd, 0, atom_by_atom, shape, dense, "mixed", 0);
    // Every value against the sum in double, relative to the sum of its terms' magnitudes. Blocks
    // with fewer than 16 codes of the basis are summed atom by atom either way, to the same bits;
    // the others take the separable sum, which rounds differently somewhere.
    std::size_t code = 0;
    for (std::uint32_t b = 0; b < 8; ++b) {
      const std::uint32_t s = parts.sparsity[b];
      std::uint32_t basis_codes = 0;
      for (std::uint32_t k = 0; k < s; ++k) basis_codes += parts.atoms[code + k] >= learned;
      bool same_bits = true;
      const double mean = double{parts.dequantization[0]} +
                          double{parts.dequantization[1]} * static_cast<double>(parts.mean[b]);
      double scale = 1 + std::abs(mean);
      for (std::uint32_t k = 0; k < s; ++k)
        scale += std::abs(double{parts.dequantization[2]} * parts.values[code + k]);
      for (vr_uint v = 0; v < VR_BLOCK_LENGTH; ++v) {
        double want = mean;
        for (std::uint32_t k = 0; k < s; ++k)
          want += double{parts.dequantization[2]} * parts.values[code + k] *
                  double{d.atoms[std::size_t{parts.atoms[code + k]} * VR_BLOCK_LENGTH + v]};
        const std::size_t at = vr_brick_voxel(2, b, v);
        const double error = std::abs(double{fast[at]} - want) / scale;
        same_bits = same_bits && std::memcmp(&fast[at], &dense[at], sizeof(float)) == 0;
        ASSERT_LT(error, 2e-6) << "learned " << learned << ", block " << b << ", value " << v
                               << ": " << fast[at] << " for " << want;
        ASSERT_LT(std::abs(double{dense[at]} - want) / scale, 2e-6);
      }
      EXPECT_EQ(same_bits, basis_codes < 16) << "learned " << learned << ", block " << b << ": "
                                             << basis_codes << " codes of the basis";
      code += s;
    }
  }
}

TEST(Decoder, AtomTableFindsTheDctBasisBitForBit) {
  const format::DictionaryFile dct = format::dct_dictionary(VR_BLOCK_SIZE, "test");
  EXPECT_TRUE(format::atom_table(dct.atoms, dct.atom_count).dct_basis);
  format::DictionaryFile d = learned_and_dct(16, 1);
  EXPECT_TRUE(format::atom_table(d.atoms, d.atom_count).dct_basis);
  // Fewer atoms than the basis, a table too short for its count, or one value of the basis
  // changed by a unit in the last place: summed atom by atom.
  EXPECT_FALSE(format::atom_table(std::span(d.atoms).first(16 * VR_BLOCK_LENGTH), 16).dct_basis);
  EXPECT_FALSE(
      format::atom_table(std::span(d.atoms).first(d.atoms.size() - 1), d.atom_count).dct_basis);
  d.atoms[d.atoms.size() - 5] = std::nextafter(d.atoms[d.atoms.size() - 5], 2.0f);
  EXPECT_FALSE(format::atom_table(d.atoms, d.atom_count).dct_basis);
}

}  // namespace
}  // namespace volreel
