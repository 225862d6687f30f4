// priorities.hpp: pre-load priorities of keyframe nodes (Cesium patent [0041]–[0045];
// docs/design.md, "Streaming", step 1) and the view traversal they run on: frustum culling,
// screen-space error (SSE) and the refinement rule "descend while the node's SSE exceeds the
// target" ([0032], [0037]).
//
//   ssePriority      = SSE / (1 + SSE)                                                    [0042]
//   temporalPriority = (1 − |k − playhead| / maxDistance)^4, maxDistance = the larger distance
//                      from the playhead to either end of the timeline (keyframe units)  [0043]
//   randomPriority   = a ruler-like table: first, middle and last keyframe 1, then the middle of
//                      each half ½, recursively halving                                  [0044]
//   priority         = 10·ssePriority + lerp(random, temporal, lerp(0.15, 1, temporal))   [0045]
//
// Due window (volreel's request management, patent policy only; [0033], [0037]): the keyframe
// nodes the pre-render selection needs now — for each visited node, its keyframe nodes nearest the
// playhead on each side —, those the playhead reaches within `lookahead_s` seconds at its current
// velocity (play direction and speed), and the next one beyond the first two on each side (a step,
// a start of playback or a change of direction), are "due". A due keyframe node's priority is
//   due_priority = sse_weight + 2 − s/(s + lookahead_s) ∈ (sse_weight + 1, sse_weight + 2]
// (s: seconds until the playhead reaches it, 0 for the two around the playhead), above every [0045]
// priority (< sse_weight + 1). So the heap always holds them and they are requested first, the
// soonest needed first and, for one time step, coarser levels first (the heap's tie rule); every
// other keyframe node ("speculative") keeps its [0045] priority and gets the link time the due
// window leaves (SchedulerSettings::speculative_link_s). Without it the 10·ssePriority term puts
// the coarse levels of every keyframe of the timeline — and the fine bricks near the camera of far
// keyframes — ahead of the fine bricks the current frame draws, and a full heap can even leave
// out fine bricks of the keyframes at the playhead.
// The nearest-keyframe-first baseline has no due window (it is the temporal order already).
//
// SSE of a level (volreel's reading of [0042], SseScope::level, the default): ssePriority is
// computed from the largest SSE among the visited nodes of the keyframe node's level, not from
// the node's own SSE. With the node's own SSE the spread within one level (a nearer node projects
// its voxels larger: 0.5 to 2 pixels for the finest level of a typical view, 3.3 to 6.7 after the
// factor 10) outweighs the temporal and random terms (at most 1), so once the heap is full it
// holds the near-camera fine bricks of every keyframe of the timeline and no keyframe whole: a
// seek anywhere finds its time step only partly detailed, which looks worse than a whole
// keyframe or a coarse level. With one SSE per level the levels keep their order (coarser levels
// project larger voxels: the coarse levels of the whole timeline still come first), and within a
// level whole keyframes are kept, by the temporal and random terms.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "volreel/player/camera.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {

enum class PriorityPolicy {
  patent,                  ///< [0045]: SSE, temporal and random priorities combined
  nearest_keyframe_first,  ///< baseline: temporal priority only (nearest the playhead first)
};

/// Which SSE the patent policy's ssePriority is computed from (see above).
enum class SseScope {
  node,   ///< the keyframe node's spatial node ([0042] literally)
  level,  ///< the largest SSE among this frame's visited nodes of the same level
};

struct PrioritySettings {
  PriorityPolicy policy = PriorityPolicy::patent;
  double sse_target = 1.0;         ///< pixels per voxel at which a node is detailed enough [0030]
  double sse_weight = 10.0;        ///< factor of ssePriority in the combined priority
  double temporal_exponent = 4.0;  ///< exponent of temporalPriority
  /// lerp(min, 1, temporal): weight of temporal vs random. [0045] uses 0.15; volreel's default 1
  /// (the temporal priority alone, nearest in time first within a level): with the image metric,
  /// the partial or interpolated time steps the ruler keeps far from the playhead look little
  /// better than the coarse levels, and cost whole keyframes next to it (measured with
  /// `volreel bench stream`: docs/benchmarks.md, "Streaming").
  double temporal_lerp_min = 1.0;
  /// Patent policy: the due window (see above). false: every keyframe node by [0045] alone.
  bool due_window = true;
  /// Due window: seconds of playback ahead of the playhead (at its current velocity) whose
  /// keyframes are due; the two keyframes around the playhead are always due.
  double lookahead_s = 1.0;
  /// Patent policy: the SSE behind ssePriority (see above).
  SseScope sse_scope = SseScope::level;
  /// A restricted working set (Thiele, Matthes, Froehlich §4.1; ViewTraversal): the view's target
  /// nodes that touch differ by at most one level.
  bool restricted = true;
};

/// [0044]: the ruler-like table for `keyframes` time steps. 9 keyframes give exactly
/// [1, .25, .5, .25, 1, .25, .5, .25, 1].
std::vector<double> random_selection_table(std::size_t keyframes);

