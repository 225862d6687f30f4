// prng_test.cpp: volreel's SplitMix64 reproduces the reference sequence and sane distributions.
#include <gtest/gtest.h>

#include <cmath>

#include "volreel/datasets/prng.hpp"

using volreel::SplitMix64;

TEST(SplitMix64, MatchesReferenceSequence) {
  // First outputs of Vigna's splitmix64.c seeded with 0.
  SplitMix64 rng(0);
  EXPECT_EQ(rng.next(), 0xE220A8397B1DCDAFull);
  EXPECT_EQ(rng.next(), 0x6E789E6AA1B965F4ull);
  EXPECT_EQ(rng.next(), 0x06C45D188009454Full);
}

TEST(SplitMix64, UniformAndNormalMoments) {
  SplitMix64 rng(42);
  const int n = 200000;
  double sum = 0, sum2 = 0, nsum = 0, nsum2 = 0;
  for (int i = 0; i < n; ++i) {
    const double u = rng.uniform();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    sum += u;
    sum2 += u * u;
    const double g = rng.normal();
    nsum += g;
    nsum2 += g * g;
  }
  EXPECT_NEAR(sum / n, 0.5, 0.005);
  EXPECT_NEAR(sum2 / n - (sum / n) * (sum / n), 1.0 / 12, 0.002);
  EXPECT_NEAR(nsum / n, 0.0, 0.01);
  EXPECT_NEAR(nsum2 / n, 1.0, 0.02);
}

TEST(SplitMix64, BelowStaysInRange) {
  SplitMix64 rng(7);
  int counts[5] = {};
  for (int i = 0; i < 50000; ++i) {
    const auto v = rng.below(5);
    ASSERT_LT(v, 5u);
    ++counts[v];
  }
  for (int c : counts) EXPECT_NEAR(c, 10000, 500);
}
