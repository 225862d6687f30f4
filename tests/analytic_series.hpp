// analytic_series.hpp: a raw series of one of the generator's analytic fields, written into a
// test's folder and opened, for the encoder's tests.
#pragma once

#include <filesystem>
#include <memory>

#include "volreel/datasets/analytic.hpp"
#include "volreel/datasets/series.hpp"

namespace volreel::test {

/// `frames` frames of `field` on `dims` (40×36×30 by default: bricks of the encoder's tests cover
/// it unevenly) in dir/series, named `variable`, opened.
inline std::unique_ptr<datasets::SeriesReader> analytic_series(const std::filesystem::path& dir,
                                                               datasets::AnalyticField field,
                                                               std::size_t frames,
                                                               const char* variable,
                                                               Dims dims = {40, 36, 30}) {
  datasets::AnalyticParams p;
  p.field = field;
  p.dims = dims;
  p.frames = frames;
  {
    datasets::RawSeriesWriter w(dir / "series", p.dims, variable);
    datasets::generate_analytic(p, w);
  }
  return datasets::open_series(dir / "series");
}

}  // namespace volreel::test
