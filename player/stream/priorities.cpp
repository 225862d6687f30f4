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

namespace {

/// The time step ⌊v⌋ and ⌈v⌉, within [0, no_time − 1].
std::uint32_t step_floor(double v) {
  constexpr double top = static_cast<double>(no_time - 1);
  return v <= 0 ? 0 : v >= top ? no_time - 1 : static_cast<std::uint32_t>(std::floor(v));
}
std::uint32_t step_ceil(double v) {
  constexpr double top = static_cast<double>(no_time - 1);
  return v <= 0 ? 0 : v >= top ? no_time - 1 : static_cast<std::uint32_t>(std::ceil(v));
}

}  // namespace

void due_times(const HeldTimes& times, double playhead, double velocity, double lookahead_s,
               std::vector<DueTime>& due) {
  due.clear();
  if (times.empty() || !std::isfinite(playhead)) return;
  // The last time step ≤ playhead and the first ≥ playhead (the pre-render selection's picks; on
  // a keyframe, the same one), and the next one beyond each.
  const std::uint32_t before = playhead < 0 ? no_time : times.at_or_before(step_floor(playhead));
  const std::uint32_t after = times.at_or_after(step_ceil(playhead));
  const std::uint32_t before_next =
      before == no_time || before == 0 ? no_time : times.at_or_before(before - 1);
  const std::uint32_t after_next = after == no_time ? no_time : times.at_or_after(after + 1);
  // Those the playhead reaches within the lookahead, in its direction of travel.
  const double reach = velocity * std::max(0.0, lookahead_s);
  const bool reaching = std::abs(reach) > 0 && std::isfinite(reach);
  const auto first_of = [](std::initializer_list<std::uint32_t> ts) {
    for (const std::uint32_t t : ts)
      if (t != no_time) return t;
    return no_time;
  };
  std::uint32_t lo = first_of({before_next, before, after});
  std::uint32_t hi = first_of({after_next, after, before});
  if (reaching && reach > 0) hi = std::max(hi, step_floor(playhead + reach));
  if (reaching && reach < 0) lo = std::min(lo, step_ceil(playhead + reach));
  // A step, a start of playback or a change of direction goes first to the next ones beyond:
  // due last (as if needed at the end of the lookahead).
  const double at_end = std::max(0.0, lookahead_s);
  times.for_each(lo, hi, [&](std::uint32_t t) {
    double s = -1;
    if (t == before || t == after) {
      s = 0;
    } else if (reaching) {
      const double d = static_cast<double>(t) - playhead;
      if (d != 0 && (d > 0) == (reach > 0) && std::abs(d) <= std::abs(reach))
        s = std::abs(d / velocity);
    }
    if (s < 0 && (t == before_next || t == after_next)) s = at_end;
    if (s >= 0) due.push_back({t, s});
  });
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
                        double sse_target, bool restricted) {
  if (stamp_.size() != index.node_count()) {
    stamp_.assign(index.node_count(), 0);
    where_.assign(index.node_count(), 0);
    forced_.assign(index.node_count(), 0);
    forced_list_.clear();
    generation_ = 0;
  }
  for (const std::uint32_t id : forced_list_) forced_[id] = 0;
  forced_list_.clear();
  const Frustum frustum(camera);
  walk(index, frustum, camera, sse_target);
  // Each pass forces at least one more node, and a node is forced once: this ends.
  while (restricted && force_splits(index)) walk(index, frustum, camera, sse_target);
}

void ViewTraversal::walk(const SpatialIndex& index, const Frustum& frustum,
                         const player::OrbitCamera& camera, double sse_target) {
  visits_.clear();
  if (++generation_ == 0) {  // wrapped: clear the stamps
    std::fill(stamp_.begin(), stamp_.end(), 0u);
    generation_ = 1;
  }
  if (index.node_count() == 0 || !index.node(0).present()) return;
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
    const bool detailed = v.sse <= sse_target;
    v.refine = n.has_children && (!detailed || forced_[id] != 0);
    v.forced = v.refine && detailed;
    stamp_[id] = generation_;
    where_[id] = static_cast<std::uint32_t>(visits_.size());
    visits_.push_back(v);
    if (v.refine)
      for (int i = 7; i >= 0; --i)
        if (n.children[static_cast<std::size_t>(i)] != no_node)
          stack.push_back(n.children[static_cast<std::size_t>(i)]);
  }
}

bool ViewTraversal::force_splits(const SpatialIndex& index) {
  const std::size_t before = forced_list_.size();
  for (const Visit& v : visits_) {
    if (v.refine) continue;
    const NodeKey& k = index.node(v.node).key;
    if (k.level < 2) continue;  // every neighbour is at level 0 or finer
    // The 26 cells around N at level d lie in N's parent and in 7 cells of level d − 1 around it:
    // per axis the parent's coordinate, or the one on N's side (below for an even coordinate).
    const std::uint32_t c[3] = {k.x, k.y, k.z};
    std::int64_t side[3];
    for (int a = 0; a < 3; ++a) side[a] = std::int64_t{c[a] / 2} + (c[a] % 2 == 0 ? -1 : 1);
    for (int octant = 1; octant < 8; ++octant) {
      std::int64_t cell[3];
      bool inside = true;
      for (int a = 0; a < 3; ++a) {
        cell[a] = (octant >> a) & 1 ? side[a] : std::int64_t{c[a] / 2};
        inside = inside && cell[a] >= 0 && cell[a] < (std::int64_t{1} << (k.level - 1));
      }
      if (!inside) continue;
      // That cell must be drawn at level d − 1 or finer: find the deepest visited node at or
      // above it; a target node above it is too coarse.
      NodeKey up{k.level - 1, static_cast<std::uint32_t>(cell[0]),
                 static_cast<std::uint32_t>(cell[1]), static_cast<std::uint32_t>(cell[2])};
      for (;;) {
        const std::uint32_t id = index.find(up);
        if (id != no_node && visited(id)) {
          const Visit& above = visit(id);
          if (up.level < k.level - 1 && !above.refine && index.node(id).has_children &&
              forced_[id] == 0) {
            forced_[id] = 1;
            forced_list_.push_back(id);
          }
          break;
        }
        if (up.level == 0) break;
        up = {up.level - 1, up.x / 2, up.y / 2, up.z / 2};
      }
    }
  }
  return forced_list_.size() > before;
}

}  // namespace volreel::stream
