// transfer_function.cpp: tables from control points, presets, JSON, opacity correction and the
// histogram visibility test of volreel's transfer functions.
#include "volreel/cpu_render/transfer_function.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include "json_fields.hpp"
#include "volreel/format/error.hpp"

namespace volreel::cpu_render {
namespace {

/// Presets: control points at normalized positions t ∈ [0, 1] of the range. Opacities are per
/// finest voxel, low enough that a few tens of voxels of the featured values become opaque.
struct PresetPoint {
  float t, r, g, b, a;
};

struct Preset {
  std::string name;
  std::vector<PresetPoint> points;
};

/// The presets in the order menus and messages list them.
const std::vector<Preset>& presets() {
  static const std::vector<Preset> table = {
      {"grayscale", {{0.0f, 0, 0, 0, 0}, {1.0f, 1, 1, 1, 0.2f}}},
      // Moreland's diverging map (2009): both extremes opaque, the middle clear — for signed
      // fields such as pressure (low-pressure vortex cores in blue, stagnation regions in red).
      {"cool-warm",
       {{0.00f, 0.230f, 0.299f, 0.754f, 0.30f},
        {0.20f, 0.484f, 0.628f, 0.980f, 0.06f},
        {0.40f, 0.777f, 0.815f, 0.861f, 0.0f},
        {0.60f, 0.887f, 0.789f, 0.743f, 0.0f},
        {0.80f, 0.958f, 0.604f, 0.482f, 0.06f},
        {1.00f, 0.706f, 0.016f, 0.150f, 0.30f}}},
      // Black body: dark red to white, opacity rising with the value.
      {"fire",
       {{0.00f, 0.0f, 0.0f, 0.0f, 0.0f},
        {0.30f, 0.5f, 0.0f, 0.0f, 0.005f},
        {0.55f, 0.9f, 0.2f, 0.0f, 0.04f},
        {0.80f, 1.0f, 0.65f, 0.0f, 0.12f},
        {1.00f, 1.0f, 1.0f, 0.85f, 0.3f}}},
      // For magnitudes with heavy tails (vorticity, enstrophy): the bulk clear, the intense
      // structures from blue through green and yellow to red.
      {"turbulence",
       {{0.00f, 0.05f, 0.05f, 0.20f, 0.0f},
        {0.40f, 0.10f, 0.25f, 0.70f, 0.0f},
        {0.55f, 0.10f, 0.55f, 0.90f, 0.015f},
        {0.70f, 0.30f, 0.90f, 0.55f, 0.05f},
        {0.85f, 1.00f, 0.85f, 0.20f, 0.14f},
        {1.00f, 1.00f, 0.25f, 0.10f, 0.35f}}},
      {"transparent", {{0.0f, 0, 0, 0, 0}}},
  };
  return table;
}

void check_entries(int entries, const std::string& where) {
  if (entries < 2 || entries > 65536)
    throw InputError(where + ": expected 2 to 65536 table entries, found " +
                     std::to_string(entries));
}

/// A number that a float holds (values and ranges are floats, as the volume's values are).
double float_number(const nlohmann::json& value, const std::string& where) {
  constexpr double largest = std::numeric_limits<float>::max();
  return detail::number_in(value, -largest, largest, where);
}

void check_range(float lo, float hi, const std::string& where) {
  if (!(std::isfinite(lo) && std::isfinite(hi) && lo < hi))
    throw InputError(where + ": expected a finite range lo < hi, found [" +
                     format::number_text(lo) + ", " + format::number_text(hi) + "]");
}

}  // namespace

TransferFunction::TransferFunction() : TransferFunction({{0, 0, 0, 0, 0}}, 0, 1) {}

TransferFunction::TransferFunction(std::vector<ControlPoint> points, float lo, float hi,
                                   int entries)
    : points_(std::move(points)), lo_(lo), hi_(hi) {
  const std::string where = "transfer function";
  check_range(lo, hi, where);
  check_entries(entries, where);
  if (points_.empty()) throw InputError(where + ": expected at least one control point");
  for (std::size_t i = 0; i < points_.size(); ++i) {
    const ControlPoint& p = points_[i];
    if (!std::isfinite(p.value))
      throw InputError(where + ": point " + std::to_string(i) + ": value is not finite");
    for (float c : {p.r, p.g, p.b, p.a})
      if (!(c >= 0 && c <= 1))
        throw InputError(where + ": point " + std::to_string(i) +
                         ": expected r, g, b, a in [0, 1], found " + format::number_text(c));
    if (i > 0 && p.value < points_[i - 1].value)
      throw InputError(
          where + ": point " + std::to_string(i) + ": expected values in increasing order, found " +
          format::number_text(p.value) + " after " + format::number_text(points_[i - 1].value));
  }
  table_.resize(static_cast<std::size_t>(entries));
  for (int i = 0; i < entries; ++i) {
    const double v = double(lo) + (double(hi) - double(lo)) * i / (entries - 1);
    // First point with value > v; interpolate between it and the one before.
    const auto next =
        std::upper_bound(points_.begin(), points_.end(), v,
                         [](double x, const ControlPoint& p) { return x < double(p.value); });
    const ControlPoint& a = next == points_.begin() ? *next : *(next - 1);
    const ControlPoint& b = next == points_.end() ? *(next - 1) : *next;
    const double span = double(b.value) - double(a.value);
    const double w = span > 0 ? std::clamp((v - double(a.value)) / span, 0.0, 1.0) : 0.0;
    const auto mix = [w](float x, float y) {
      return static_cast<float>(double(x) + (double(y) - double(x)) * w);
    };
    table_[static_cast<std::size_t>(i)] = {mix(a.r, b.r), mix(a.g, b.g), mix(a.b, b.b),
                                           mix(a.a, b.a)};
  }
}

TransferFunction TransferFunction::from_quantiles(std::vector<float> values, float lo, float hi,
                                                  double path_voxels) {
  if (!(hi > lo) || values.empty()) return preset("cool-warm", lo, hi > lo ? hi : lo + 1);
  values.erase(
      std::remove_if(values.begin(), values.end(), [](float v) { return !std::isfinite(v); }),
      values.end());
  if (values.empty()) return preset("cool-warm", lo, hi);
  std::sort(values.begin(), values.end());
  const auto q = [&](double p) {
    const auto i = static_cast<std::size_t>(p * static_cast<double>(values.size() - 1));
    return std::clamp(values[i], lo, hi);
  };
  // 1. Which tails are structures: each tail's extent from the median against the other's. A
  //    tail shorter than half the other fades out, gone at a quarter.
  const double median = q(0.5);
  const double low_extent = median - double(q(0.001)), high_extent = double(q(0.999)) - median;
  const auto weight = [](double extent, double other) {
    if (!(other > 0)) return extent > 0 ? 1.0 : 0.0;
    return std::clamp((extent / other - 0.25) / 0.25, 0.0, 1.0);
  };
  const auto w_low = static_cast<float>(weight(low_extent, high_extent));
  const auto w_high = static_cast<float>(weight(high_extent, low_extent));
  // 2. Moreland's cool-warm ends, clear in between; opacity per voxel of ray.
  std::vector<ControlPoint> points = {{lo, 0.10f, 0.20f, 0.80f, 0.70f * w_low},
                                      {q(0.001), 0.15f, 0.35f, 0.95f, 0.45f * w_low},
                                      {q(0.01), 0.35f, 0.65f, 1.00f, 0.12f * w_low},
                                      {q(0.04), 0.60f, 0.80f, 1.00f, 0.0f},
                                      {q(0.96), 1.00f, 0.80f, 0.60f, 0.0f},
                                      {q(0.99), 1.00f, 0.55f, 0.25f, 0.05f * w_high},
                                      {q(0.999), 0.90f, 0.20f, 0.10f, 0.25f * w_high},
                                      {hi, 0.70f, 0.02f, 0.15f, 0.50f * w_high}};
  for (std::size_t i = 1; i < points.size(); ++i)
    points[i].value = std::max(points[i].value, points[i - 1].value);
  TransferFunction tf(points, lo, hi, 256);
  // 3. The average ray's optical depth: the mean extinction −ln(1 − α) per voxel over the
  //    sampled values times the path. Above the limit, every point's opacity becomes
  //    1 − (1 − α)^k, k found by bisection so that the table (which interpolates the points)
  //    gives the limit.
  constexpr double max_depth = 2.0;
  if (path_voxels > 0) {
    const std::size_t stride = std::max<std::size_t>(1, values.size() / 65536);
    const auto depth_of = [&](const TransferFunction& t) {
      double extinction = 0;
      std::size_t n = 0;
      for (std::size_t i = 0; i < values.size(); i += stride, ++n)
        extinction -= std::log1p(-std::min(double(t.lookup(values[i])[3]), 0.999999));
      return extinction / static_cast<double>(n) * path_voxels;
    };
    if (depth_of(tf) > max_depth) {
      const auto scaled = [&](double k) {
        std::vector<ControlPoint> p = points;
        for (ControlPoint& c : p) c.a = static_cast<float>(1.0 - std::pow(1.0 - double(c.a), k));
        return TransferFunction(std::move(p), lo, hi, 256);
      };
      double k_lo = 0, k_hi = 1;
      for (int i = 0; i < 40; ++i) {
        const double k = 0.5 * (k_lo + k_hi);
        (depth_of(scaled(k)) > max_depth ? k_hi : k_lo) = k;
      }
      tf = scaled(k_lo);
    }
  }
  return tf;
}

TransferFunction TransferFunction::preset(const std::string& name, float lo, float hi,
                                          float opacity, int entries) {
  const auto it = std::find_if(presets().begin(), presets().end(),
                               [&](const Preset& p) { return p.name == name; });
  if (it == presets().end()) {
    std::string list;
    for (const auto& p : preset_names()) list += (list.empty() ? "" : ", ") + p;
    throw InputError("transfer function: unknown preset \"" + name + "\" (known: " + list + ")");
  }
  if (!(opacity >= 0 && std::isfinite(opacity)))
    throw InputError("transfer function: expected an opacity scale ≥ 0, found " +
                     format::number_text(opacity));
  check_range(lo, hi, "transfer function preset \"" + name + "\"");
  std::vector<ControlPoint> points;
  for (const PresetPoint& p : it->points)
    points.push_back({lo + (hi - lo) * p.t, p.r, p.g, p.b, std::min(1.0f, p.a * opacity)});
  return TransferFunction(std::move(points), lo, hi, entries);
}

const std::vector<std::string>& TransferFunction::preset_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> list;
    for (const Preset& p : presets()) list.push_back(p.name);
    return list;
  }();
  return names;
}

