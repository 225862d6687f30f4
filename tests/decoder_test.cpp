// decoder_test.cpp: the CPU reference decoder's sum of a block's codes, atom by atom for learned
// atoms and as a separable transform for the DCT basis, against the sum in double precision; two
// payloads decoded with their codes read in step (decode_payloads) against one at a time.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <numeric>
#include <random>
#include <string>
#include <vector>

#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"

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

/// A random payload of a brick of `shape` indexing `count` atoms: a random box of coded blocks,
/// 0..max_sparsity codes a block, magnitudes up to 2^c (with escapes), the coder's parameters
/// chosen by pack_ksvd_payload.
std::vector<std::byte> random_payload(format::BrickShape shape, std::uint32_t count,
                                      std::uint32_t max_sparsity, std::mt19937& rng) {
  const auto pick = [&rng](std::uint32_t k) { return static_cast<std::uint32_t>(rng() % k); };
  const std::uint32_t n = shape.blocks_per_axis();
  format::KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 0);
  p.mean.assign(shape.blocks(), 0);
  p.dequantization[0] = 1.5f;
  p.dequantization[1] = 0.01f;
  p.dequantization[2] = 0.003f;
  p.mean_bits = 9;
  p.sparsity_bits = format::bits_for_count(max_sparsity + 1);
  p.coef_bits = 1 + pick(12);
  p.atom_bits = format::bits_for_count(count);
  p.band_split = pick(3) == 0 ? 0 : count / 4;
  for (std::uint32_t a = 0; a < 3; ++a) p.box[a] = 1 + pick(n);
  p.from_split = p.band_split > 0 && pick(3) == 0;  // atoms from the split on, a third of them
  const std::uint32_t first_atom = p.from_split ? p.band_split : 0;
  std::vector<std::uint32_t> all(count - first_atom);
  std::iota(all.begin(), all.end(), first_atom);
  const int largest = 1 << p.coef_bits;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b) {
    if (b % n >= p.box[0] || b / n % n >= p.box[1] || b / (n * n) >= p.box[2]) continue;
    p.sparsity[b] = std::min<std::uint32_t>(pick(max_sparsity + 1), count - first_atom);
    p.mean[b] = pick(512);
    std::shuffle(all.begin(), all.end(), rng);
    std::vector<std::uint32_t> atoms(all.begin(), all.begin() + p.sparsity[b]);
    std::sort(atoms.begin(), atoms.end());
    // A third of the blocks name consecutive atoms from a random start, now and then one left out
    // (runs, brick_decode.h's vr_read_gap), as dense blocks of low frequencies do.
    if (pick(3) == 0 && !atoms.empty()) {
      std::uint32_t spare = count - first_atom - p.sparsity[b];
      std::uint32_t atom = first_atom + pick(spare / 2 + 1);
      spare -= atom - first_atom;
      for (std::uint32_t& a : atoms) {
        a = atom;
        const std::uint32_t skip = pick(5) == 0 ? std::min(spare, pick(3)) : 0;
        atom += 1 + skip;
        spare -= skip;
      }
    }
    for (std::uint32_t a : atoms) {
      // Mostly small magnitudes, some at the largest (escapes where the Rice parameter is small).
      const int m = pick(8) == 0 ? largest : 1 + static_cast<int>(pick(largest < 4 ? 2 : 4));
      p.atoms.push_back(a);
      p.values.push_back(pick(2) ? m : -m);
    }
  }
  p.magnitude_model = static_cast<int>(pick(VR_MAX_MAGNITUDE_MODEL + 1));  // every model
  if (pick(2) == 0) {  // any run limit and parameter, not only the packer's choice
    p.run_limit = static_cast<int>(pick(VR_MAX_RUN_LIMIT + 1));
    p.run_rice = static_cast<int>(pick(VR_MAX_RUN_RICE + 1));
  }
  return format::pack_ksvd_payload(p);
}

