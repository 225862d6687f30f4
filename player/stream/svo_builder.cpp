// svo_builder.cpp: the array-encoded SVO of svo_layout.h (Cesium patent [0049]).
#include "volreel/stream/svo_builder.hpp"

#include "volreel/player/atlas_layout.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <utility>

namespace volreel::stream {

namespace {

struct ChildResult {
  vr_uint kind = VR_SVO_CHILD_EMPTY;
  vr_uint index = 0;
};

class Builder {
 public:
  Builder(const SpatialIndex& index, const ViewTraversal& view, const ResidentKeyframes& resident,
          double playhead, const SelectionSettings& settings, SvoStats& stats, StoredTimes& stored,
          std::span<const std::uint8_t> hidden, LodBlendState* blend, double now,
          DrawnRegions* drawn)
      : index_(index),
        view_(view),
        resident_(resident),
        playhead_(playhead),
        settings_(settings),
        stats_(stats),
        stored_(stored),
        hidden_(hidden),
        blend_(blend),
        now_(now),
        drawn_(drawn) {
    stored_.start(index_, playhead_);
    if (blend_) {
      blend_->reset(index_.node_count());
      // Stamps are builds; at the wrap every stamp is cleared (0: never).
      if (++blend_->build == 0) {
        blend_->reset(0);
        blend_->reset(index_.node_count());
        blend_->build = 1;
      }
    }
  }

  SvoArrays run() {
    if (index_.node_count() == 0 || !view_.visited(0)) {
      // 4. Nothing visible: a root that draws nothing.
      append_node(VR_SVO_NO_PARENT, no_node);
      for (vr_uint i = 0; i < 8; ++i) out_.nodes[1 + i] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
      return std::move(out_);
    }
    const ChildResult root = visit(0, VR_SVO_NO_PARENT, nullptr);
    if (root.kind != VR_SVO_CHILD_NODE) {
      // 4. The root is a leaf (or draws nothing): one record whose octants all defer to it.
      append_node(VR_SVO_NO_PARENT, 0);
      const SpatialNode& n = index_.node(0);
      const bool drawn = root.kind == VR_SVO_CHILD_LEAF;
      for (vr_uint i = 0; i < 8; ++i) {
        const bool inside = !n.has_children || n.children[i] != no_node;
        out_.nodes[1 + i] =
            vr_svo_child_word(inside && drawn ? VR_SVO_CHILD_UP : VR_SVO_CHILD_EMPTY, 0);
      }
      if (drawn) out_.nodes[9] = root.index;
    }
    if (blend_) blend_corners();
    std::sort(used_.begin(), used_.end());
    used_.erase(std::unique(used_.begin(), used_.end()), used_.end());
    stats_.used_slots = std::move(used_);
    stats_.node_records = static_cast<std::uint32_t>(out_.nodes.size() / VR_SVO_NODE_WORDS);
    stats_.leaf_records = static_cast<std::uint32_t>(out_.leaves.size() / VR_SVO_LEAF_WORDS);
    return std::move(out_);
  }

 private:
  const SpatialIndex& index_;
  const ViewTraversal& view_;
  const ResidentKeyframes& resident_;
  double playhead_;
  const SelectionSettings& settings_;
  SvoStats& stats_;
  StoredTimes& stored_;
  std::span<const std::uint8_t> hidden_;
  LodBlendState* blend_;
  double now_;
  DrawnRegions* drawn_;  ///< restricted drawing: caps applied and regions recorded (null: off)
  SvoArrays out_;
  std::vector<std::uint32_t> used_;
  /// Leaf records of nodes drawn from their own leaf, for the corner weights.
  struct OwnLeaf {
    vr_uint leaf = 0;
    std::uint32_t node = 0;
  };
  std::vector<OwnLeaf> own_leaves_;

  /// The data level a pair draws node `node` (at `level`) at: the coarser keyframe it reads.
  static std::uint32_t data_level(std::uint32_t level, const KeyframePair& pair) {
    const std::uint32_t d = vr_svo_coarser_lod(
        vr_svo_lod_pack(pair.a.lod_difference, pair.b.lod_difference), pair.factor);
    return level >= d ? level - d : 0;
  }

