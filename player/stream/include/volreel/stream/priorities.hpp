// priorities.hpp: pre-load priorities of keyframe nodes (Cesium patent [0041]–[0045]; DESIGN.md
// "Player", step 1) and the view traversal they run on: frustum culling, screen-space error (SSE)
// and the refinement rule "descend while the node's SSE exceeds the target" ([0032], [0037]).
//
//   ssePriority      = SSE / (1 + SSE)                                                    [0042]
//   temporalPriority = (1 − |k − playhead| / maxDistance)^4, maxDistance = the larger distance
//                      from the playhead to either end of the timeline (keyframe units)  [0043]
//   randomPriority   = a ruler-like table: first, middle and last keyframe 1, then the middle of
//                      each half ½, recursively halving                                  [0044]
//   priority         = 10·ssePriority + lerp(random, temporal, lerp(0.15, 1, temporal))   [0045]
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

struct PrioritySettings {
  PriorityPolicy policy = PriorityPolicy::patent;
  double sse_target = 1.0;          ///< pixels per voxel at which a node is detailed enough [0030]
  double sse_weight = 10.0;         ///< factor of ssePriority in the combined priority
  double temporal_exponent = 4.0;   ///< exponent of temporalPriority
  double temporal_lerp_min = 0.15;  ///< lerp(min, 1, temporal): weight of temporal vs random
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
class ViewTraversal {
 public:
  struct Visit {
    std::uint32_t node = no_node;
    double sse = 0;
    bool refine = false;  ///< SSE > target and the node has children: its children are visited
  };

  /// Walks the index for the camera; visits are in depth-first preorder.
  void run(const SpatialIndex& index, const player::OrbitCamera& camera, double sse_target);

  std::span<const Visit> visits() const { return visits_; }
  bool visited(std::uint32_t node) const {
    return node < stamp_.size() && stamp_[node] == generation_;
  }
  /// Precondition: visited(node).
  const Visit& visit(std::uint32_t node) const { return visits_[where_[node]]; }

 private:
  std::vector<Visit> visits_;
  std::vector<std::uint32_t> stamp_, where_;
  std::uint32_t generation_ = 0;
};

}  // namespace volreel::stream
