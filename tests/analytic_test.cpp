// analytic_test.cpp: the analytic fields are deterministic, time-varying and written correctly.
#include <gtest/gtest.h>

#include <cmath>

#include "test_util.hpp"
#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"

namespace vd = volreel::datasets;
using volreel::Dims;

class AnalyticFields : public ::testing::TestWithParam<vd::AnalyticField> {};

TEST_P(AnalyticFields, DeterministicBoundedAndMoving) {
  vd::AnalyticParams p;
  p.field = GetParam();
  p.dims = Dims{24, 20, 16};
  p.frames = 8;
  p.seed = 3;
  std::vector<float> a(p.dims.voxels()), b(p.dims.voxels()), c(p.dims.voxels());
  vd::analytic_frame(p, 2, a);
  vd::analytic_frame(p, 2, b);
  EXPECT_EQ(a, b) << "same parameters and frame must give identical data";
  vd::analytic_frame(p, 3, c);
  double change = 0, energy = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    ASSERT_TRUE(std::isfinite(a[i]));
    ASSERT_LT(std::abs(a[i]), 2.0f);
    change += std::abs(static_cast<double>(a[i] - c[i]));
    energy += std::abs(static_cast<double>(a[i]));
  }
  EXPECT_GT(energy / static_cast<double>(a.size()), 0.01) << "field is nearly zero";
  EXPECT_GT(change, 0.01 * energy) << "consecutive frames should differ";
  p.seed = 4;
  vd::analytic_frame(p, 2, b);
  EXPECT_NE(a, b) << "another seed should give another field";
}

INSTANTIATE_TEST_SUITE_P(All, AnalyticFields,
                         ::testing::Values(vd::AnalyticField::blobs, vd::AnalyticField::rotating,
                                           vd::AnalyticField::noise),
                         [](const auto& param_info) { return vd::to_string(param_info.param); });

TEST(Analytic, GenerateWritesAReadableSeries) {
  volreel::test::TempDir dir("analytic");
  vd::AnalyticParams p;
  p.field = vd::AnalyticField::noise;
  p.dims = Dims{16, 12, 10};
  p.frames = 5;
  vd::RawSeriesWriter writer(dir / "s", p.dims, "noise");
  vd::generate_analytic(p, writer);
  const auto series = vd::open_series(dir / "s");
  ASSERT_EQ(series->info().frames, 5u);
  EXPECT_EQ(series->info().dims, p.dims);
  std::vector<float> expected(p.dims.voxels());
  vd::analytic_frame(p, 4, expected);
  EXPECT_EQ(series->read_frame(4).data, expected);
  EXPECT_DOUBLE_EQ(series->info().timestamps[4], 0.8);
  EXPECT_EQ(series->info().generator.at("field"), "noise");
}

TEST(Analytic, UnknownFieldIsAnError) {
  EXPECT_THROW(vd::parse_analytic_field("vortex"), volreel::InputError);
}