  /// The restricted drawing's data level of `pair` drawing a node at `level`: an own brick the
  /// node's level, an ancestor's that ancestor's; exact constants impose nothing (exact_level).
  static std::uint32_t restricted_level(std::uint32_t level, const KeyframePair& pair) {
    std::uint32_t d = DrawnRegions::exact_level;
    const auto take = [&](const KeyframePick& k) {
      if (!(k.exact && k.lod_difference > 0)) d = std::min(d, level - k.lod_difference);
    };
    if (pair.factor != 1.0f) take(pair.a);
    if (pair.factor != 0.0f) take(pair.b);
    return d;
  }

  /// The node's keyframe pair, chosen again from coarser data when the restriction caps it.
  KeyframePair choose_pair(std::uint32_t id) {
    const KeyframePair pair =
        select_keyframe_pair(index_, id, playhead_, resident_, settings_, &stored_);
    if (!drawn_ || drawn_->cap_pass[id] < drawn_->caps_from) return pair;
    const std::uint32_t level = index_.node(id).key.level, cap = drawn_->cap[id];
    const std::uint32_t drawn = restricted_level(level, pair);
    if (drawn == DrawnRegions::exact_level || drawn <= cap) return pair;
    ++stats_.restricted_nodes;
    return select_keyframe_pair(index_, id, playhead_, resident_, settings_, &stored_, level - cap);
  }

  /// Records for the restriction the region of `node` drawn by `owner`'s pair (or refined).
  void record(std::uint32_t node, std::uint32_t owner, const KeyframePair* pair) {
    DrawnRegions& d = *drawn_;
    d.stamp[node] = d.pass;
    d.owner[node] = owner;
    d.refined[node] = pair == nullptr;
    d.level[node] = static_cast<std::uint8_t>(
        pair ? std::min<std::uint32_t>(restricted_level(index_.node(owner).key.level, *pair),
                                       DrawnRegions::exact_level)
             : 0);
    d.nodes.push_back(node);
  }

  /// Marks `node` as a region drawn at data level `level` with temporal weight t.
  void mark(std::uint32_t node, std::uint32_t level, float t) {
    LodBlendState& b = *blend_;
    b.region_build[node] = b.build;
    b.region_refined[node] = 0;
    b.region_level[node] = static_cast<std::uint8_t>(std::min<std::uint32_t>(level, 255));
    b.region_t[node] = t;
  }
  /// Marks the region `node` drawn by `pair` of the node `owner` (itself, or its parent for an
  /// "up" child).
  void mark_region(std::uint32_t node, std::uint32_t owner, const KeyframePair& pair) {
    mark(node, data_level(index_.node(owner).key.level, pair), 1.0f);
  }

  vr_uint append_node(vr_uint parent, std::uint32_t id) {
    const auto record = static_cast<vr_uint>(out_.nodes.size() / VR_SVO_NODE_WORDS);
    out_.nodes.resize(out_.nodes.size() + VR_SVO_NODE_WORDS, 0);
    out_.node_ids.push_back(id);
    out_.nodes[record * VR_SVO_NODE_WORDS] = parent;
    out_.nodes[record * VR_SVO_NODE_WORDS + 9] = VR_SVO_NO_LEAF;
    return record;
  }

