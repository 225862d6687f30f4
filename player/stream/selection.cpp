// selection.cpp: two keyframe nodes per spatial node with the ancestor handicap (Cesium patent
// [0046]–[0048], [0069]–[0075]).
#include "volreel/stream/selection.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace volreel::stream {

void ResidentKeyframes::assign(const SpatialIndex& index,
                               std::span<const ResidentKeyframe> entries) {
  entries_.assign(entries.begin(), entries.end());
  std::sort(entries_.begin(), entries_.end(),
            [](const ResidentKeyframe& a, const ResidentKeyframe& b) {
              // Keyframe ids are grouped by node and sorted by t inside a node.
              return a.keyframe < b.keyframe;
            });
  first_.assign(index.node_count(), 0);
  count_.assign(index.node_count(), 0);
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    const std::uint32_t node = index.node_of(entries_[i].keyframe);
    if (count_[node] == 0) first_[node] = static_cast<std::uint32_t>(i);
    ++count_[node];
  }
}

std::span<const ResidentKeyframe> ResidentKeyframes::of_node(std::uint32_t node) const {
  if (node >= count_.size() || count_[node] == 0) return {};
  return {entries_.data() + first_[node], count_[node]};
}

namespace {

enum class Side { before, after };

/// Step 1 for one node: its resident keyframe node on `side` nearest p, or the nearest on the
/// other side with the missing-side factor. Returns an invalid pick if nothing is resident.
KeyframePick nearest_on_side(const SpatialIndex& index, std::span<const ResidentKeyframe> list,
                             double p, Side side, const SelectionSettings& settings) {
  KeyframePick best_here, best_other;
  double d_here = std::numeric_limits<double>::infinity(), d_other = d_here;
  for (const ResidentKeyframe& r : list) {
    const double t = static_cast<double>(index.keyframe(r.keyframe).t);
    const bool on_side = side == Side::before ? t <= p : t >= p;
    const double d = std::abs(t - p);
    if (on_side && d < d_here) {
      d_here = d;
      best_here.keyframe = r.keyframe;
      best_here.slot = r.slot;
    } else if (!on_side && d < d_other) {
      d_other = d;
      best_other.keyframe = r.keyframe;
      best_other.slot = r.slot;
    }
  }
  if (best_here.valid()) {
    best_here.score = d_here;
    return best_here;
  }
  if (best_other.valid()) best_other.score = d_other * settings.missing_side_factor;
  return best_other;
}

/// The time step on `side` of p nearest it at which `node` has a keyframe node in the index (with
/// constant_only, a constant subtree's); -1 when there is none.
double stored_time(const SpatialIndex& index, std::uint32_t node, double p, Side side,
                   bool constant_only) {
  const HeldTimes times = constant_only ? index.constant_times(node) : index.times(node);
  if (times.empty() || !(p >= 0)) return -1;
  // Keyframe nodes at p itself are on both sides.
  const double q = std::min(p, static_cast<double>(no_time - 1));
  const std::uint32_t t = side == Side::before
                              ? times.at_or_before(static_cast<std::uint32_t>(std::floor(q)))
                              : times.at_or_after(static_cast<std::uint32_t>(std::ceil(q)));
  return t == no_time ? -1 : static_cast<double>(t);
}

/// The time step on `side` of p nearest it at which the node's state is stored: its own keyframe
/// nodes and the constant subtrees of its ancestors (exact data for it); -1 when none is.
double stored_state_time(const SpatialIndex& index, std::uint32_t node, Side side,
                         StoredTimes& stored) {
  const bool after = side == Side::after;
  double best = stored.nearest(node, after, false);
  for (std::uint32_t a = index.node(node).parent; a != no_node; a = index.node(a).parent) {
    const double t = stored.nearest(a, after, true);
    if (t >= 0 && (best < 0 || (side == Side::before ? t > best : t < best))) best = t;
  }
  return best;
}

KeyframePick pick_side(const SpatialIndex& index, std::uint32_t node, double p,
                       const ResidentKeyframes& resident, Side side,
                       const SelectionSettings& settings, StoredTimes& stored,
                       std::uint32_t min_up) {
  KeyframePick best;
  best.score = std::numeric_limits<double>::infinity();
  // The nearest time step on this side, and the step at which this node's state is stored
  // nearest it: a node without a brick at every step is drawn between its stored states, so its
  // nearest stored state counts as if it were at the nearest step (distance from p to that step).
  const double step = side == Side::before ? std::floor(p) : std::ceil(p);
  const double own_reference = stored_state_time(index, node, side, stored);
  // exp(ancestor_handicap · up), one level at a time.
  const double level_handicap = std::exp(settings.ancestor_handicap);
  double handicap = 1;
  std::uint32_t up = 0;
  for (std::uint32_t n = node; n != no_node;
       n = index.node(n).parent, ++up, handicap *= level_handicap) {
    KeyframePick c = nearest_on_side(index, resident.of_node(n), p, side, settings);
    if (!c.valid()) continue;
    const KeyframeNode& k = index.keyframe(c.keyframe);
    // A node drawn coarser for the restriction skips the finer levels, except exact constants.
    if (up < min_up && !k.subtree_constant) continue;
    // 2. Ancestor handicap, except for a constant subtree, which is exact for its descendants.
    c.exact = up == 0 || k.subtree_constant;
    const double t = static_cast<double>(k.t);
    if (side == Side::before ? t <= p : t >= p) {
      const double reference =
          c.exact ? own_reference : stored.nearest(n, side == Side::after, false);
      if (reference >= 0) c.score = std::abs(reference - t) + std::abs(step - p);
    }
    if (!c.exact) c.score *= handicap;
    c.lod_difference = up;
    c.t = k.t;
    // 3. Keep the best (ties keep the finer candidate).
    if (c.score < best.score) best = c;
  }
  if (!best.valid()) best = KeyframePick{};
  return best;
}

}  // namespace

