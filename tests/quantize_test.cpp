// quantize_test.cpp: the quantizer's least-squares refit leaves the coefficients of orthonormal
// atoms as they are, so skipping it there writes the same payload.
#include <gtest/gtest.h>

#include <utility>
#include <vector>

#include "detail.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/dictionary_file.hpp"

namespace volreel {
namespace {

/// A brick's blocks: each a few random atoms of `atoms` with coefficients of 1–4 in magnitude,
/// plus noise of RMS 0.05 a value, its mean removed; the means random.
struct Blocks {
  std::vector<float> columns, means;
};

Blocks random_blocks(const Eigen::MatrixXf& atoms, std::uint32_t count, std::uint64_t seed) {
  SplitMix64 rng(seed);
  Blocks out;
  out.columns.assign(std::size_t{count} * VR_BLOCK_LENGTH, 0.0f);
  out.means.resize(count);
  for (std::uint32_t b = 0; b < count; ++b) {
    Eigen::Map<Eigen::VectorXf> y(out.columns.data() + std::size_t{b} * VR_BLOCK_LENGTH,
                                  VR_BLOCK_LENGTH);
    for (int k = 0; k < 6; ++k)
      y +=
          static_cast<float>((rng.uniform() < 0.5 ? -1 : 1) * rng.uniform(1.0, 4.0)) *
          atoms.col(static_cast<Eigen::Index>(rng.below(static_cast<std::uint64_t>(atoms.cols()))));
    for (Eigen::Index v = 0; v < y.size(); ++v) y[v] += static_cast<float>(0.05 * rng.normal());
    y.array() -= y.mean();
    out.means[b] = static_cast<float>(rng.uniform(-1.0, 1.0));
  }
  return out;
}

/// The payload of one brick of blocks coded against `atoms`, quantized with `options`.
std::vector<std::byte> payload(const Eigen::MatrixXf& atoms, const Blocks& blocks,
                               format::BrickShape shape,
                               const encoder::detail::QuantizeOptions& options,
                               encoder::detail::BrickQuantization* result) {
  const auto m = static_cast<Eigen::Index>(VR_BLOCK_LENGTH);
  const Eigen::Map<const Eigen::MatrixXf> columns(blocks.columns.data(), m,
                                                  static_cast<Eigen::Index>(shape.blocks()));
  dictionary::SparseCodes codes;
  dictionary::BatchOmp(atoms, {.max_atoms = 15, .min_atom_gain = 0.1}).encode(columns, codes);
  return encoder::detail::quantize_brick(shape, blocks.columns.data(), blocks.means.data(), codes,
                                         0, atoms, options, result);
}

TEST(Quantization, OrthonormalAtomsNeedNoRefit) {
  const format::BrickShape shape{12};  // 8 blocks
  const std::vector<float> dct = format::block_dct_atoms(VR_BLOCK_SIZE);
  const Eigen::MatrixXf atoms = Eigen::Map<const Eigen::MatrixXf>(
      dct.data(), VR_BLOCK_LENGTH, static_cast<Eigen::Index>(dct.size() / VR_BLOCK_LENGTH));
  ASSERT_TRUE(dictionary::BatchOmp(atoms, {}).orthonormal());
  encoder::detail::QuantizeOptions refit;
  refit.coef_step = 0.9;  // coarse against the coefficients: the rounding errors are large
  refit.mean_step = 1e-3;
  encoder::detail::QuantizeOptions rounded = refit;
  rounded.refit = false;
  // Also with the steps that add atoms after quantization: while a block's error exceeds m·ε²
  // (target_energy) or one of its values exceeds a bound (max_abs_error, which also halves the
  // step of a brick that misses it).
  encoder::detail::QuantizeOptions extended = refit;
  extended.target_energy = 216 * 0.2 * 0.2;
  encoder::detail::QuantizeOptions bounded = refit;
  bounded.max_abs_error = 0.25;
  for (const auto& with_refit : {refit, extended, bounded}) {
    encoder::detail::QuantizeOptions without = with_refit;
    without.orthonormal_atoms = true;
    for (std::uint64_t seed = 1; seed <= 20; ++seed) {
      const Blocks blocks = random_blocks(atoms, shape.blocks(), seed);
      encoder::detail::BrickQuantization a, b;
      EXPECT_EQ(payload(atoms, blocks, shape, with_refit, &a),
                payload(atoms, blocks, shape, without, &b))
          << "seed " << seed << ", target energy " << with_refit.target_energy << ", bound "
          << with_refit.max_abs_error;
      EXPECT_NEAR(a.squared_error, b.squared_error, 1e-6 * a.squared_error);
    }
  }
  // Atoms that all lean towards one (correlations near 0.2): there the refit changes the codes, so
  // the comparison above would see a refit that mattered.
  Eigen::MatrixXf skewed = atoms;
  for (Eigen::Index k = 1; k < skewed.cols(); ++k) skewed.col(k) += 0.5f * atoms.col(0);
  dictionary::normalize_atoms(skewed);
  int differ = 0;
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    const Blocks blocks = random_blocks(skewed, shape.blocks(), seed);
    encoder::detail::BrickQuantization a, b;
    differ +=
        payload(skewed, blocks, shape, refit, &a) != payload(skewed, blocks, shape, rounded, &b);
  }
  EXPECT_GT(differ, 10);
}

TEST(Quantization, BlocksOnAllThreadsWriteTheSamePayload) {
  // A brick of 64 blocks against skewed atoms (the refit matters) and against the DCT basis, with
  // each of the quantizer's steps: the blocks shared among the threads give the payload and the
  // sums of the blocks quantized one after the other.
  const format::BrickShape shape{24};
  const std::vector<float> dct = format::block_dct_atoms(VR_BLOCK_SIZE);
  const Eigen::MatrixXf basis = Eigen::Map<const Eigen::MatrixXf>(
      dct.data(), VR_BLOCK_LENGTH, static_cast<Eigen::Index>(dct.size() / VR_BLOCK_LENGTH));
  Eigen::MatrixXf skewed = basis;
  for (Eigen::Index k = 1; k < skewed.cols(); ++k) skewed.col(k) += 0.5f * basis.col(0);
  dictionary::normalize_atoms(skewed);
  encoder::detail::QuantizeOptions plain;
  plain.coef_step = 0.3;
  plain.mean_step = 1e-3;
  encoder::detail::QuantizeOptions extended = plain, bounded = plain;
  extended.target_energy = 216 * 0.05 * 0.05;
  bounded.max_abs_error = 0.1;
  std::vector<float> weights(shape.blocks());
  for (std::size_t b = 0; b < weights.size(); ++b)
    weights[b] = 0.25f + 0.01f * static_cast<float>(b);
  for (const Eigen::MatrixXf* atoms : {&std::as_const(skewed), &basis})
    for (encoder::detail::QuantizeOptions serial : {plain, extended, bounded}) {
      serial.orthonormal_atoms = atoms == &basis;
      serial.block_weights = weights.data();
      serial.box = vr_make_box(4, 3, 4);  // the blocks past it are not coded
      encoder::detail::QuantizeOptions parallel = serial;
      parallel.parallel_blocks = true;
      for (std::uint64_t seed = 1; seed <= 4; ++seed) {
        const Blocks blocks = random_blocks(*atoms, shape.blocks(), seed);
        encoder::detail::BrickQuantization a, b;
        EXPECT_EQ(payload(*atoms, blocks, shape, serial, &a),
                  payload(*atoms, blocks, shape, parallel, &b))
            << "seed " << seed;
        EXPECT_EQ(a.squared_error, b.squared_error);
        EXPECT_EQ(a.weighted_error, b.weighted_error);
        EXPECT_EQ(a.codes, b.codes);
        EXPECT_EQ(a.blocks_over_bound, b.blocks_over_bound);
        EXPECT_GT(a.codes, 0u);
      }
    }
}

}  // namespace
}  // namespace volreel