  /// A leaf record; `coarse` (null or invalid: none) is the parent's pair, blended in later by
  /// blend_corners().
  vr_uint append_leaf(const KeyframePair& pair, const KeyframePair* coarse = nullptr) {
    const auto record = static_cast<vr_uint>(out_.leaves.size() / VR_SVO_LEAF_WORDS);
    const bool blends = coarse && coarse->valid();
    const vr_uint lods =
        vr_svo_lod_pack(pair.a.lod_difference, pair.b.lod_difference) |
        (blends ? vr_svo_lod_pack(coarse->a.lod_difference + 1, coarse->b.lod_difference + 1) << 16
                : 0u);
    out_.leaves.insert(
        out_.leaves.end(),
        {pair.a.slot, pair.b.slot, lods, std::bit_cast<std::uint32_t>(pair.factor),
         blends ? coarse->a.slot : VR_ATLAS_NO_SLOT, blends ? coarse->b.slot : VR_ATLAS_NO_SLOT,
         std::bit_cast<std::uint32_t>(blends ? coarse->factor : 0.0f), VR_SVO_BLEND_NONE,
         VR_SVO_BLEND_NONE});
    used_.push_back(pair.a.slot);
    used_.push_back(pair.b.slot);
    return record;
  }

  // 1. A node drawn as a whole: its leaf, or deferred to an ancestor, or nothing to draw.
  ChildResult as_leaf(std::uint32_t id, const KeyframePair& pair, const KeyframePair* parent,
                      std::uint32_t last_visit) {
    if (!pair.valid()) return {VR_SVO_CHILD_EMPTY, 0};
    if (pair.drawn_by_ancestor()) return {VR_SVO_CHILD_UP, 0};
    if (drawn_) record(id, id, &pair);
    if (!blend_) return {VR_SVO_CHILD_LEAF, append_leaf(pair)};
    LodBlendState& b = *blend_;
    const vr_uint leaf = append_leaf(pair, parent);
    // The temporal weight: a node visited in the last build whose region an ancestor's leaf drew
    // then fades in. The regions marked in the last build tell: walking up from the node, the
    // first one marked then is the node's own region drawn by its parent's leaf ("up"), or an
    // ancestor's region, or a node record (the node itself: drawn by its children, a collapse;
    // an ancestor: an empty octant). Ancestors are marked after their children are visited, so
    // their marks are still the last build's here.
    const std::uint32_t last = b.build - 1;
    const bool continuing = b.own_build[id] == last && last != 0;
    bool drawn_above = false;
    if (!continuing && last != 0 && last_visit == last)
      for (std::uint32_t n = id; n != no_node; n = index_.node(n).parent)
        if (b.region_build[n] == last) {
          drawn_above = !b.region_refined[n];
          break;
        }
    const bool fades_in = drawn_above && b.settings.fade_s > 0;
    if (!continuing) b.since[id] = fades_in ? now_ : -1e300;
    b.own_build[id] = b.build;
    const float t =
        parent && parent->valid() && b.settings.fade_s > 0
            ? static_cast<float>(std::clamp((now_ - b.since[id]) / b.settings.fade_s, 0.0, 1.0))
            : 1.0f;
    mark(id, data_level(index_.node(id).key.level, pair), t);
    if (parent && parent->valid()) own_leaves_.push_back({leaf, id});
    return {VR_SVO_CHILD_LEAF, leaf};
  }

