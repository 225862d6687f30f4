// priorities.cpp: pre-load priorities (Cesium patent [0042]–[0045]), frustum culling and the
// SSE-driven view traversal.
#include "volreel/stream/priorities.hpp"

#include <algorithm>
#include <cmath>

namespace volreel::stream {

namespace {

void fill_ruler(std::vector<double>& table, std::size_t lo, std::size_t hi, double priority) {
  if (hi - lo < 2) return;
  const std::size_t mid = lo + (hi - lo) / 2;
  table[mid] = priority;
  fill_ruler(table, lo, mid, priority / 2);
  fill_ruler(table, mid, hi, priority / 2);
}

double lerp(double a, double b, double f) {
  return a + (b - a) * f;
}

}  // namespace

std::vector<double> random_selection_table(std::size_t keyframes) {
  std::vector<double> table(keyframes, 0.0);
  if (keyframes == 0) return table;
  // First, middle and last 1.0; each half's middle 0.5; and so on ([0044]).
  table.front() = 1.0;
  table.back() = 1.0;
  fill_ruler(table, 0, keyframes - 1, 1.0);
  return table;
}

double sse_priority(double sse) {
  return sse / (1.0 + sse);
}

double temporal_priority(double keyframe, double playhead, std::size_t keyframes, double exponent) {
  const double last = keyframes > 0 ? static_cast<double>(keyframes - 1) : 0.0;
  const double max_distance = std::max(playhead, last - playhead);
  if (!(max_distance > 0)) return 1.0;
  const double closeness = std::clamp(1.0 - std::abs(keyframe - playhead) / max_distance, 0.0, 1.0);
  return std::pow(closeness, exponent);
}

double combined_priority(double sse_priority_value, double temporal_priority_value,
                         double random_priority_value, const PrioritySettings& settings) {
  if (settings.policy == PriorityPolicy::nearest_keyframe_first) return temporal_priority_value;
  return settings.sse_weight * sse_priority_value +
         lerp(random_priority_value, temporal_priority_value,
              lerp(settings.temporal_lerp_min, 1.0, temporal_priority_value));
}

std::size_t due_range(const KeyframeList& keyframes, double playhead, double velocity,
                      double lookahead_s, std::vector<double>& seconds) {
  seconds.clear();
  const std::span<const std::uint32_t> times = keyframes.times();
  if (times.empty()) return 0;
  // The last time step ≤ playhead and the first ≥ playhead (the pre-render selection's picks).
  const auto after = std::lower_bound(times.begin(), times.end(), playhead,
                                      [](std::uint32_t t, double p) { return t < p; });
  const auto n = static_cast<std::ptrdiff_t>(times.size());
  const auto i_after = static_cast<std::ptrdiff_t>(after - times.begin());
  // On a keyframe it is both sides' pick.
  const bool on_keyframe =
      i_after < n && static_cast<double>(times[static_cast<std::size_t>(i_after)]) == playhead;
  const std::ptrdiff_t i_before = on_keyframe ? i_after : i_after - 1;
  // Those the playhead reaches within the lookahead, in its direction of travel: [first, last]
  // of the keyframe nodes that can be due.
  const double reach = velocity * std::max(0.0, lookahead_s);
  const bool reaching = std::abs(reach) > 0 && std::isfinite(reach);
  std::ptrdiff_t first = i_before - 1, last = i_after + 1;
  if (reaching && reach > 0) {
    const auto end = std::upper_bound(after, times.end(), playhead + reach,
                                      [](double v, std::uint32_t t) { return v < t; });
    last = std::max(last, static_cast<std::ptrdiff_t>(end - times.begin()) - 1);
  } else if (reaching) {
    const auto begin = std::lower_bound(times.begin(), after, playhead + reach,
                                        [](std::uint32_t t, double v) { return t < v; });
    first = std::min(first, static_cast<std::ptrdiff_t>(begin - times.begin()));
  }
  first = std::max<std::ptrdiff_t>(first, 0);
  last = std::min(last, n - 1);
  if (last < first) return 0;
  seconds.assign(static_cast<std::size_t>(last - first + 1), -1.0);
  const auto mark = [&](std::ptrdiff_t i, double s) {
    if (i >= first && i <= last && seconds[static_cast<std::size_t>(i - first)] < 0)
      seconds[static_cast<std::size_t>(i - first)] = s;
  };
  mark(i_before, 0);
  mark(i_after, 0);
  if (reaching)
    for (std::ptrdiff_t i = first; i <= last; ++i) {
      const double d = static_cast<double>(times[static_cast<std::size_t>(i)]) - playhead;
      if (d != 0 && (d > 0) == (reach > 0) && std::abs(d) <= std::abs(reach))
        mark(i, std::abs(d / velocity));
    }
  // The next one beyond those on each side, where a step, a start of playback or a change of
  // direction goes first: due last (as if needed at the end of the lookahead).
  const double at_end = std::max(0.0, lookahead_s);
  mark(i_before - 1, at_end);
  mark(i_after + 1, at_end);
  return static_cast<std::size_t>(first);
}

void due_seconds(const KeyframeList& keyframes, double playhead, double velocity,
                 double lookahead_s, std::vector<double>& seconds) {
  std::vector<double> range;
  const std::size_t first = due_range(keyframes, playhead, velocity, lookahead_s, range);
  seconds.assign(keyframes.size(), -1.0);
  std::copy(range.begin(), range.end(), seconds.begin() + static_cast<std::ptrdiff_t>(first));
}

double due_priority(double seconds, const PrioritySettings& settings) {
  const double s = std::max(0.0, seconds);
  const double horizon = settings.lookahead_s > 0 ? settings.lookahead_s : 1.0;
  return settings.sse_weight + 2.0 - s / (s + horizon);
}

Box node_box(const SpatialNode& node) {
  return {glm::dvec3(node.lo[0], node.lo[1], node.lo[2]),
          glm::dvec3(node.hi[0], node.hi[1], node.hi[2])};
}

Frustum::Frustum(const player::OrbitCamera& camera) {
  // Gribb and Hartmann: the planes are sums and differences of the rows of projection · view.
  const glm::dmat4 m = camera.projection() * camera.view();
  const auto row = [&](int r) { return glm::dvec4(m[0][r], m[1][r], m[2][r], m[3][r]); };
  planes_ = {row(3) + row(0), row(3) - row(0), row(3) + row(1),
             row(3) - row(1), row(3) + row(2), row(3) - row(2)};
}

bool Frustum::intersects(const Box& box) const {
  for (const glm::dvec4& p : planes_) {
    // The corner farthest along the plane's normal.
    const glm::dvec3 corner{p.x >= 0 ? box.hi.x : box.lo.x, p.y >= 0 ? box.hi.y : box.lo.y,
                            p.z >= 0 ? box.hi.z : box.lo.z};
    if (p.x * corner.x + p.y * corner.y + p.z * corner.z + p.w < 0) return false;
  }
  return true;
}

double distance_to_box(const glm::dvec3& p, const Box& box) {
  const glm::dvec3 nearest = glm::clamp(p, box.lo, box.hi);
  return glm::length(p - nearest);
}

double node_sse(const SpatialIndex& index, std::uint32_t node, const player::OrbitCamera& camera) {
  const SpatialNode& n = index.node(node);
  const double depth = distance_to_box(camera.eye(), node_box(n));
  return camera.projected_pixels(static_cast<double>(index.voxel_size(n.key.level)), depth);
}

void ViewTraversal::run(const SpatialIndex& index, const player::OrbitCamera& camera,
                        double sse_target) {
  visits_.clear();
  if (stamp_.size() != index.node_count()) {
    stamp_.assign(index.node_count(), 0);
    where_.assign(index.node_count(), 0);
    generation_ = 0;
  }
  if (++generation_ == 0) {  // wrapped: clear the stamps
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    generation_ = 1;
  }
  if (index.node_count() == 0 || !index.node(0).present()) return;
  const Frustum frustum(camera);
  // Depth-first preorder with an explicit stack (children pushed in reverse octant order).
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const std::uint32_t id = stack.back();
    stack.pop_back();
    const SpatialNode& n = index.node(id);
    if (!frustum.intersects(node_box(n))) continue;
    Visit v;
    v.node = id;
    v.sse = node_sse(index, id, camera);
    v.refine = n.has_children && v.sse > sse_target;
    stamp_[id] = generation_;
    where_[id] = static_cast<std::uint32_t>(visits_.size());
    visits_.push_back(v);
    if (v.refine)
      for (int i = 7; i >= 0; --i)
        if (n.children[static_cast<std::size_t>(i)] != no_node)
          stack.push_back(n.children[static_cast<std::size_t>(i)]);
  }
}

}  // namespace volreel::stream
