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

double PlayheadMotion::observe(double seconds, double position) {
  if (!std::isfinite(seconds) || !std::isfinite(position)) return velocity_;
  if (!has_last_) {
    has_last_ = true;
    last_time_ = seconds;
    last_position_ = position;
    return velocity_;
  }
  const double dt = seconds - last_time_;
  if (!(dt > 0)) {
    last_position_ = position;  // same instant: the newest position, no new difference
    return velocity_;
  }
  const double v = (position - last_position_) / dt;
  last_time_ = seconds;
  last_position_ = position;
  recent_ = {recent_[1], recent_[2], v};
  count_ = std::min<std::size_t>(count_ + 1, 3);
  if (count_ < 3) {
    // Fewer than three differences: the first one (playback usually starts with the first
    // frames), then the one of smaller magnitude (a seek is not read as fast playback).
    const double smaller = std::abs(recent_[1]) < std::abs(recent_[2]) ? recent_[1] : recent_[2];
    velocity_ = count_ == 1 ? v : smaller;
    return velocity_;
  }
  std::array<double, 3> sorted = recent_;
  std::sort(sorted.begin(), sorted.end());
  velocity_ = sorted[1];
  return velocity_;
}

}  // namespace volreel::stream