  ChildResult visit(std::uint32_t id, vr_uint parent_record, const KeyframePair* parent) {
    const ViewTraversal::Visit& v = view_.visit(id);
    const KeyframePair pair = choose_pair(id);
    // The build that visited the node before this one (blending).
    const std::uint32_t last_visit =
        blend_ ? std::exchange(blend_->visited_build[id], blend_->build) : 0;
    if (!v.refine) {
      if (id < hidden_.size() && hidden_[id] != 0) {
        ++stats_.hidden_targets;
      } else {
        ++stats_.target_nodes;
        if (pair.at_full_detail()) ++stats_.at_target_nodes;
      }
      if (!pair.valid())
        ++stats_.holes;
      else if (pair.drawn_by_ancestor())
        ++stats_.ancestor_drawn;
      if (blend_ && blend_->settings.fade_out_s > 0) {
        const ChildResult out = fade_out(id, parent_record, pair);
        if (out.kind == VR_SVO_CHILD_NODE) return out;
      }
      return as_leaf(id, pair, parent, last_visit);
    }
    // 2. A node record for the refined node; children first, then this node's own leaf.
    const vr_uint record = append_node(parent_record, id);
    const SpatialNode& n = index_.node(id);
    ChildResult children[8];
    bool any_deeper = false;
    for (vr_uint i = 0; i < 8; ++i) {
      const std::uint32_t c = n.children[i];
      if (c == no_node)
        children[i] = {VR_SVO_CHILD_EMPTY, 0};
      else if (!view_.visited(c))
        children[i] = {VR_SVO_CHILD_UP, 0};  // outside the view
      else
        children[i] = visit(c, record, &pair);
      any_deeper |= children[i].kind == VR_SVO_CHILD_NODE || children[i].kind == VR_SVO_CHILD_LEAF;
    }
    if (!any_deeper) {
      // 3. Nothing deeper: collapse. The record is the last one appended (no child appended any).
      out_.nodes.resize(out_.nodes.size() - VR_SVO_NODE_WORDS);
      out_.node_ids.pop_back();
      return as_leaf(id, pair, parent, last_visit);
    }
    bool any_up = false;
    for (vr_uint i = 0; i < 8; ++i) {
      if (children[i].kind == VR_SVO_CHILD_UP && !pair.valid())
        children[i].kind = VR_SVO_CHILD_EMPTY;
      any_up |= children[i].kind == VR_SVO_CHILD_UP;
      out_.nodes[record * VR_SVO_NODE_WORDS + 1 + i] =
          vr_svo_child_word(children[i].kind, children[i].index);
    }
    if (any_up) out_.nodes[record * VR_SVO_NODE_WORDS + 9] = append_leaf(pair);
    if (drawn_) {
      this->record(id, id, nullptr);
      for (vr_uint i = 0; i < 8; ++i)
        if (children[i].kind == VR_SVO_CHILD_UP) this->record(n.children[i], id, &pair);
    }
    if (blend_) {
      blend_->region_build[id] = blend_->build;
      blend_->region_refined[id] = 1;
      for (vr_uint i = 0; i < 8; ++i)
        if (children[i].kind == VR_SVO_CHILD_UP) mark_region(n.children[i], id, pair);
    }
    return {VR_SVO_CHILD_NODE, record};
  }

  /// Fade-out on collapse: a target node that its children drew in the last build (or that is
  /// still fading out) keeps a node record whose children with bricks of their own are drawn from
  /// them, blended towards this node's drawing with weight 1 − (now − out_since) / fade_out_s; the
  /// others are drawn "up" by its own leaf. Returns an empty result (and appends nothing) when
  /// the node is not fading out or no child has bricks of its own.
  ChildResult fade_out(std::uint32_t id, vr_uint parent_record, const KeyframePair& pair) {
    LodBlendState& b = *blend_;
    const std::uint32_t last = b.build - 1;
    const SpatialNode& n = index_.node(id);
    if (!pair.valid() || !n.has_children || last == 0) return {};
    if (b.out_build[id] != last) {
      // Not fading in the last build: a collapse if its children drew it then.
      if (!(b.region_build[id] == last && b.region_refined[id])) return {};
      b.out_since[id] = now_;
    }
    const double t = (now_ - b.out_since[id]) / b.settings.fade_out_s;
    if (!(t < 1.0)) return {};
    const auto w = static_cast<vr_uint>(std::lround(std::clamp(1.0 - t, 0.0, 1.0) * 255.0));
    if (w == 0) return {};
    // The children's own pairs (plain selection: they are not in the view's cut), only where both
    // are the child's own bricks at the times the playhead needs: the resident set may still
    // hold a child's bricks of other times (after a seek, or as the playhead moves on), which
    // are further from the truth than the node's own drawing.
    KeyframePair pairs[8];
    bool own[8] = {};
    bool any = false;
    for (vr_uint i = 0; i < 8; ++i) {
      const std::uint32_t c = n.children[i];
      if (c == no_node) continue;
      pairs[i] = select_keyframe_pair(index_, c, playhead_, resident_, settings_, &stored_);
      own[i] = pairs[i].at_full_detail() &&
               static_cast<double>(pairs[i].a.t) == stored_.nearest(c, false, false) &&
               static_cast<double>(pairs[i].b.t) == stored_.nearest(c, true, false);
      any |= own[i];
    }
    if (!any) return {};
    b.out_build[id] = b.build;
    const vr_uint record = append_node(parent_record, id);
    const std::uint32_t level = n.key.level;
    bool any_up = false;
    for (vr_uint i = 0; i < 8; ++i) {
      const std::uint32_t c = n.children[i];
      vr_uint kind = VR_SVO_CHILD_EMPTY, index = 0;
      if (c != no_node && own[i]) {
        kind = VR_SVO_CHILD_LEAF;
        index = append_leaf(pairs[i], &pair);
        vr_uint* leaf = &out_.leaves[std::size_t{index} * VR_SVO_LEAF_WORDS];
        leaf[7] = leaf[8] = w * 0x01010101u;
        if (w != 255) {
          const float g = std::bit_cast<float>(leaf[6]);
          if (g != 1.0f) used_.push_back(leaf[4]);
          if (g != 0.0f) used_.push_back(leaf[5]);
          ++stats_.blended_leaves;
        }
        // Drawn from its own bricks: if it comes back into the cut it goes on without a fade-in.
        b.own_build[c] = b.build;
        mark(c, data_level(level + 1, pairs[i]), 1.0f);
      } else if (c != no_node) {
        kind = VR_SVO_CHILD_UP;
        any_up = true;
        mark_region(c, id, pair);
      }
      out_.nodes[record * VR_SVO_NODE_WORDS + 1 + i] = vr_svo_child_word(kind, index);
    }
    if (any_up) out_.nodes[record * VR_SVO_NODE_WORDS + 9] = append_leaf(pair);
    b.region_build[id] = b.build;
    b.region_refined[id] = 1;
    return {VR_SVO_CHILD_NODE, record};
  }