/// The parts of a brick of `shape` without codes: every block's sparsity and mean 0, means of 0
/// bits, the given widths and coefficient scale (the codes and sparsities to be added).
format::KsvdPayloadParts parts_without_codes(format::BrickShape shape, std::uint32_t sparsity_bits,
                                             std::uint32_t coef_bits, std::uint32_t atom_bits,
                                             float coef_scale) {
  format::KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 0);
  p.mean.assign(shape.blocks(), 0);
  p.dequantization[0] = 0.5f;
  p.dequantization[1] = 0.01f;
  p.dequantization[2] = coef_scale;
  p.mean_bits = 0;
  p.sparsity_bits = sparsity_bits;
  p.coef_bits = coef_bits;
  p.atom_bits = atom_bits;
  return p;
}

/// A payload of `shape` without codes: paired with another payload, every code of the other is
/// read after this one's end, as the longer one of a pair is read on alone.
std::vector<std::byte> payload_without_codes(format::BrickShape shape, std::uint32_t atom_count) {
  return format::pack_ksvd_payload(
      parts_without_codes(shape, 4, 4, format::bits_for_count(atom_count), 0.001f));
}

/// Packs `p`, requires the CPU decoder's reader to give its codes back, and reads them again with
/// the shared text the GPU decoders run (vr_read_code), requiring the same codes and every block's
/// runs to end with it; calls each(block, code of the block, bits the code took). Returns the bits
/// of the code stream.
std::uint64_t read_back(const format::KsvdPayloadParts& p, std::uint32_t atom_count,
                        format::BrickShape shape,
                        const std::function<void(std::uint32_t, std::uint32_t, vr_uint)>& each) {
  const std::vector<std::byte> payload = format::pack_ksvd_payload(p);
  const format::KsvdPayloadParts back =
      format::unpack_ksvd_payload(payload, atom_count, shape, "read back", 0);
  EXPECT_EQ(back.atoms, p.atoms);
  EXPECT_EQ(back.values, p.values);
  std::vector<vr_uint> words(payload.size() / 4 + 1, 0u);
  std::memcpy(words.data(), payload.data(), payload.size());
  const vr_uint layout = words[3];
  const vr_uint first = vr_code_first_word(layout, shape.blocks());
  vr_uint bit = 0;
  std::size_t code = 0;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b) {
    const vr_uint s = p.sparsity[b];
    const vr_uint band_word = vr_block_band_word(words[4], words[5], s);
    vr_uint next_atom = 0, run = 0, atom = 0;
    for (std::uint32_t k = 0; k < s; ++k, ++code) {
      const vr_uint start = bit;
      const int q = vr_read_code(words.data(), first, layout, band_word, words[5], s, bit,
                                 next_atom, run, atom);
      EXPECT_EQ(atom, p.atoms[code]) << "block " << b << ", code " << k;
      EXPECT_EQ(q, p.values[code]) << "block " << b << ", code " << k;
      each(b, k, bit - start);
    }
    EXPECT_LT(run, 2u) << "block " << b;
  }
  return bit;
}

