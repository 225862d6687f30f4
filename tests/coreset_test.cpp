// coreset_test.cpp: the coreset hierarchy — Halton frame choice, importance sampling that keeps
// weighted sums unbiased (energy exactly, second moments within a stated tolerance), nested
// levels of the right sizes, no flat blocks, determinism, and the same result from a series on
// disk.
#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <numeric>
#include <set>

#include "dictionary_test_data.hpp"
#include "test_util.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/blocks.hpp"
#include "volreel/dictionary/coreset.hpp"

namespace {

using namespace volreel;
using namespace volreel::dictionary;

std::vector<Volume> frames(int count, Dims dims) {
  std::vector<Volume> v;
  for (int t = 0; t < count; ++t)
    v.push_back(test::wavy_volume(dims, 100 + static_cast<std::uint64_t>(t)));
  return v;
}

/// All blocks of all frames, zero-mean, as columns.
Eigen::MatrixXf all_blocks(const std::vector<Volume>& volumes, int M) {
  std::vector<Eigen::MatrixXf> parts;
  Eigen::Index total = 0;
  for (const Volume& v : volumes) {
    Eigen::MatrixXf b;
    std::vector<float> means;
    extract_blocks(BlockGrid(v.dims, M), v.data, b, means);
    total += b.cols();
    parts.push_back(std::move(b));
  }
  Eigen::MatrixXf all(M * M * M, total);
  Eigen::Index at = 0;
  for (const auto& p : parts) {
    all.middleCols(at, p.cols()) = p;
    at += p.cols();
  }
  return all;
}

TEST(Blocks, ExtractAndStoreRoundTripWithEdgeReplication) {
  const Dims dims{13, 7, 6};  // not multiples of 6
  const Volume v = test::wavy_volume(dims, 1);
  const BlockGrid grid(dims, 6);
  EXPECT_EQ(grid.block_count(), 3u * 2u * 1u);
  Volume back(dims);
  std::vector<float> block(216);
  for (std::size_t b = 0; b < grid.block_count(); ++b) {
    const float mean = grid.extract(v.data, b, block.data());
    EXPECT_NEAR(std::accumulate(block.begin(), block.end(), 0.0), 0.0, 1e-3);
    grid.store(back.data, b, mean, block.data());
  }
  for (std::size_t i = 0; i < v.data.size(); ++i) ASSERT_NEAR(back.data[i], v.data[i], 1e-5);
  // Block 2 covers x = 12..17: x = 13..17 replicate x = 12.
  grid.extract(v.data, 2, block.data());
  for (int i = 1; i < 6; ++i) EXPECT_EQ(block[static_cast<std::size_t>(i)], block[0]);
}

TEST(Coreset, HaltonFrames) {
  std::vector<std::size_t> candidates(64);
  std::iota(candidates.begin(), candidates.end(), std::size_t{0});
  const auto chosen = halton_frames(candidates, 1000, 16 * 1000);
  ASSERT_EQ(chosen.size(), 16u);
  EXPECT_EQ((std::vector<std::size_t>(chosen.begin(), chosen.begin() + 7)),
            (std::vector<std::size_t>{32, 16, 48, 8, 40, 24, 56}));
  EXPECT_EQ(std::set<std::size_t>(chosen.begin(), chosen.end()).size(), 16u);
  // Too few frames: all of them, each once.
  std::vector<std::size_t> few{3, 5, 9, 11, 12};
  auto all = halton_frames(few, 1000, 1e9);
  std::sort(all.begin(), all.end());
  EXPECT_EQ(all, few);
  // A frame count that is not a power of two still yields distinct frames.
  std::vector<std::size_t> odd(37);
  std::iota(odd.begin(), odd.end(), std::size_t{0});
  const auto some = halton_frames(odd, 10, 200);
  EXPECT_EQ(some.size(), 20u);
  EXPECT_EQ(std::set<std::size_t>(some.begin(), some.end()).size(), 20u);
}

TEST(Coreset, WeightedSumsMatchTheFullData) {
  const int M = 4;
  const auto volumes = frames(4, {48, 48, 48});  // 4 × 1728 blocks of 64 values
  CoresetOptions o;
  o.block_size = M;
  o.coreset_voxels = 2048 * 64;  // 2048 draws at the largest level
  o.levels = 3;
  o.seed = 5;
  const CoresetHierarchy h = build_coreset_hierarchy(volumes, o);
  const Eigen::MatrixXf all = all_blocks(volumes, M);
  const double energy = all.cast<double>().colwise().squaredNorm().sum();
  const Eigen::MatrixXd second_moment = all.cast<double>() * all.cast<double>().transpose();
  EXPECT_EQ(h.population_blocks, static_cast<double>(all.cols()));
  EXPECT_NEAR(h.population_energy, energy, 1e-6 * energy);
  ASSERT_EQ(h.levels.size(), 4u);
  for (std::size_t l = 0; l < h.levels.size(); ++l) {
    const Coreset& c = h.levels[l];
    EXPECT_EQ(c.draws, std::size_t{2048} >> (3 - l));
    EXPECT_LE(static_cast<std::size_t>(c.blocks.cols()), c.draws);
    Eigen::VectorXd w(c.blocks.cols());
    for (Eigen::Index i = 0; i < w.size(); ++i) w[i] = c.weights[static_cast<std::size_t>(i)];
    const Eigen::MatrixXd Y = c.blocks.cast<double>();
    // Energy: exact by construction of the weights (Σ w‖y‖² = E).
    const double weighted_energy = Y.colwise().squaredNorm().dot(w);
    EXPECT_NEAR(weighted_energy, energy, 1e-4 * energy) << "level " << l;
    // Second-moment matrix Σ w y yᵀ, which fixes Σ w‖y − P y‖² for every projection P. Each draw
    // contributes (E/n)·u uᵀ with u = y/‖y‖, so the relative Frobenius error has expectation
    // sqrt((1 − ‖S/E‖²) / n) / ‖S/E‖ (S the full matrix); allowed: 1.5 times that.
    const Eigen::MatrixXd estimate = Y * w.asDiagonal() * Y.transpose();
    const double error = (estimate - second_moment).norm() / second_moment.norm();
    const double s_norm = second_moment.norm() / energy;
    const double expected =
        std::sqrt((1 - s_norm * s_norm) / static_cast<double>(c.draws)) / s_norm;
    EXPECT_LT(error, 1.5 * expected) << "level " << l;
    EXPECT_GT(error, 0.3 * expected) << "level " << l << ": suspiciously exact";
  }
  // Levels are nested: each level's blocks are among the next level's.
  for (std::size_t l = 0; l + 1 < h.levels.size(); ++l) {
    const auto& small = h.levels[l].blocks;
    const auto& big = h.levels[l + 1].blocks;
    for (Eigen::Index i = 0; i < small.cols(); ++i) {
      bool found = false;
      for (Eigen::Index j = 0; j < big.cols() && !found; ++j) found = small.col(i) == big.col(j);
      ASSERT_TRUE(found) << "level " << l << " block " << i;
    }
  }
}

TEST(Coreset, FlatBlocksAreNeverKept) {
  const int M = 4;
  Volume v = test::wavy_volume({32, 32, 32}, 9);
  for (std::int64_t k = 0; k < 16; ++k)  // the lower half constant
    for (std::int64_t j = 0; j < 32; ++j)
      for (std::int64_t i = 0; i < 32; ++i) v.at(i, j, k) = 2.5f;
  CoresetOptions o;
  o.block_size = M;
  o.coreset_voxels = 256 * 64;
  o.levels = 2;
  const CoresetHierarchy h = build_coreset_hierarchy(std::vector<Volume>{v}, o);
  EXPECT_EQ(h.population_blocks, 512.0);
  for (const Coreset& c : h.levels)
    for (Eigen::Index i = 0; i < c.blocks.cols(); ++i)
      EXPECT_GT(c.blocks.col(i).squaredNorm(), 0.0f);
  // An all-flat input gives empty levels, not a crash.
  const Volume flat(Dims{16, 16, 16});
  const CoresetHierarchy none = build_coreset_hierarchy(std::vector<Volume>{flat}, o);
  for (const Coreset& c : none.levels) EXPECT_EQ(c.blocks.cols(), 0);
}

TEST(Coreset, DeterministicForASeedAndTooSmallIsRefused) {
  const auto volumes = frames(2, {24, 24, 24});
  CoresetOptions o;
  o.block_size = 4;
  o.coreset_voxels = 128 * 64;
  o.levels = 2;
  o.seed = 77;
  const auto a = build_coreset_hierarchy(volumes, o);
  const auto b = build_coreset_hierarchy(volumes, o);
  o.seed = 78;
  const auto c = build_coreset_hierarchy(volumes, o);
  EXPECT_EQ(a.largest().blocks, b.largest().blocks);
  EXPECT_EQ(a.largest().weights, b.largest().weights);
  EXPECT_FALSE(a.largest().blocks.cols() == c.largest().blocks.cols() &&
               a.largest().blocks == c.largest().blocks);
  o.coreset_voxels = 3 * 64;  // 3 blocks cannot halve twice
  EXPECT_THROW(build_coreset_hierarchy(volumes, o), InputError);
}

TEST(Coreset, FromASeriesOnDiskMatchesInMemory) {
  test::TempDir dir("coreset-series");
  const Dims dims{20, 20, 20};
  const auto volumes = frames(8, dims);
  datasets::RawSeriesWriter writer(dir.path(), dims, "test");
  for (std::size_t t = 0; t < volumes.size(); ++t)
    writer.write_frame(t, static_cast<double>(t), volumes[t].data);
  writer.finish();
  const auto series = datasets::open_series(dir.path());
  CoresetOptions o;
  o.block_size = 5;
  o.coreset_voxels = 64 * 125;
  o.levels = 3;
  o.frame_factor = 3 * 8000.0 / static_cast<double>(o.coreset_voxels);  // three frames' worth
  const CoresetHierarchy from_disk = build_coreset_hierarchy(*series, o);
  ASSERT_EQ(from_disk.frames, (std::vector<std::size_t>{4, 2, 6}));
  // The draw depends on the frames' indices, not on the order they are visited in, nor on who
  // visits them: one draw over 6, 2, 4 in memory, and two draws (two processes: 4; 2 and 6) sent
  // as bytes and merged, give the hierarchy read from disk.
  CoresetDraw one(o);
  for (std::size_t t : {6u, 2u, 4u}) one.add_frame(t, volumes[t].data, dims);
  CoresetDraw first(o), second(o);
  first.add_frame(4, volumes[4].data, dims);
  second.add_frame(2, volumes[2].data, dims);
  second.add_frame(6, volumes[6].data, dims);
  CoresetDraw merged = CoresetDraw::from_bytes(second.to_bytes(), o);
  merged.merge(CoresetDraw::from_bytes(first.to_bytes(), o));
  const CoresetHierarchy drawn[2] = {one.finish(o.levels), merged.finish(o.levels)};
  for (const CoresetHierarchy& in_memory : drawn) {
    SCOPED_TRACE(&in_memory == drawn ? "one draw over every frame" : "two draws merged");
    EXPECT_EQ(in_memory.population_energy, from_disk.population_energy);
    for (std::size_t l = 0; l < in_memory.levels.size(); ++l) {
      EXPECT_EQ(from_disk.levels[l].blocks, in_memory.levels[l].blocks);
      EXPECT_EQ(from_disk.levels[l].weights, in_memory.levels[l].weights);
    }
  }
  // A draw of other options, or bytes cut short, are refused.
  CoresetOptions other = o;
  other.coreset_voxels *= 2;
  EXPECT_THROW(merged.merge(CoresetDraw(other)), std::invalid_argument);
  std::vector<std::byte> cut = first.to_bytes();
  cut.resize(cut.size() - 1);
  EXPECT_THROW(CoresetDraw::from_bytes(cut, o), std::invalid_argument);
  float lo = volumes[4].data[0], hi = lo;
  for (int t : {4, 2, 6})
    for (float x : volumes[static_cast<std::size_t>(t)].data) {
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
  EXPECT_EQ(from_disk.value_min, lo);
  EXPECT_EQ(from_disk.value_max, hi);
  // Held-out frames are never drawn from.
  o.candidate_frames = {0, 1, 3, 5};
  EXPECT_EQ(build_coreset_hierarchy(*series, o).frames, (std::vector<std::size_t>{3, 1, 5}));
}

}  // namespace