  /// The region drawing the cell of `node` (a node record's cell: refined), or none: walks up to
  /// the nearest marked ancestor. Returns false where nothing is drawn (an empty octant).
  bool region_of(std::uint32_t node, std::uint32_t& region) const {
    const LodBlendState& b = *blend_;
    const std::uint32_t start = node;
    for (; node != no_node; node = index_.node(node).parent) {
      if (b.region_build[node] != b.build) continue;
      if (b.region_refined[node] && node != start) return false;  // an empty octant below it
      region = node;
      return true;
    }
    return false;
  }

  /// Corner weights of the leaves drawn from their own node (svo_layout.h words 7, 8).
  void blend_corners() {
    const LodBlendState& b = *blend_;
    for (const OwnLeaf& own : own_leaves_) {
      const SpatialNode& n = index_.node(own.node);
      const std::uint32_t level = n.key.level;
      const std::uint8_t mine = b.region_level[own.node];
      // A node that has faded in keeps its own weight: a neighbour that starts fading later
      // must not pull it back to its parent's drawing (which would pop).
      const bool fading = b.region_t[own.node] < 1.0f;
      // The 26 neighbouring cells of the same level: −1 coarser, else their temporal weight (1
      // for a finer or absent neighbour, which blends itself or draws nothing).
      float near[27];
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int k = (dx + 1) + 3 * (dy + 1) + 9 * (dz + 1);
            near[k] = 1.0f;
            if (dx == 0 && dy == 0 && dz == 0) continue;
            const std::int64_t x = std::int64_t{n.key.x} + dx, y = std::int64_t{n.key.y} + dy,
                               z = std::int64_t{n.key.z} + dz;
            if (x < 0 || y < 0 || z < 0) continue;
            NodeKey key = n.key;
            key.level = level;
            key.x = static_cast<std::uint32_t>(x);
            key.y = static_cast<std::uint32_t>(y);
            key.z = static_cast<std::uint32_t>(z);
            const std::uint32_t cell = index_.find(key);
            std::uint32_t region = no_node;
            if (cell == no_node || !region_of(cell, region) || b.region_refined[region]) continue;
            if (b.region_level[region] < mine)
              near[k] = b.settings.spatial ? -1.0f : 1.0f;
            else if (b.region_level[region] == mine && fading)
              near[k] = b.region_t[region];
          }
      vr_uint words[2] = {0, 0};
      for (vr_uint i = 0; i < 8; ++i) {
        const int sx = (i & 1) ? 1 : -1, sy = (i & 2) ? 1 : -1, sz = (i & 4) ? 1 : -1;
        float w = b.region_t[own.node];
        for (int k = 0; k < 8; ++k) {
          const int dx = (k & 1) ? sx : 0, dy = (k & 2) ? sy : 0, dz = (k & 4) ? sz : 0;
          w = std::min(w, near[(dx + 1) + 3 * (dy + 1) + 9 * (dz + 1)]);
        }
        const auto byte = static_cast<vr_uint>(std::lround(std::clamp(w, 0.0f, 1.0f) * 255.0f));
        words[i / 4] |= byte << (8 * (i % 4));
      }
      vr_uint* record = &out_.leaves[std::size_t{own.leaf} * VR_SVO_LEAF_WORDS];
      record[7] = words[0];
      record[8] = words[1];
      if (words[0] != VR_SVO_BLEND_NONE || words[1] != VR_SVO_BLEND_NONE) {
        ++stats_.blended_leaves;
        const float g = std::bit_cast<float>(record[6]);
        if (g != 1.0f) used_.push_back(record[4]);
        if (g != 0.0f) used_.push_back(record[5]);
      }
    }
  }
};

/// Lowers the cap of each region's owner whose region touches one drawn two or more levels
/// coarser; returns whether it lowered any. A region's 26 neighbouring cells of its node's level
/// lead, walking up, to the coarser or equal regions that touch it; finer ones check it from their
/// side.
bool lower_caps(const SpatialIndex& index, DrawnRegions& d) {
  bool lowered = false;
  for (const std::uint32_t node : d.nodes) {
    const std::uint32_t mine = d.level[node];
    if (d.refined[node] || mine == DrawnRegions::exact_level || mine < 2) continue;
    const NodeKey& k = index.node(node).key;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          const std::int64_t x = std::int64_t{k.x} + dx, y = std::int64_t{k.y} + dy,
                             z = std::int64_t{k.z} + dz;
          if (x < 0 || y < 0 || z < 0) continue;
          const std::uint32_t cell =
              index.find({k.level, static_cast<std::uint32_t>(x), static_cast<std::uint32_t>(y),
                          static_cast<std::uint32_t>(z)});
          for (std::uint32_t n = cell; n != no_node; n = index.node(n).parent) {
            if (d.stamp[n] != d.pass) continue;
            // A refined cell holds finer regions; a refined ancestor, an empty octant.
            const std::uint32_t other = d.level[n];
            if (!d.refined[n] && other != DrawnRegions::exact_level && other + 1 < mine) {
              const std::uint32_t owner = d.owner[node];
              const auto cap = static_cast<std::uint8_t>(other + 1);
              if (d.cap_pass[owner] < d.caps_from || cap < d.cap[owner]) {
                d.cap[owner] = cap;
                d.cap_pass[owner] = d.pass;
                lowered = true;
              }
            }
            break;
          }
        }
  }
  return lowered;
}

}  // namespace