TEST(Decoder, TheLongestCodesReadBack) {
  // Codes of 65 bits, every gap and magnitude an escape (16 zeros, then 16 bits) and a sign: a
  // code longer than a 64-bit window, at every bit alignment (65 bits move the next code's start
  // by one bit of a byte). The CPU decoder's reader and the shared text (vr_read_code) read them
  // back.
  const format::BrickShape shape{12};
  format::KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 3);
  p.mean.assign(shape.blocks(), 7);
  p.dequantization[2] = 0.001f;
  p.sparsity_bits = 2;
  p.coef_bits = 16;
  p.atom_bits = 16;
  p.gap_shift = 3;  // gap Rice parameter 16 − 1 − 2 − 3 = 10: gaps from 16·2^10 on escape
  p.band_rice.fill(0);
  p.magnitude_model = 0;  // every block keeps parameter 0: every magnitude escapes
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    for (std::uint32_t k = 0; k < 3; ++k) {
      p.atoms.push_back(20000 * (k + 1) + b);
      p.values.push_back((b + k) % 2 ? 65536 - static_cast<int>(b) : -40000 - static_cast<int>(k));
    }
  EXPECT_EQ(read_back(p, 1u << 16, shape,
                      [](std::uint32_t, std::uint32_t, vr_uint bits) { EXPECT_EQ(bits, 65u); }),
            65u * p.atoms.size());

  // Under a run limit of 1 each block's first code (position 0) takes a run length first: 0, with
  // parameter 7 (8 bits), then the escaped gap less one: 73 bits, the longest a valid code takes.
  p.run_limit = 1;
  p.run_rice = VR_MAX_RUN_RICE;
  read_back(p, 1u << 16, shape, [](std::uint32_t b, std::uint32_t k, vr_uint bits) {
    EXPECT_EQ(bits, k == 0 ? 73u : 65u) << "block " << b << ", code " << k;
  });

  // A run of 255 consecutive atoms, its length escaped (parameter 0: 16 zeros, then 255 in 8
  // bits, every bit set), in a block of 8-bit sparsities: the first code takes the 24 bits of the
  // run length, the other 254 no gap bits; magnitudes |q| − 1 of 0..3 with parameter 2 take 3
  // bits, and the sign 1.
  format::KsvdPayloadParts r = parts_without_codes(shape, 8, 4, 8, 0.001f);
  r.run_limit = VR_MAX_RUN_LIMIT;
  r.run_rice = 0;
  r.band_rice.fill(2);
  r.magnitude_model = 0;
  r.sparsity[3] = 255;
  for (std::uint32_t k = 0; k < 255; ++k) {
    r.atoms.push_back(k);
    r.values.push_back(k % 2 ? 1 + static_cast<int>(k % 4) : -2);
  }
  read_back(r, 256, shape, [](std::uint32_t, std::uint32_t k, vr_uint bits) {
    EXPECT_EQ(bits, (k == 0 ? 24u : 0u) + 3u + 1u) << "code " << k;
  });
  const std::vector<std::byte> long_run = format::pack_ksvd_payload(r);
  vr_uint layout_word = 0, first_code_word = 0;  // the code stream starts with the escape
  std::memcpy(&layout_word, long_run.data() + 12, 4);
  std::memcpy(&first_code_word,
              long_run.data() + 4 * vr_code_first_word(layout_word, shape.blocks()), 4);
  EXPECT_EQ(first_code_word & 0xFFFFFFu, 255u << 16);
}

/// decode_payload's error on one payload ("" when it decodes).
std::string alone_error(std::span<const std::byte> payload, const format::AtomTable& atoms,
                        format::BrickShape shape, std::span<float> out, const std::string& name,
                        std::uint64_t at) {
  try {
    format::decode_payload(payload, format::Codec::ksvd, 0, atoms, shape, out, name, at);
  } catch (const format::FormatError& e) {
    return e.what();
  }
  return "";
}

std::string decode_error(std::span<const format::PayloadJob> jobs, const format::AtomTable& atoms,
                         format::BrickShape shape) {
  try {
    format::decode_payloads(jobs, format::Codec::ksvd, atoms, shape);
  } catch (const format::FormatError& e) {
    return e.what();
  }
  return "";
}

TEST(Decoder, PayloadsReadInStepDecodeAsOneAtATime) {
  const format::DictionaryFile d = learned_and_dct(40, 5);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  std::mt19937 rng(11);
  for (const format::BrickShape shape : {format::BrickShape{12}, format::BrickShape{24}}) {
    for (int trial = 0; trial < 40; ++trial) {
      // Five jobs: payloads of different lengths (the longer one is read on alone at the end),
      // and a constant brick among them that is decoded alone.
      std::vector<std::vector<std::byte>> payloads;
      for (std::size_t j = 0; j < 5; ++j)
        payloads.push_back(random_payload(shape, d.atom_count, j == 1 ? 3 : 60, rng));
      const float constant = 0.25f * static_cast<float>(trial);
      if (trial % 2) std::memcpy(payloads[2].data(), &constant, 4), payloads[2].resize(4);
      std::vector<std::vector<float>> one(5, std::vector<float>(shape.voxels()));
      std::vector<std::vector<float>> paired(5, std::vector<float>(shape.voxels(), -7.0f));
      std::vector<format::PayloadJob> jobs;
      for (std::size_t j = 0; j < 5; ++j) {
        format::decode_payload(payloads[j], format::Codec::ksvd, 0, atoms, shape, one[j], "one", 0);
        jobs.push_back({payloads[j], paired[j], "paired", 0});
      }
      // Read in step: jobs 0 and 1, then 2 and 3, or 3 and 4 after the constant.
      EXPECT_EQ(format::decode_payloads(jobs, format::Codec::ksvd, atoms, shape), 4u);
      for (std::size_t j = 0; j < 5; ++j)
        ASSERT_EQ(std::memcmp(one[j].data(), paired[j].data(), one[j].size() * sizeof(float)), 0)
            << "brick " << shape.size << ", trial " << trial << ", job " << j;
    }
  }
}

