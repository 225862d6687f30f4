// resolution_control.cpp: frame-time control (see resolution_control.hpp).
#include "volreel/loop/resolution_control.hpp"
#include "volreel/format/error.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace volreel::loop {
namespace {

constexpr double step = 1.0 / 16;
constexpr std::size_t kept_samples = 12;

}  // namespace

ResolutionControl::ResolutionControl(ResolutionSettings settings) : settings_(settings) {
  if (!(settings_.frame_ms > 0) || !std::isfinite(settings_.frame_ms))
    throw std::invalid_argument("frame-time target: expected milliseconds > 0, found " +
                                format::number_text(settings_.frame_ms));
  if (!(settings_.min_scale > 0) || settings_.min_scale > 1)
    throw std::invalid_argument("smallest resolution scale: expected a value in (0, 1], found " +
                                format::number_text(settings_.min_scale));
  // Until a frame is measured, half the side: a quarter of the pixels.
  busy_scale_ = std::max(0.5, settings_.min_scale);
}

double ResolutionControl::predict(double scale) const {
  return fixed_ms_ + per_full_frame_ms_ * scale * scale;
}

void ResolutionControl::measured(double scale, double frame_ms) {
  if (!(scale > 0) || !std::isfinite(frame_ms) || frame_ms < 0) return;
  samples_.emplace_back(scale * scale, frame_ms);
  if (samples_.size() > kept_samples) samples_.pop_front();
  fit();
}

void ResolutionControl::fit() {
  // Least squares of ms = fixed + per · s² over the kept samples; with one scale only (or a
  // negative slope from noise), the whole time is taken to scale with the pixels, which only
  // overestimates what a smaller image saves until a second scale is measured.
  const double n = static_cast<double>(samples_.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const auto& [x, y] : samples_) {
    sx += x;
    sy += y;
    sxx += x * x;
    sxy += x * y;
  }
  const double variance = sxx - sx * sx / n;
  double per = 0, fixed = 0;
  if (variance > 1e-6 * std::max(sxx, 1e-12)) {
    per = (sxy - sx * sy / n) / variance;
    fixed = (sy - per * sx) / n;
  }
  if (per <= 0 || fixed < 0) {
    fixed = 0;
    per = sy / std::max(sx, 1e-12);
  }
  fixed_ms_ = fixed;
  per_full_frame_ms_ = per;
}

double ResolutionControl::next(bool busy) {
  if (!busy) return scale_ = 1.0;
  if (!samples_.empty()) {
    const double target = settings_.frame_ms;
    const double predicted = predict(busy_scale_);
    const bool too_slow = predicted > target * (1 + settings_.tolerance);
    const bool too_fast = predicted < target * (1 - settings_.tolerance) && busy_scale_ < 1.0;
    if (too_slow || too_fast) {
      // The largest step whose prediction fits the target; the smallest allowed if none does.
      const double lowest = std::ceil(settings_.min_scale / step - 1e-9) * step;
      double best = std::min(lowest, 1.0);
      for (double s = 1.0; s >= lowest - 1e-9; s -= step)
        if (predict(s) <= target) {
          best = s;
          break;
        }
      if (too_slow || best > busy_scale_) busy_scale_ = std::max(best, settings_.min_scale);
    }
  }
  return scale_ = busy_scale_;
}

std::pair<int, int> scaled_size(int width, int height, double scale) {
  const auto side = [scale](int n) {
    return std::max(1, static_cast<int>(std::lround(static_cast<double>(n) * scale)));
  };
  return {side(width), side(height)};
}

}  // namespace volreel::loop
