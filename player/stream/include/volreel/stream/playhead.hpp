// playhead.hpp: the timeline's playhead, in keyframe units (time step t at position t), with the
// controls of a video player: play, pause, reverse, speed (0.25×–8×), seek and step. advance()
// moves it by the wall-clock time of a rendered frame; at either end it stops there (clamped) or
// wraps around (looping).
#pragma once

#include <array>
#include <cstddef>

namespace volreel::stream {

struct PlayheadOptions {
  double keyframes_per_second = 10.0;  ///< playback rate at speed 1×
  bool loop = false;                   ///< wrap around at the ends instead of stopping there
};

class Playhead {
 public:
  static constexpr double min_speed = 0.25, max_speed = 8.0;

  /// keyframes: time steps of the timeline (≥ 1); the playhead lies in [0, keyframes − 1].
  explicit Playhead(std::size_t keyframes, PlayheadOptions options = {});

  double position() const { return position_; }
  double last() const { return last_; }
  bool playing() const { return playing_; }
  bool reversed() const { return reversed_; }
  double speed() const { return speed_; }
  const PlayheadOptions& options() const { return options_; }
  void set_loop(bool loop) { options_.loop = loop; }

  void play() { playing_ = true; }
  void pause() { playing_ = false; }
  void toggle() { playing_ = !playing_; }
  /// Plays backwards (true) or forwards (false).
  void set_reversed(bool reversed) { reversed_ = reversed; }
  void reverse() { reversed_ = !reversed_; }
  /// Clamped to [0.25, 8].
  void set_speed(double speed);
  /// Moves to time t (keyframe units), clamped to the timeline (wrapped when looping).
  void seek(double t);
  /// Pauses and moves `keyframes` whole keyframes from the nearest keyframe (negative: back).
  void step(int keyframes);
  /// Advances by dt seconds of wall-clock time when playing. At an end: stops there and pauses
  /// unless looping, in which case it wraps around. Returns the new position.
  double advance(double dt_seconds);

 private:
  PlayheadOptions options_;
  double last_;
  double position_ = 0;
  double speed_ = 1;
  bool playing_ = false, reversed_ = false;

  double wrap(double t) const;
};

/// The playhead's velocity (keyframes per second, negative backwards) as seen by a consumer that
/// only gets its positions, one per rendered frame: the median of the last three finite
/// differences, so that a seek (one huge difference) does not read as fast playback, while playback
/// at any speed, reverse and pauses are followed within two frames (before three differences: the
/// first difference, then the smaller of the two). The scheduler's due window uses it
/// (priorities.hpp).
class PlayheadMotion {
 public:
  /// A position at time `seconds` (non-decreasing); returns the velocity estimate. Observations at
  /// the same time as the previous one change nothing.
  double observe(double seconds, double position);
  double velocity() const { return velocity_; }

 private:
  std::array<double, 3> recent_{};  ///< the last finite differences, oldest first
  std::size_t count_ = 0;           ///< differences seen (saturates at 3)
  double last_time_ = 0, last_position_ = 0;
  bool has_last_ = false;
  double velocity_ = 0;
};

}  // namespace volreel::stream
