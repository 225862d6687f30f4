// tour.hpp: a scripted tour of a container — camera moves, playback (play, reverse, seek, pause,
// or keyed playhead positions) and transfer-function changes over a fixed duration — replayed by
// `volreel render` (headless) and `volreel bench stream`. Tour::at(seconds) gives the camera, the
// playhead and the transfer function at any time.
//
// JSON (every time "t" in seconds from the start of the tour, in [0, duration]):
//   {
//     "duration": 12,                 seconds, > 0 (required)
//     "fps": 30,                      frames per second, > 0 (default 30)
//     "size": [512, 512],             image width and height in pixels, 1..16384 (default 512²)
//     "camera": [                     orbit-camera keys (default: one key, the framing camera)
//       {"t": 0, "azimuth": 34, "elevation": 26, "distance": 400, "target": [120, 20, 15],
//        "fov": 45},
//       {"t": 12, "azimuth": 394}     a field left out repeats the previous key's value; the
//     ],                              first key's missing fields come from the framing camera
//                                     azimuth, elevation, fov in degrees (elevation in (−90, 90),
//                                     fov in (0, 180)); distance (> 0) and target in voxels
//     "playhead": [                   playhead keys, in keyframe units (0 .. keyframes − 1)
//       {"t": 0, "keyframe": 0}, {"t": 6, "keyframe": 15.5}
//     ],
//     or "segments": [                playback, in order from "start" (default keyframe 0)
//       {"play": 4, "speed": 2},      forward for 4 s at 2 keyframes/s (speed default 1)
//       {"reverse": 2, "speed": 1},   backward; both stop (hold) at either end of the timeline
//       {"seek": 7.25},               jump to keyframe 7.25 at once
//       {"pause": 1}                  hold for 1 s
//     ],                              (neither given: the playhead stays at keyframe 0)
//     "transfer": [                   transfer-function keys (default: preset "cool-warm" over
//       {"t": 0, "preset": "fire"},   the container's value range); each key is a transfer
//       {"t": 8, "points": [[-1, 0, 0, 1, 0.1], [1, 1, 0, 0, 0.2]]}   function's JSON
//     ]                               (transfer_function.hpp) plus "t"
//   }
// Between keys every quantity is interpolated linearly (azimuth as given, so 34 → 394 is one
// full orbit; transfer functions entry by entry, TransferFunction::blend); before the first key
// and after the last it holds. Keys are in non-decreasing time; two keys at the same time make a
// cut. Unknown fields are errors, so a misspelt field is not silently ignored.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/format/container.hpp"
#include "volreel/player/camera.hpp"

namespace volreel::cpu_render {

/// What a tour needs to know about the container it tours.
struct TourContext {
  std::array<std::uint32_t, 3> dims{};     ///< finest level, voxels
  std::size_t keyframes = 1;               ///< frame count; playheads lie in [0, keyframes − 1]
  std::array<float, 2> value_range{0, 1};  ///< default transfer-function range (manifest)

  /// From a container's manifest: dims, frame count and value range (an empty range, a constant
  /// sequence, is widened to [v − 0.5, v + 0.5]).
  static TourContext of(const format::Manifest& manifest);
};

struct CameraKey {
  double time = 0;
  double azimuth = 0, elevation = 0;  ///< degrees
  double distance = 1;                ///< voxels
  glm::dvec3 target{0.0};             ///< voxels
  double fov = 45;                    ///< vertical, degrees
};
struct PlayheadKey {
  double time = 0;
  double keyframe = 0;
};
struct TransferKey {
  double time = 0;
  TransferFunction transfer;
};

/// Everything one rendered frame of a tour needs.
struct TourFrame {
  player::OrbitCamera camera;  ///< width and height = the tour's size
  double playhead = 0;         ///< keyframe units
  TransferFunction transfer;
};

class Tour {
 public:
  /// Parses and validates a tour (the format above). `name` (a file name) prefixes errors, which
  /// name the field: "tour.json: camera[2].t: expected a time ≥ 3 (the previous key's), found 1".
  /// Throws InputError.
  static Tour from_json(const nlohmann::json& json, const TourContext& context,
                        const std::string& name = "tour");
  /// The same from JSON text (syntax errors also throw InputError naming `name`).
  static Tour parse(const std::string& text, const TourContext& context,
                    const std::string& name = "tour");
  /// Reads and parses a file; errors name the file.
  static Tour load(const std::filesystem::path& path, const TourContext& context);

  /// The tour used when the user gives none: 12 s at 30 fps, 512²; plays forward through the
  /// whole timeline in 4 s, reverses for 2 s, seeks to a pseudo-random keyframe (from `seed`),
  /// pauses 1 s, plays in slow motion (interpolated states between keyframes) for 2 s, then
  /// holds; meanwhile the camera orbits once around the volume, rising and sinking.
  static Tour default_for(const TourContext& context, std::uint64_t seed = 1);

  /// The tour as JSON in the format above, with playback as "playhead" keys (segments are
  /// converted on parsing); from_json(to_json()) gives the same tour.
  nlohmann::json to_json() const;

  double duration() const { return duration_; }
  double fps() const { return fps_; }
  int width() const { return width_; }
  int height() const { return height_; }
  /// Frames rendered: ⌈duration·fps⌉, frame i at time i/fps.
  std::size_t frame_count() const;
  double frame_time(std::size_t frame) const { return static_cast<double>(frame) / fps_; }

  /// Camera, playhead and transfer function at `seconds` (clamped to [0, duration]).
  TourFrame at(double seconds) const;

  const std::vector<CameraKey>& camera_keys() const { return camera_; }
  const std::vector<PlayheadKey>& playhead_keys() const { return playhead_; }
  const std::vector<TransferKey>& transfer_keys() const { return transfer_; }

 private:
  double duration_ = 1, fps_ = 30;
  int width_ = 512, height_ = 512;
  std::vector<CameraKey> camera_;
  std::vector<PlayheadKey> playhead_;
  std::vector<TransferKey> transfer_;
};

}  // namespace volreel::cpu_render