SvoArrays build_svo(const SpatialIndex& index, const ViewTraversal& view,
                    const ResidentKeyframes& resident, double playhead,
                    const SelectionSettings& settings, SvoStats* stats, StoredTimes* stored,
                    std::span<const std::uint8_t> hidden, LodBlendState* blend, double now) {
  SvoStats local;
  SvoStats& s = stats ? *stats : local;
  StoredTimes fresh;
  StoredTimes& st = stored ? *stored : fresh;
  const bool blending = blend && (blend->settings.fade_s > 0 || blend->settings.fade_out_s > 0 ||
                                  blend->settings.spatial);
  LodBlendState* const b = blending ? blend : nullptr;
  s = SvoStats{};
  if (!settings.restricted)
    return Builder(index, view, resident, playhead, settings, s, st, hidden, b, now, nullptr).run();
  // Restricted drawing: build (without touching the blending's state), lower the caps of the
  // regions that touch one two or more levels coarser, and build again until none does. Caps only
  // go down, so this ends; then the last build stands, or one more with the blending.
  DrawnRegions own;
  DrawnRegions& d = blend ? blend->drawn : own;
  d.reset(index.node_count());
  d.start_build();
  for (std::uint32_t extra = 0;; ++extra) {
    d.start_pass();
    s = SvoStats{};
    SvoArrays out =
        Builder(index, view, resident, playhead, settings, s, st, hidden, nullptr, now, &d).run();
    if (lower_caps(index, d)) continue;
    if (blending) {
      d.start_pass();
      s = SvoStats{};
      out = Builder(index, view, resident, playhead, settings, s, st, hidden, b, now, &d).run();
      ++extra;
    }
    s.restriction_builds = extra;
    return out;
  }
}

