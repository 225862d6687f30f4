// analytic_test.cpp: the analytic fields are deterministic, time-varying and written correctly.
#include <gtest/gtest.h>

#include <algorithm>
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
  vd::analytic_frame(p, 5, a);
  vd::analytic_frame(p, 5, b);
  EXPECT_EQ(a, b) << "same parameters and frame must give identical data";
  vd::analytic_frame(p, 6, c);
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
  vd::analytic_frame(p, 5, b);
  EXPECT_NE(a, b) << "another seed should give another field";
}

INSTANTIATE_TEST_SUITE_P(All, AnalyticFields,
                         ::testing::Values(vd::AnalyticField::blobs, vd::AnalyticField::rotating,
                                           vd::AnalyticField::noise, vd::AnalyticField::plume),
                         [](const auto& param_info) { return vd::to_string(param_info.param); });

TEST(Analytic, PlumeChangesOnlyWhereThePlumeIs) {
  vd::AnalyticParams p;
  p.field = vd::AnalyticField::plume;
  p.dims = Dims{32, 28, 40};
  p.frames = 10;
  std::vector<float> a(p.dims.voxels()), b(p.dims.voxels());
  vd::analytic_frame(p, 4, a);
  vd::analytic_frame(p, 5, b);
  std::size_t still = 0, changed = 0;
  for (std::size_t i = 0; i < a.size(); ++i) (a[i] == b[i] ? still : changed) += 1;
  EXPECT_GT(still, a.size() / 2) << "most of the box is outside the plume and must stay still";
  EXPECT_GT(changed, a.size() / 50) << "the plume must move";
  // Above the front the box is still, and not constant: it has structure to code.
  const auto top = static_cast<std::size_t>(p.dims.x * p.dims.y);
  const std::vector<float> last_plane(a.end() - static_cast<std::ptrdiff_t>(top), a.end());
  const std::vector<float> last_plane_b(b.end() - static_cast<std::ptrdiff_t>(top), b.end());
  EXPECT_EQ(last_plane, last_plane_b);
  const auto [lo, hi] = std::minmax_element(last_plane.begin(), last_plane.end());
  EXPECT_GT(*hi - *lo, 0.05f);
}

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