TransferFunction TransferFunction::from_json(const nlohmann::json& json,
                                             std::array<float, 2> default_range,
                                             const std::string& where) {
  using namespace detail;
  object(json, where);
  only_known_keys(json, {"preset", "range", "points", "entries", "opacity"}, where);
  const bool has_preset = json.contains("preset"), has_points = json.contains("points");
  if (has_preset == has_points)
    fail_text(where, has_preset ? "give either \"preset\" or \"points\", not both"
                                : "expected a \"preset\" or \"points\" field");
  int entries = default_entries;
  if (json.contains("entries")) {
    const double e = number_in(json["entries"], 2, 65536, where + ".entries");
    if (e != std::floor(e)) fail(where + ".entries", "an integer", json["entries"]);
    entries = static_cast<int>(e);
  }
  std::array<float, 2> range = default_range;
  const bool has_range = json.contains("range");
  if (has_range) {
    const auto& r = json["range"];
    if (!r.is_array() || r.size() != 2) fail(where + ".range", "[lo, hi]", r);
    range = {static_cast<float>(float_number(r[0], where + ".range[0]")),
             static_cast<float>(float_number(r[1], where + ".range[1]"))};
    if (!(range[0] < range[1])) fail(where + ".range", "lo < hi", r);
  }
  if (has_preset) {
    const auto& p = json["preset"];
    if (!p.is_string()) fail(where + ".preset", "a preset name", p);
    const std::string name = p.get<std::string>();
    const auto& names = preset_names();
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string list;
      for (const auto& n : names) list += (list.empty() ? "" : ", ") + n;
      fail(where + ".preset", "one of " + list, p);
    }
    float opacity = 1;
    if (json.contains("opacity"))
      opacity = static_cast<float>(number_in(json["opacity"], 0, 1e6, where + ".opacity"));
    if (!(range[0] < range[1]))
      fail_text(where, "the default value range is empty; give a \"range\"");
    return preset(name, range[0], range[1], opacity, entries);
  }
  if (json.contains("opacity")) fail_text(where, "\"opacity\" applies to presets only");
  const auto& pts = json["points"];
  if (!pts.is_array() || pts.empty()) fail(where + ".points", "a non-empty array", pts);
  std::vector<ControlPoint> points;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    const std::string at = where + ".points[" + std::to_string(i) + "]";
    const auto& p = pts[i];
    if (!p.is_array() || p.size() != 5) fail(at, "[value, r, g, b, a]", p);
    ControlPoint c;
    c.value = static_cast<float>(float_number(p[0], at + "[0] (value)"));
    c.r = static_cast<float>(number_in(p[1], 0, 1, at + "[1] (r)"));
    c.g = static_cast<float>(number_in(p[2], 0, 1, at + "[2] (g)"));
    c.b = static_cast<float>(number_in(p[3], 0, 1, at + "[3] (b)"));
    c.a = static_cast<float>(number_in(p[4], 0, 1, at + "[4] (a)"));
    if (i > 0 && c.value < points.back().value)
      fail(at + "[0] (value)",
           "values in increasing order (≥ " + format_number(double(points.back().value)) + ")",
           p[0]);
    points.push_back(c);
  }
  if (!has_range) {
    range = {points.front().value, points.back().value};
    if (!(range[0] < range[1])) {
      // A single value (or all equal): a unit range around it.
      range = {points.front().value - 0.5f, points.front().value + 0.5f};
    }
  }
  return TransferFunction(std::move(points), range[0], range[1], entries);
}