void DrawnRegions::reset(std::size_t node_count) {
  if (stamp.size() == node_count) return;
  pass = caps_from = 0;
  stamp.assign(node_count, 0);
  owner.assign(node_count, 0);
  level.assign(node_count, 0);
  refined.assign(node_count, 0);
  cap_pass.assign(node_count, 0);
  cap.assign(node_count, 0);
  nodes.clear();
}

void DrawnRegions::start_build() {
  caps_from = pass + 1;  // 0 at the wrap, which the next start_pass handles
}

void DrawnRegions::start_pass() {
  nodes.clear();
  if (++pass == 0) {
    // Wrapped: clear the stamps. Caps set so far in this build are lost (more passes), and those
    // set from now on count: caps_from must not stay above the new stamps, or no cap would hold
    // and the build would never end.
    const std::size_t n = stamp.size();
    reset(0);
    reset(n);
    pass = caps_from = 1;
  }
}

void LodBlendState::reset(std::size_t nodes) {
  if (visited_build.size() == nodes) return;
  build = 0;
  visited_build.assign(nodes, 0);
  own_build.assign(nodes, 0);
  since.assign(nodes, 0);
  out_build.assign(nodes, 0);
  out_since.assign(nodes, 0);
  region_build.assign(nodes, 0);
  region_level.assign(nodes, 0);
  region_refined.assign(nodes, 0);
  region_t.assign(nodes, 1.0f);
}