TEST(Decoder, ARunPastItsBlocksLastCodeIsNamed) {
  // Block 0 names atoms 0 and 1: one run of 2, its length a Rice code with parameter 1 (bits 0, 1,
  // 0 of the code stream). Setting bit 2 makes the length 3, a run past the block's 2 codes, and
  // changes nothing else: the code has the same length and the 63 blocks after it read as before.
  // Every reader refuses the payload by name (the block is far from the stream's end, so the fast
  // paths read it: one at a time and in step, first or second of a pair), where a decoder without
  // the check would decode it.
  const format::DictionaryFile d = learned_and_dct(40, 5);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  const format::BrickShape shape{24};
  std::mt19937 rng(3);
  format::KsvdPayloadParts p =
      parts_without_codes(shape, 5, 4, format::bits_for_count(d.atom_count), 0.002f);
  p.run_limit = VR_MAX_RUN_LIMIT;
  p.run_rice = 1;
  p.sparsity[0] = 2;
  p.atoms = {0, 1};
  p.values = {3, -2};
  std::vector<std::uint32_t> all(d.atom_count);
  std::iota(all.begin(), all.end(), 0u);
  for (std::uint32_t b = 1; b < shape.blocks(); ++b) {
    p.sparsity[b] = 20;
    std::shuffle(all.begin(), all.end(), rng);
    std::vector<std::uint32_t> block(all.begin(), all.begin() + 20);
    std::sort(block.begin(), block.end());
    for (const std::uint32_t a : block) {
      p.atoms.push_back(a);
      p.values.push_back(static_cast<int>(rng() % 16) - 8 >= 0 ? 1 + static_cast<int>(rng() % 7)
                                                               : -1 - static_cast<int>(rng() % 7));
    }
  }
  const std::vector<std::byte> good = format::pack_ksvd_payload(p);
  const format::KsvdPayloadLayout layout =
      format::check_ksvd_payload(good, d.atom_count, shape, "good", 0);
  ASSERT_GT(layout.code_bits, 2000u);
  std::vector<std::byte> bad = good;
  std::byte& first_code = bad[4 * vr_code_first_word(layout.word, shape.blocks())];
  ASSERT_EQ(std::to_integer<int>(first_code) & 7, 2);  // 0, then 1, then the low bit 0
  first_code |= std::byte{4};
  try {
    format::check_ksvd_payload(bad, d.atom_count, shape, "run.vrf", 100);
    ADD_FAILURE() << "a run past its block accepted";
  } catch (const format::FormatError& e) {
    EXPECT_NE(std::string(e.what()).find("runs of consecutive atoms that end with their block "
                                         "(block 0)"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("a run reaching 1 code(s) past the block's 2 codes"),
              std::string::npos)
        << e.what();
  }
  std::vector<float> out(shape.voxels()), other(shape.voxels());
  const format::PayloadJob alone[1] = {{bad, out, "run.vrf", 100}};
  const std::string error = decode_error(alone, atoms, shape);
  EXPECT_NE(error.find("run.vrf"), std::string::npos) << error;
  EXPECT_NE(error.find("runs of consecutive atoms"), std::string::npos) << error;
  const format::PayloadJob second[2] = {{good, other, "good.vrf", 0}, {bad, out, "run.vrf", 100}};
  EXPECT_EQ(decode_error(second, atoms, shape), error);
  const format::PayloadJob first[2] = {{bad, out, "run.vrf", 100}, {good, other, "good.vrf", 0}};
  EXPECT_EQ(decode_error(first, atoms, shape), error);
  // Beside a payload without codes, every block of the bad one is read after the other's end.
  const std::vector<std::byte> empty = payload_without_codes(shape, d.atom_count);
  const format::PayloadJob after[2] = {{empty, other, "empty.vrf", 0}, {bad, out, "run.vrf", 100}};
  EXPECT_EQ(decode_error(after, atoms, shape), error);
  const format::PayloadJob before[2] = {{bad, out, "run.vrf", 100}, {empty, other, "empty.vrf", 0}};
  EXPECT_EQ(decode_error(before, atoms, shape), error);
}

TEST(Decoder, TheFirstCodePastTheDictionaryOrItsMagnitudeIsNamed) {
  // Blocks far from the stream's end are read without per-code checks and checked once (their
  // last atom, the OR of their magnitudes); a block that fails is read again code by code. The
  // error names the first bad code, as a check of every code would, alone and in step.
  const format::DictionaryFile d = learned_and_dct(40, 6);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  const format::BrickShape shape{18};
  std::mt19937 rng(21);
  int named = 0;
  for (int trial = 0; trial < 60; ++trial) {
    // 1. Codes of atoms up to 12 past the dictionary's.
    const std::vector<std::byte> bad = random_payload(shape, d.atom_count + 12, 40, rng);
    const format::KsvdPayloadParts parts =
        format::unpack_ksvd_payload(bad, d.atom_count + 12, shape, "bad", 0);
    std::string expected;
    for (std::uint32_t b = 0, k = 0; b < shape.blocks() && expected.empty(); ++b)
      for (std::uint32_t j = 0; j < parts.sparsity[b]; ++j, ++k)
        if (parts.atoms[k] >= d.atom_count) {
          expected = "atom index < " + std::to_string(d.atom_count) + " (block " +
                     std::to_string(b) + ", code " + std::to_string(j) + ")";
          break;
        }
    std::vector<float> out(shape.voxels()), other(shape.voxels());
    const std::string alone = alone_error(bad, atoms, shape, out, "frame.vrf", 100);
    if (expected.empty()) {
      EXPECT_EQ(alone, "") << "trial " << trial;
      continue;
    }
    ++named;
    EXPECT_NE(alone.find(expected), std::string::npos) << alone << "; expected " << expected;
    const std::vector<std::byte> good = random_payload(shape, d.atom_count, 40, rng);
    const format::PayloadJob pair[2] = {{good, other, "frame.vrf", 100},
                                        {bad, out, "frame.vrf", 100}};
    EXPECT_EQ(decode_error(pair, atoms, shape), alone) << "trial " << trial;
    // Read on alone after a payload without codes: the same checks, the same error.
    const std::vector<std::byte> empty = payload_without_codes(shape, d.atom_count);
    const format::PayloadJob after[2] = {{empty, other, "empty.vrf", 0},
                                         {bad, out, "frame.vrf", 100}};
    EXPECT_EQ(decode_error(after, atoms, shape), alone) << "trial " << trial;
  }
  EXPECT_GT(named, 40);
  // 2. A magnitude past 2^c: a payload packed with c = 8 and no escapes (every band's Rice
  //    parameter 6), one code of magnitude 200 in block 9, then c lowered to 7 in the layout
  //    word (only the check changes: no code is an escape).
  format::KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 4);
  p.mean.assign(shape.blocks(), 0);
  p.mean_bits = 4;
  p.sparsity_bits = 3;
  p.coef_bits = 8;
  p.atom_bits = format::bits_for_count(d.atom_count);
  p.band_rice.fill(6);
  p.magnitude_model = 0;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    for (std::uint32_t j = 0; j < 4; ++j) {
      p.atoms.push_back(3 * j + b % 3);
      p.values.push_back(b == 9 && j == 2 ? -200 : 1 + static_cast<int>(j));
    }
  std::vector<std::byte> payload = format::pack_ksvd_payload(p);
  std::vector<float> out(shape.voxels());
  EXPECT_EQ(alone_error(payload, atoms, shape, out, "frame.vrf", 100), "");
  std::uint32_t layout;
  std::memcpy(&layout, payload.data() + 12, 4);
  layout = (layout & ~(31u << 8)) | (7u << 8);
  std::memcpy(payload.data() + 12, &layout, 4);
  const std::string error = alone_error(payload, atoms, shape, out, "frame.vrf", 100);
  EXPECT_NE(error.find("magnitude ≤ 2^7 (block 9, code 2)"), std::string::npos) << error;
  std::vector<float> other(shape.voxels());
  const std::vector<std::byte> empty = payload_without_codes(shape, d.atom_count);
  const format::PayloadJob after[2] = {{empty, other, "empty.vrf", 0},
                                       {payload, out, "frame.vrf", 100}};
  EXPECT_EQ(decode_error(after, atoms, shape), error);
}

