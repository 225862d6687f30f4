// playhead.cpp: play, pause, reverse, speed, seek, step and advance on a timeline of keyframes.
#include "volreel/stream/playhead.hpp"

#include <algorithm>
#include <cmath>

namespace volreel::stream {

Playhead::Playhead(std::size_t keyframes, PlayheadOptions options)
    : options_(options), last_(keyframes > 0 ? static_cast<double>(keyframes - 1) : 0.0) {}

void Playhead::set_speed(double speed) {
  speed_ = std::isfinite(speed) ? std::clamp(speed, min_speed, max_speed) : 1.0;
}

double Playhead::wrap(double t) const {
  if (!(last_ > 0)) return 0;
  const double w = std::fmod(t, last_);
  return w < 0 ? w + last_ : w;
}

void Playhead::seek(double t) {
  if (!std::isfinite(t)) return;
  if (options_.loop && (t < 0 || t > last_))
    position_ = wrap(t);
  else
    position_ = std::clamp(t, 0.0, last_);
}

void Playhead::step(int keyframes) {
  playing_ = false;
  seek(std::round(position_) + keyframes);
}

double Playhead::advance(double dt_seconds) {
  if (!playing_ || !(dt_seconds > 0)) return position_;
  const double delta = dt_seconds * options_.keyframes_per_second * speed_ * (reversed_ ? -1 : 1);
  const double t = position_ + delta;
  if (options_.loop) {
    position_ = (t < 0 || t > last_) ? wrap(t) : t;
  } else if (t <= 0 || t >= last_) {
    position_ = std::clamp(t, 0.0, last_);
    playing_ = false;  // stopped at the end, like a video player
  } else {
    position_ = t;
  }
  return position_;
}

}  // namespace volreel::stream