std::vector<std::string> validate_svo(std::span<const std::uint32_t> nodes,
                                      std::span<const std::uint32_t> leaves,
                                      std::uint32_t slot_count, std::uint32_t level_count) {
  std::vector<std::string> problems;
  const auto fail = [&](const std::string& s) {
    if (problems.size() < 32) problems.push_back(s);
  };
  if (nodes.size() % VR_SVO_NODE_WORDS != 0 || nodes.empty()) {
    fail("node array of " + std::to_string(nodes.size()) +
         " words is not a whole number (≥ 1) of records");
    return problems;
  }
  if (leaves.size() % VR_SVO_LEAF_WORDS != 0) {
    fail("leaf array of " + std::to_string(leaves.size()) +
         " words is not a whole number of records");
    return problems;
  }
  const std::size_t node_count = nodes.size() / VR_SVO_NODE_WORDS;
  const std::size_t leaf_count = leaves.size() / VR_SVO_LEAF_WORDS;
  if (nodes[0] != VR_SVO_NO_PARENT) fail("record 0 has a parent");
  std::vector<std::uint32_t> node_seen(node_count, 0), leaf_seen(leaf_count, 0);
  const auto check_leaf = [&](std::uint32_t leaf, std::uint32_t depth, const std::string& where) {
    if (leaf >= leaf_count) {
      fail(where + ": leaf " + std::to_string(leaf) + " out of range");
      return;
    }
    if (leaf_seen[leaf]++) fail(where + ": leaf " + std::to_string(leaf) + " referenced twice");
    if (depth >= level_count)
      fail(where + ": leaf " + std::to_string(leaf) + " deeper than the octree");
    const std::uint32_t* w = &leaves[std::size_t{leaf} * VR_SVO_LEAF_WORDS];
    if (w[0] >= slot_count || w[1] >= slot_count)
      fail(where + ": leaf " + std::to_string(leaf) + " slot out of range");
    if (vr_svo_lod_a(w[2]) > depth || vr_svo_lod_b(w[2]) > depth)
      fail(where + ": leaf " + std::to_string(leaf) + " LOD difference above the root");
    const float f = std::bit_cast<float>(w[3]);
    if (!(f >= 0.0f && f <= 1.0f))
      fail(where + ": leaf " + std::to_string(leaf) + " factor outside [0, 1]");
    if (w[7] == VR_SVO_BLEND_NONE && w[8] == VR_SVO_BLEND_NONE) return;
    // A blending leaf: its coarse pair is drawn too (a slot whose weight, 1 − g or g, is 0 may be
    // VR_ATLAS_NO_SLOT).
    const float g = std::bit_cast<float>(w[6]);
    const bool c_bad = w[4] >= slot_count && !(w[4] == VR_ATLAS_NO_SLOT && g == 1.0f);
    const bool d_bad = w[5] >= slot_count && !(w[5] == VR_ATLAS_NO_SLOT && g == 0.0f);
    if (c_bad || d_bad)
      fail(where + ": leaf " + std::to_string(leaf) + " coarse slot out of range");
    for (const std::uint32_t d : {vr_svo_lod_c(w[2]), vr_svo_lod_d(w[2])})
      if (d == 0 || d > depth)
        fail(where + ": leaf " + std::to_string(leaf) + " coarse LOD difference " +
             std::to_string(d) + " outside [1, " + std::to_string(depth) + "]");
    if (!(g >= 0.0f && g <= 1.0f))
      fail(where + ": leaf " + std::to_string(leaf) + " coarse factor outside [0, 1]");
  };
  // Depth-first from the root.
  struct Item {
    std::uint32_t record, depth;
  };
  std::vector<Item> stack{{0, 0}};
  node_seen[0] = 1;
  while (!stack.empty()) {
    const Item it = stack.back();
    stack.pop_back();
    const std::string where = "node " + std::to_string(it.record);
    if (it.depth >= level_count) fail(where + ": deeper than the octree");
    const std::uint32_t* w = &nodes[std::size_t{it.record} * VR_SVO_NODE_WORDS];
    bool any_up = false;
    for (std::uint32_t i = 0; i < 8; ++i) {
      const std::uint32_t kind = vr_svo_child_kind(w[1 + i]), idx = vr_svo_child_index(w[1 + i]);
      if (kind == VR_SVO_CHILD_NODE) {
        if (idx == 0 || idx >= node_count) {
          fail(where + ": child record " + std::to_string(idx) + " out of range");
          continue;
        }
        if (node_seen[idx]++) {
          fail(where + ": record " + std::to_string(idx) + " reached twice");
          continue;
        }
        if (nodes[std::size_t{idx} * VR_SVO_NODE_WORDS] != it.record)
          fail("node " + std::to_string(idx) + ": parent word does not name its parent");
        stack.push_back({idx, it.depth + 1});
      } else if (kind == VR_SVO_CHILD_LEAF) {
        check_leaf(idx, it.depth + 1, where);
      } else if (kind == VR_SVO_CHILD_UP) {
        any_up = true;
      }
    }
    if (any_up != (w[9] != VR_SVO_NO_LEAF))
      fail(where + ": own leaf " + std::string(any_up ? "missing" : "present without an UP child"));
    if (w[9] != VR_SVO_NO_LEAF) check_leaf(w[9], it.depth, where + " (own leaf)");
  }
  for (std::size_t r = 0; r < node_count; ++r)
    if (!node_seen[r]) fail("node " + std::to_string(r) + " unreachable");
  for (std::size_t l = 0; l < leaf_count; ++l)
    if (!leaf_seen[l]) fail("leaf " + std::to_string(l) + " unreferenced");
  return problems;
}

}  // namespace volreel::stream