TEST(Decoder, AStreamRunningPastItsEndIsNamedInsideThePayload) {
  // A code stream of zeros (escapes of value 0: every code 49 to 65 bits) runs past its end; the
  // error names an offset inside the payload, its end at most.
  const format::DictionaryFile d = learned_and_dct(40, 6);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  const format::BrickShape shape{18};
  std::mt19937 rng(17);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<std::byte> bad = random_payload(shape, d.atom_count, 40, rng);
    const format::KsvdPayloadLayout layout =
        format::check_ksvd_payload(bad, d.atom_count, shape, "good", 0);
    if (layout.codes < 8) continue;
    const std::size_t first = 4 * vr_code_first_word(layout.word, vr_box_entries(layout.box_word));
    std::fill(bad.begin() + static_cast<std::ptrdiff_t>(first), bad.end(), std::byte{0});
    std::vector<float> out(shape.voxels());
    const std::string error = alone_error(bad, atoms, shape, out, "frame.vrf", 100);
    const std::size_t at = error.find("offset ");
    ASSERT_NE(at, std::string::npos) << error;
    EXPECT_LE(std::stoull(error.substr(at + 7)), 100 + bad.size()) << error;
    EXPECT_GE(std::stoull(error.substr(at + 7)), 100 + first) << error;
  }
}