nlohmann::json TransferFunction::to_json() const {
  nlohmann::json points = nlohmann::json::array();
  for (const ControlPoint& p : points_) points.push_back({p.value, p.r, p.g, p.b, p.a});
  return {{"range", {lo_, hi_}}, {"entries", entry_count()}, {"points", points}};
}

Rgba TransferFunction::lookup(float v) const {
  float t = (v - lo_) / (hi_ - lo_);
  if (!(t > 0)) t = 0;  // also NaN
  if (t > 1) t = 1;
  const float x = t * static_cast<float>(table_.size() - 1);
  const std::size_t i = std::min(static_cast<std::size_t>(x), table_.size() - 2);
  const float w = x - static_cast<float>(i);
  const Rgba& a = table_[i];
  const Rgba& b = table_[i + 1];
  return {a[0] + (b[0] - a[0]) * w, a[1] + (b[1] - a[1]) * w, a[2] + (b[2] - a[2]) * w,
          a[3] + (b[3] - a[3]) * w};
}

TransferFunction TransferFunction::opacity_corrected(double step_ratio) const {
  TransferFunction out = *this;
  for (Rgba& e : out.table_) {
    const double a = std::clamp(double(e[3]), 0.0, 1.0);
    e[3] = a >= 1 ? 1.0f : static_cast<float>(1.0 - std::pow(1.0 - a, step_ratio));
  }
  return out;
}