void StoredTimes::start(const SpatialIndex& index, double playhead, bool remember) {
  index_ = &index;
  playhead_ = playhead;
  const std::size_t entries = remember ? 4 * index.node_count() : 0;
  if (stamp_.size() != entries || generation_ == std::numeric_limits<std::uint32_t>::max()) {
    stamp_.assign(entries, 0);
    values_.assign(entries, -1);
    generation_ = 0;
  }
  ++generation_;
}

double StoredTimes::nearest(std::uint32_t node, bool after, bool constant_only) {
  const Side side = after ? Side::after : Side::before;
  if (stamp_.empty()) return stored_time(*index_, node, playhead_, side, constant_only);
  const std::size_t i = 4 * std::size_t{node} + 2 * std::size_t{after} + std::size_t{constant_only};
  if (i >= stamp_.size()) throw std::logic_error("StoredTimes: a node outside the index started");
  if (stamp_[i] != generation_) {
    values_[i] = stored_time(*index_, node, playhead_, side, constant_only);
    stamp_[i] = generation_;
  }
  return values_[i];
}

KeyframePair select_keyframe_pair(const SpatialIndex& index, std::uint32_t node, double playhead,
                                  const ResidentKeyframes& resident,
                                  const SelectionSettings& settings, StoredTimes* stored,
                                  std::uint32_t min_lod_difference) {
  StoredTimes alone;
  if (!stored) {
    alone.start(index, playhead, false);
    stored = &alone;
  }
  KeyframePair pair;
  pair.a = pick_side(index, node, playhead, resident, Side::before, settings, *stored,
                     min_lod_difference);
  pair.b = pick_side(index, node, playhead, resident, Side::after, settings, *stored,
                     min_lod_difference);
  if (pair.valid() && pair.a.t != pair.b.t) {
    const double f = (playhead - static_cast<double>(pair.a.t)) /
                     (static_cast<double>(pair.b.t) - static_cast<double>(pair.a.t));
    pair.factor = static_cast<float>(std::clamp(f, 0.0, 1.0));
  }
  return pair;
}

}  // namespace volreel::stream