TEST(Decoder, AtomsPastTheIndexWidthAreRefused) {
  // Blocks of atoms 0, 2, .., 18 packed with a = 5 and gap shift 1 (every gap's Rice parameter
  // 0, no escape), then a lowered to 4 in the layout word: the codes read the same, but atoms
  // 16 and 18 are past what 4 bits index (F + 2^a = 16), though the dictionary holds them. The
  // reader refuses them (a reader that looks a band up by a table of F + 2^a entries would take
  // another Rice parameter for them than vr_read_code computes), alone and in step.
  const format::DictionaryFile d = learned_and_dct(40, 6);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  const format::BrickShape shape{12};
  format::KsvdPayloadParts p;
  p.sparsity.assign(shape.blocks(), 10);
  p.mean.assign(shape.blocks(), 3);
  p.mean_bits = 4;
  p.sparsity_bits = 4;
  p.coef_bits = 4;
  p.atom_bits = 5;
  p.gap_shift = 1;
  p.band_rice.fill(1);
  p.magnitude_model = 0;
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    for (std::uint32_t j = 0; j < 10; ++j) {
      p.atoms.push_back(2 * j);
      p.values.push_back(j % 2 ? 2 : -3);
    }
  std::vector<std::byte> payload = format::pack_ksvd_payload(p);
  std::vector<float> out(shape.voxels()), other(shape.voxels());
  ASSERT_EQ(alone_error(payload, atoms, shape, out, "frame.vrf", 100), "");
  std::uint32_t layout;
  std::memcpy(&layout, payload.data() + 12, 4);
  ASSERT_EQ(vr_layout_atom_bits(layout), 5u);
  ASSERT_EQ(vr_gap_rice(layout, 10), 0u);
  layout = (layout & ~(31u << 13)) | (4u << 13);
  ASSERT_EQ(vr_layout_atom_bits(layout), 4u);
  ASSERT_EQ(vr_gap_rice(layout, 10), 0u);  // the blocks' gaps read the same
  std::memcpy(payload.data() + 12, &layout, 4);
  const std::string alone = alone_error(payload, atoms, shape, out, "frame.vrf", 100);
  EXPECT_NE(alone.find("atom index < 16 (block 0, code 8)"), std::string::npos) << alone;
  std::mt19937 rng(5);
  const std::vector<std::byte> good = random_payload(shape, d.atom_count, 20, rng);
  const format::PayloadJob pair[2] = {{good, other, "frame.vrf", 100},
                                      {payload, out, "frame.vrf", 100}};
  EXPECT_EQ(decode_error(pair, atoms, shape), alone);
}