/// [0042]: SSE / (1 + SSE), in [0, 1).
double sse_priority(double sse);
/// [0043]: (1 − |keyframe − playhead| / maxDistance)^exponent with maxDistance = max(playhead,
/// keyframes − 1 − playhead); 1 when the timeline has a single keyframe.
double temporal_priority(double keyframe, double playhead, std::size_t keyframes,
                         double exponent = 4.0);
/// [0045]: sse_weight·ssePriority + lerp(random, temporal, lerp(lerp_min, 1, temporal)), or the
/// temporal priority alone for PriorityPolicy::nearest_keyframe_first.
double combined_priority(double sse_priority_value, double temporal_priority_value,
                         double random_priority_value, const PrioritySettings& settings);

/// A keyframe node that can be due: its time step, and the seconds until the playhead needs it.
struct DueTime {
  std::uint32_t t = 0;
  double seconds = 0;
  friend bool operator==(const DueTime&, const DueTime&) = default;
};

/// Due window for one spatial node's held time steps: the keyframe nodes that the playhead at
/// `playhead` moving at `velocity` keyframes per second (negative: backwards) needs soon, by
/// ascending t, with the seconds until it does — 0 for the last time step ≤ playhead and the
/// first ≥ playhead; (t − playhead)/velocity for those the playhead reaches within lookahead_s;
/// lookahead_s for the next one beyond those two on each side (where a step, a start of playback
/// or a change of direction goes first). The others are not due.
void due_times(const HeldTimes& times, double playhead, double velocity, double lookahead_s,
               std::vector<DueTime>& due);
/// The priority of a due keyframe node needed in `seconds` (see above): in
/// (settings.sse_weight + 1, settings.sse_weight + 2], decreasing with seconds.
double due_priority(double seconds, const PrioritySettings& settings);

/// Axis-aligned box in world space (finest voxels), [lo, hi).
struct Box {
  glm::dvec3 lo{0.0}, hi{0.0};
};
Box node_box(const SpatialNode& node);

/// The six planes of the camera's view frustum; a box is culled when it lies wholly outside one.
class Frustum {
 public:
  explicit Frustum(const player::OrbitCamera& camera);
  bool intersects(const Box& box) const;

 private:
  std::array<glm::dvec4, 6> planes_{};
};

/// Distance from point p to the box (0 inside).
double distance_to_box(const glm::dvec3& p, const Box& box);
/// Screen-space error of a node: the projected size in pixels of one of its voxels at the node's
/// nearest distance from the eye (OrbitCamera::projected_pixels).
double node_sse(const SpatialIndex& index, std::uint32_t node, const player::OrbitCamera& camera);

/// One frame's walk of the spatial octree: from the root, every node in the frustum is visited,
/// and its children too while its SSE exceeds the target. Results are per node (frame-stamped, so
/// nothing is cleared between frames).
///
/// Restricted (Thiele, Matthes, Froehlich §4.1): the target nodes — visited and not refined —
/// that touch (by a face, an edge or a corner) differ by at most one level, so that a boundary
/// between levels of detail is one level step, which blending can hide. Where a target node N at
/// level d touches a region whose target node is coarser than d − 1, that coarser node is refined
/// too ("forced split"), and the walk runs again, until no target node has such a neighbour. The
/// paper's split condition ("split N only once its neighbours are fine enough") in the order of a
/// walk: N keeps its refinement, and its coarse neighbours follow. A node that has no children
/// (its region constant in every held frame: exact at its level) and regions outside the frustum
/// (never drawn) impose nothing and are never refined.
class ViewTraversal {
 public:
  struct Visit {
    std::uint32_t node = no_node;
    double sse = 0;
    /// The node has children and its SSE exceeds the target (or the restriction forces it): its
    /// children are visited.
    bool refine = false;
    bool forced = false;  ///< refined for the restriction alone (its SSE meets the target)
  };

  /// Walks the index for the camera; visits are in depth-first preorder.
  void run(const SpatialIndex& index, const player::OrbitCamera& camera, double sse_target,
           bool restricted = false);
  /// Refined by the restriction alone, this frame.
  std::size_t forced_count() const { return forced_list_.size(); }

  std::span<const Visit> visits() const { return visits_; }
  bool visited(std::uint32_t node) const {
    return node < stamp_.size() && stamp_[node] == generation_;
  }
  /// Precondition: visited(node).
  const Visit& visit(std::uint32_t node) const { return visits_[where_[node]]; }

 private:
  /// One walk from the root, refining where the SSE exceeds the target or forced_ is set.
  void walk(const SpatialIndex& index, const Frustum& frustum, const player::OrbitCamera& camera,
            double sse_target);
  /// Marks in forced_ the target nodes coarser than a touching target node's level − 1; returns
  /// whether it marked any.
  bool force_splits(const SpatialIndex& index);

  std::vector<Visit> visits_;
  std::vector<std::uint32_t> stamp_, where_;
  std::uint32_t generation_ = 0;
  std::vector<std::uint8_t> forced_;        ///< per node: refined for the restriction
  std::vector<std::uint32_t> forced_list_;  ///< the nodes forced_ marks
};

}  // namespace volreel::stream
