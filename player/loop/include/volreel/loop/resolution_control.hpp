// resolution_control.hpp: frame-time control of the player (as ParaView and OSPRay do while a
// user interacts). While the view is busy — the camera moves, the playhead runs, or what the view
// needs is still streaming in — the volume is rendered at a reduced resolution chosen so that a
// frame takes about `frame_ms`, and scaled up for display; once the view is still, one frame at
// full resolution refines it.
//
// The cost model: a frame at scale s (image side relative to the output) costs about
// fixed + per_pixel · s², the fixed part being the scheduler, the decode and the presentation.
// The controller keeps an estimate of both from the frames it measures at different scales (a
// least-squares fit over the recent ones, so neither a single slow frame nor a constant overhead
// misleads it) and picks the largest scale whose predicted time fits the target. Scales move in
// steps of 1/16 and only when the prediction misses the target by more than a tolerance, so the
// image size does not change every frame (each change re-creates the output image).
#pragma once

#include <cstddef>
#include <deque>
#include <utility>

namespace volreel::loop {

struct ResolutionSettings {
  double frame_ms = 100;     ///< target frame time while the view is busy, milliseconds (> 0)
  double min_scale = 0.125;  ///< smallest scale of the image side, (0, 1]
  /// A busy scale is changed only when its predicted frame time is off the target by more than
  /// this fraction (either way).
  double tolerance = 0.2;
};

class ResolutionControl {
 public:
  explicit ResolutionControl(ResolutionSettings settings = {});

  /// The scale of the next frame: full (1) when the view is still, else the largest step of 1/16
  /// (not below min_scale) whose predicted frame time fits frame_ms.
  double next(bool busy);
  /// The measured time of the frame rendered at `scale`, milliseconds.
  void measured(double scale, double frame_ms);

  /// The scale next() returned last.
  double scale() const { return scale_; }
  /// Predicted frame time at `scale`, milliseconds (the fit; 0 before any measurement).
  double predict(double scale) const;
  const ResolutionSettings& settings() const { return settings_; }

 private:
  ResolutionSettings settings_;
  double scale_ = 1.0;
  double busy_scale_ = 1.0;  ///< the scale used while busy (kept across still periods)
  double fixed_ms_ = 0, per_full_frame_ms_ = 0;    ///< the cost model
  std::deque<std::pair<double, double>> samples_;  ///< (s², ms) of recent frames
  void fit();
};

/// The image size for `scale` of an output of width × height (each side ≥ 1, rounded).
std::pair<int, int> scaled_size(int width, int height, double scale);

}  // namespace volreel::loop