TEST(Decoder, APayloadReadInStepFailsAsItDoesAlone) {
  // A damaged payload, first or second of a pair, beside a good one or another damaged one: the
  // error is the one decode_payload gives for the first damaged payload, offset included.
  const format::DictionaryFile d = learned_and_dct(40, 6);
  const format::AtomTable atoms = format::atom_table(d.atoms, d.atom_count);
  const format::BrickShape shape{18};
  std::mt19937 rng(13);
  int damaged = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const std::vector<std::byte> good = random_payload(shape, d.atom_count, 40, rng);
    // Case 4: codes of atoms up to 12 past the dictionary's (atom indices too large).
    std::vector<std::byte> bad =
        random_payload(shape, d.atom_count + (trial % 6 == 4 ? 12 : 0), 40, rng);
    switch (trial % 6) {
      case 4:
        break;
      case 5: {  // the layout word's magnitude bits c lowered: magnitudes past 2^c
        std::uint32_t layout;
        std::memcpy(&layout, bad.data() + 12, 4);
        const std::uint32_t c = vr_layout_coef_bits(layout);
        layout = (layout & ~(31u << 8)) | (std::max(1u, c - std::min(c, 3u)) << 8);
        std::memcpy(bad.data() + 12, &layout, 4);
        break;
      }
      case 0:  // a byte of the code stream or the entries changed
        bad[24 + rng() % (bad.size() - 24)] ^=
            std::byte{static_cast<unsigned char>(1 + rng() % 255)};
        break;
      case 1:  // truncated to a shorter whole number of words
        bad.resize(4 * (6 + rng() % (bad.size() / 4 - 6)));
        break;
      case 2:  // a word more
        bad.resize(bad.size() + 4, std::byte{0});
        break;
      default:  // a header field changed
        bad[12 + rng() % 12] ^= std::byte{static_cast<unsigned char>(1 + rng() % 255)};
    }
    std::vector<float> out(shape.voxels()), other(shape.voxels());
    const std::string alone = alone_error(bad, atoms, shape, out, "frame.vrf", 100);
    if (alone.empty()) continue;  // the change left a valid payload
    ++damaged;
    const format::PayloadJob bad_job{bad, out, "frame.vrf", 100};
    const format::PayloadJob good_job{good, other, "frame.vrf", 100};
    // Second of a damaged pair: a short header, named differently.
    const std::vector<std::byte> header_only(good.begin(), good.begin() + 20);
    const format::PayloadJob other_bad{header_only, other, "other.vrf", 700};
    const format::PayloadJob jobs[][2] = {
        {bad_job, good_job}, {good_job, bad_job}, {bad_job, other_bad}};
    for (const auto& pair : jobs)
      EXPECT_EQ(decode_error(pair, atoms, shape), alone) << "trial " << trial;
    const format::PayloadJob reversed[2] = {other_bad, bad_job};
    EXPECT_NE(decode_error(reversed, atoms, shape).find("other.vrf"), std::string::npos);
  }
  EXPECT_GT(damaged, 150);
  // Valid payloads against a table that holds fewer atoms than it counts: the error of one
  // payload alone.
  const std::vector<std::byte> good = random_payload(shape, d.atom_count, 40, rng);
  format::AtomTable short_table = atoms;
  short_table.values = short_table.values.first(short_table.values.size() - VR_BLOCK_LENGTH);
  std::vector<float> out(shape.voxels()), other(shape.voxels());
  const std::string alone = alone_error(good, short_table, shape, out, "a.vrf", 8);
  EXPECT_NE(alone.find("fewer than"), std::string::npos) << alone;
  const format::PayloadJob both[2] = {{good, out, "a.vrf", 8}, {good, other, "b.vrf", 16}};
  EXPECT_EQ(decode_error(both, short_table, shape), alone);
}

}  // namespace
}  // namespace volreel
