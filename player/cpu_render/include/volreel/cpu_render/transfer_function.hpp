// transfer_function.hpp: the 1D transfer function of volreel's renderers — a table of RGBA
// entries over a value range, built from control points, named presets, a JSON form, opacity
// correction for the ray step, and the histogram test that lets a renderer skip nodes the
// transfer function makes invisible (docs/design.md, "Streaming", step 7).
//
// Lookup (the same in the CPU reference renderer and the render shader): a value v maps to the
// table coordinate x = clamp((v − lo)/(hi − lo), 0, 1)·(N − 1), and the result is the linear
// interpolation of entries ⌊x⌋ and ⌊x⌋ + 1 — on the GPU a 1D texture of N texels with a linear
// sampler read at (x + 0.5)/N. Colours are not premultiplied; alpha is the opacity of one
// reference step (one finest voxel unless the renderer says otherwise).
//
// JSON:
//   {"range": [lo, hi], "entries": 256, "points": [[v, r, g, b, a], ...]}
//       v in data units, r g b a in [0, 1]; points sorted by v (equal values allowed: a step).
//       "range" defaults to [first v, last v]; "entries" to 256.
//   {"preset": "fire", "range": [lo, hi], "opacity": 1.0, "entries": 256}
//       a named preset (preset_names()) stretched over the range ("range" defaults to the
//       caller's, normally the container's value range); "opacity" scales its alpha.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace volreel::cpu_render {

/// One control point: a value in data units and a non-premultiplied colour with opacity.
struct ControlPoint {
  float value = 0;
  float r = 0, g = 0, b = 0, a = 0;
  friend bool operator==(const ControlPoint&, const ControlPoint&) = default;
};

using Rgba = std::array<float, 4>;

class TransferFunction {
 public:
  static constexpr int default_entries = 256;

  /// Fully transparent black over [0, 1].
  TransferFunction();
  /// From control points (sorted by value; at least one) over [lo, hi] (lo < hi), `entries` ≥ 2
  /// table entries; each entry is the piecewise-linear interpolation of the points at its value,
  /// clamped to the first and last point outside them. Throws InputError on bad arguments.
  TransferFunction(std::vector<ControlPoint> points, float lo, float hi,
                   int entries = default_entries);

  /// A named preset (preset_names()) over [lo, hi], alpha scaled by `opacity` (≥ 0).
  /// Throws InputError naming the preset when it is unknown.
  static TransferFunction preset(const std::string& name, float lo, float hi, float opacity = 1,
                                 int entries = default_entries);
  /// "grayscale", "cool-warm", "fire", "turbulence", "transparent".
  static const std::vector<std::string>& preset_names();

  /// Parses the JSON form (see the file comment). `default_range` is used by presets without a
  /// "range". `where` prefixes errors ("tour.json: transfer[2]"). Throws InputError naming the
  /// field, what was expected and what was found.
  static TransferFunction from_json(const nlohmann::json& json, std::array<float, 2> default_range,
                                    const std::string& where = "transfer function");
  /// {"range", "entries", "points"}: from_json(to_json()) reproduces the table exactly.
  nlohmann::json to_json() const;

  float lo() const { return lo_; }
  float hi() const { return hi_; }
  int entry_count() const { return static_cast<int>(table_.size()); }
  const std::vector<Rgba>& table() const { return table_; }
  const std::vector<ControlPoint>& points() const { return points_; }

  /// The interpolated RGBA of value v (see the file comment).
  Rgba lookup(float v) const;

  /// The same transfer function with every alpha corrected for a ray step of `step_ratio` =
  /// step / reference step: alpha' = 1 − (1 − alpha)^step_ratio, so that the opacity of a length
  /// does not depend on the number of samples taken along it. Applied to the entries; lookup then
  /// interpolates the corrected entries.
  TransferFunction opacity_corrected(double step_ratio) const;

  /// Bit b set when some value of histogram bin b (64 bins over [value_min, value_max], as
  /// format::histogram_bin: values below the range fall in bin 0, above it in bin 63) maps to a
  /// nonzero opacity. Conservative: a bin touching a visible entry is visible.
  std::uint64_t visible_bins(float value_min, float value_max) const;
  /// Whether a node with this histogram (format::Node::histogram) has anything visible.
  bool visible(std::uint64_t histogram, float value_min, float value_max) const {
    return (histogram & visible_bins(value_min, value_max)) != 0;
  }
  /// The same for the hull of the histogram — every bin from the lowest to the highest set bit —
  /// which also covers the values that interpolating between present values creates (svo_layout.h,
  /// leaf histograms). False for an empty histogram.
  bool visible_hull(std::uint64_t histogram, float value_min, float value_max) const;
  /// The hull of a histogram: bits lowest..highest set (0 for 0).
  static std::uint64_t histogram_hull(std::uint64_t histogram);

  /// Entry-wise linear blend (1 − w)·a + w·b of tables and ranges (tables resampled to the larger
  /// entry count); the points are a's when w < 0.5, else b's. Used by tours between keys.
  static TransferFunction blend(const TransferFunction& a, const TransferFunction& b, float w);

  /// A transfer function placed at quantiles of sample values that shows what a scientist looks
  /// for first — the tails of the distribution (low-pressure vortex cores, high vorticity, the
  /// inside of blobs) — and leaves the bulk clear:
  ///   - the lowest 4 % blue rising to opaque, the highest 4 % orange to red, the bulk clear;
  ///   - a tail that is short next to the other (measured from the median to the 0.1 % and
  ///     99.9 % quantiles; the values near 0 of a magnitude, the background around blobs) is
  ///     faded out, since there it is the bulk's edge, not a structure;
  ///   - with `path_voxels` > 0 (the length of a typical ray through the volume, voxels) the
  ///     opacities are scaled down where the sampled values would make the average ray's optical
  ///     depth exceed 2 (transmittance e^-2), so that structure in front does not hide all the
  ///     rest and the volume never draws as an opaque block.
  /// Spans [lo, hi]; "cool-warm" when there are no values or the range is empty.
  static TransferFunction from_quantiles(std::vector<float> values, float lo, float hi,
                                         double path_voxels = 0);

  friend bool operator==(const TransferFunction&, const TransferFunction&) = default;

 private:
  std::vector<ControlPoint> points_;
  float lo_ = 0, hi_ = 1;
  std::vector<Rgba> table_;
};

}  // namespace volreel::cpu_render