std::uint64_t TransferFunction::visible_bins(float value_min, float value_max) const {
  const std::size_t n = table_.size();
  const auto table_x = [&](double v) {
    const double t = std::clamp((v - double(lo_)) / (double(hi_) - double(lo_)), 0.0, 1.0);
    return t * double(n - 1);
  };
  const auto any_visible = [&](double x0, double x1) {
    const auto i0 = static_cast<std::size_t>(std::floor(x0));
    const auto i1 = std::min(n - 1, static_cast<std::size_t>(std::ceil(x1)));
    for (std::size_t i = i0; i <= i1; ++i)
      if (table_[i][3] > 0) return true;
    return false;
  };
  if (!(value_max > value_min))  // every value falls in bin 0 (format::histogram_bin)
    return any_visible(0, double(n - 1)) ? ~std::uint64_t{0} : 0;
  std::uint64_t mask = 0;
  const double width = (double(value_max) - double(value_min)) / 64.0;
  for (std::uint32_t b = 0; b < 64; ++b) {
    // Bin 0 also holds every value below the range, bin 63 every value above it.
    constexpr double infinity = std::numeric_limits<double>::infinity();
    const double v0 = b == 0 ? -infinity : double(value_min) + width * b;
    const double v1 = b == 63 ? infinity : double(value_min) + width * (b + 1);
    // One entry of margin on each side keeps the test conservative under float rounding.
    const double x0 = std::max(0.0, table_x(v0) - 1), x1 = std::min(double(n - 1), table_x(v1) + 1);
    if (any_visible(x0, x1)) mask |= std::uint64_t{1} << b;
  }
  return mask;
}

std::uint64_t TransferFunction::histogram_hull(std::uint64_t histogram) {
  if (histogram == 0) return 0;
  const int low = std::countr_zero(histogram), high = 63 - std::countl_zero(histogram);
  const std::uint64_t up_to_high =
      high == 63 ? ~std::uint64_t{0} : (std::uint64_t{1} << (high + 1)) - 1;
  return up_to_high & ~((std::uint64_t{1} << low) - 1);
}

bool TransferFunction::visible_hull(std::uint64_t histogram, float value_min,
                                    float value_max) const {
  return (histogram_hull(histogram) & visible_bins(value_min, value_max)) != 0;
}

TransferFunction TransferFunction::blend(const TransferFunction& a, const TransferFunction& b,
                                         float w) {
  if (w <= 0) return a;
  if (w >= 1) return b;
  TransferFunction out = w < 0.5f ? a : b;
  const std::size_t n = std::max(a.table_.size(), b.table_.size());
  out.lo_ = a.lo_ + (b.lo_ - a.lo_) * w;
  out.hi_ = a.hi_ + (b.hi_ - a.hi_) * w;
  out.table_.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    // Entry i of the blend sits at the same relative position in both tables.
    const auto sample = [&](const TransferFunction& f) {
      if (f.table_.size() == n) return f.table_[i];
      const float v = f.lo_ + (f.hi_ - f.lo_) * static_cast<float>(i) / static_cast<float>(n - 1);
      return f.lookup(v);
    };
    const Rgba x = sample(a), y = sample(b);
    for (std::size_t c = 0; c < 4; ++c) out.table_[i][c] = x[c] + (y[c] - x[c]) * w;
  }
  return out;
}

}  // namespace volreel::cpu_render
