// svo_builder.cpp: the array-encoded SVO of svo_layout.h (Cesium patent [0049]).
#include "volreel/stream/svo_builder.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

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
          std::span<const std::uint8_t> hidden)
      : index_(index),
        view_(view),
        resident_(resident),
        playhead_(playhead),
        settings_(settings),
        stats_(stats),
        stored_(stored),
        hidden_(hidden) {
    stored_.start(index_, playhead_);
  }

  SvoArrays run() {
    if (index_.node_count() == 0 || !view_.visited(0)) {
      // 4. Nothing visible: a root that draws nothing.
      append_node(VR_SVO_NO_PARENT, no_node);
      for (vr_uint i = 0; i < 8; ++i) out_.nodes[1 + i] = vr_svo_child_word(VR_SVO_CHILD_EMPTY, 0);
      return std::move(out_);
    }
    const ChildResult root = visit(0, VR_SVO_NO_PARENT);
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
  SvoArrays out_;
  std::vector<std::uint32_t> used_;

  vr_uint append_node(vr_uint parent, std::uint32_t id) {
    const auto record = static_cast<vr_uint>(out_.nodes.size() / VR_SVO_NODE_WORDS);
    out_.nodes.resize(out_.nodes.size() + VR_SVO_NODE_WORDS, 0);
    out_.node_ids.push_back(id);
    out_.nodes[record * VR_SVO_NODE_WORDS] = parent;
    out_.nodes[record * VR_SVO_NODE_WORDS + 9] = VR_SVO_NO_LEAF;
    return record;
  }

  vr_uint append_leaf(const KeyframePair& pair) {
    const auto record = static_cast<vr_uint>(out_.leaves.size() / VR_SVO_LEAF_WORDS);
    out_.leaves.push_back(pair.a.slot);
    out_.leaves.push_back(pair.b.slot);
    out_.leaves.push_back(vr_svo_lod_pack(pair.a.lod_difference, pair.b.lod_difference));
    out_.leaves.push_back(std::bit_cast<std::uint32_t>(pair.factor));
    used_.push_back(pair.a.slot);
    used_.push_back(pair.b.slot);
    return record;
  }

  // 1. A node drawn as a whole: its leaf, or deferred to an ancestor, or nothing to draw.
  ChildResult as_leaf(const KeyframePair& pair) {
    if (!pair.valid()) return {VR_SVO_CHILD_EMPTY, 0};
    if (pair.drawn_by_ancestor()) return {VR_SVO_CHILD_UP, 0};
    return {VR_SVO_CHILD_LEAF, append_leaf(pair)};
  }

  ChildResult visit(std::uint32_t id, vr_uint parent_record) {
    const ViewTraversal::Visit& v = view_.visit(id);
    const KeyframePair pair =
        select_keyframe_pair(index_, id, playhead_, resident_, settings_, &stored_);
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
      return as_leaf(pair);
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
        children[i] = visit(c, record);
      any_deeper |= children[i].kind == VR_SVO_CHILD_NODE || children[i].kind == VR_SVO_CHILD_LEAF;
    }
    if (!any_deeper) {
      // 3. Nothing deeper: collapse. The record is the last one appended (no child appended any).
      out_.nodes.resize(out_.nodes.size() - VR_SVO_NODE_WORDS);
      out_.node_ids.pop_back();
      return as_leaf(pair);
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
    return {VR_SVO_CHILD_NODE, record};
  }
};

}  // namespace

SvoArrays build_svo(const SpatialIndex& index, const ViewTraversal& view,
                    const ResidentKeyframes& resident, double playhead,
                    const SelectionSettings& settings, SvoStats* stats, StoredTimes* stored,
                    std::span<const std::uint8_t> hidden) {
  SvoStats local;
  SvoStats& s = stats ? *stats : local;
  s = SvoStats{};
  StoredTimes fresh;
  return Builder(index, view, resident, playhead, settings, s, stored ? *stored : fresh, hidden)
      .run();
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
    if ((w[2] >> 16) != 0) fail(where + ": leaf " + std::to_string(leaf) + " unused LOD bits set");
    const float f = std::bit_cast<float>(w[3]);
    if (!(f >= 0.0f && f <= 1.0f))
      fail(where + ": leaf " + std::to_string(leaf) + " factor outside [0, 1]");
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
