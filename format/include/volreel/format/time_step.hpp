// time_step.hpp: a time step of a container as the player draws it. A frame file need not hold a
// brick for every node (format/SPEC.md, "Keyframes"): a node without one at step t takes the
// linear interpolation, by time step, between its states at the nearest steps before and after t
// that store it — its own brick there, or the constant of an empty ancestor —
//   value = (1 − f)·A + f·B,  f = (t − s) / (u − s)  (float32)
// which is what the ray casters compute between two keyframe nodes (svo_layout.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <span>

#include "volreel/format/container.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::format {

/// Where a node's state at one time step comes from.
struct StoredState {
  std::size_t t = 0;               ///< the time step that stores it
  std::uint32_t brick = no_brick;  ///< the node's brick in frame t, or no_brick for a constant
  float constant = 0;              ///< the empty ancestor's value (brick == no_brick)
};

/// A node's value at a time step: one stored state (f = 0), or two to interpolate.
struct NodeSource {
  StoredState a, b;
  float factor = 0;  ///< value = (1 − factor)·A + factor·B
  bool interpolated = false;
};

/// Decodes time steps of a series of frame files, opening the frames a step's interpolated nodes
/// need (a few kept open for the next step).
class TimeStepDecoder {
 public:
  /// Maps and validates frame t (throws FormatError).
  using Opener = std::function<FrameFile(std::size_t t)>;
  /// frame_count: time steps; max_gap: the most steps between two stored states of a node (the
  /// manifest's max_keyframe_gap, ≥ 1); atoms: the dictionary (ksvd).
  TimeStepDecoder(std::size_t frame_count, std::uint32_t max_gap, AtomTable atoms, Opener opener);
  /// Decodes the container's time steps (Container::open_frame checks each frame).
  explicit TimeStepDecoder(const Container& container);

  /// Level `level` (0 = root .. levels − 1 = full resolution) of time step t into out (the level's
  /// size). Parallel (OpenMP) over bricks. Throws FormatError on a bad payload or a node whose
  /// stored states are missing.
  void decode(std::size_t t, std::uint32_t level, std::span<float> out);
  LevelVolume decode(std::size_t t, std::uint32_t level);
  /// Where node i of frame t takes its value from. Throws FormatError naming frame t's file and
  /// the node when a node without a brick has no stored state within max_gap on a side.
  NodeSource source(std::size_t t, std::uint32_t node);
  /// Checks source() of every node without a brick at step t.
  void check_keyframes(std::size_t t);
  /// Frame t, opened once and kept while steps near it are decoded.
  const FrameView& frame(std::size_t t);
  std::size_t frame_count() const { return frame_count_; }

 private:
  std::size_t frame_count_;
  std::uint32_t max_gap_;
  AtomTable atoms_;
  Opener opener_;
  std::map<std::size_t, FrameFile> open_;
  /// The state of the node at position p stored at the nearest step from `from` in `direction`
  /// (−1 or +1), within max_gap steps of `from`.
  StoredState stored_state(std::size_t from, const NodePosition& p, int direction,
                           const FrameView& origin, std::uint32_t node);
  void forget_frames_far_from(std::size_t t);
};

/// Decodes one stored state into out (S³ values, the frame's brick size): the brick, or the
/// constant everywhere.
void decode_state(const FrameView& frame, const StoredState& state, const AtomTable& atoms,
                  std::span<float> out);

}  // namespace volreel::format
