// selection.hpp: pre-render selection of two keyframe nodes per spatial node (Cesium patent
// [0046]–[0048], [0065]–[0075]; docs/design.md, "Streaming", step 4), from the keyframe nodes
// resident in the atlas only.
//
// For each side of the playhead p (before: t ≤ p, after: t ≥ p), in numbered steps:
//   1. The node's own candidate is its resident keyframe node on that side nearest p, scored by
//      its distance |t − p| ([0070]). If the node has none on that side, its nearest resident
//      keyframe node on the other side stands in, its distance × 200 ([0047]).
//      Sparse keyframes (volreel, format/SPEC.md "Keyframes"): a node need not have a keyframe
//      node at every time step; between two of them it is their interpolation. So a candidate on
//      its side is scored by how far it lies from the node's stored state nearest p, plus the
//      distance from p to the nearest time step on that side: |t − t*| + |step − p|, where t* is
//      the nearest step at which the node has a keyframe node or an ancestor a constant subtree
//      (for an ancestor's own candidate, its own nearest keyframe node), and step = floor(p)
//      before, ceil(p) after. When every step has a keyframe node, t* = step and this is |t − p|.
//      A node's own stored state far from p so beats a coarser ancestor at p.
//   2. Each ancestor `up` levels higher offers its candidate the same way, its score multiplied
//      by the handicap exp(4·up) ([0046], [0072]).
//   3. The candidate with the smallest score is kept ([0073]–[0074]). All ancestors are examined
//      (not only while each next one improves): the handicap grows so fast that this changes a
//      pick only when a nearer ancestor has nothing resident at all, and then the farther
//      ancestor is the right answer.
// Exception (volreel's choice, documented): the keyframe node of an ancestor that is a constant
// subtree at that time step (format::NodeType::empty) is exact data for the node — the frame holds
// no finer brick there — so it takes no handicap and counts as the node's own.
// If both picks come from ancestors (and are not exact), the node is drawn by an ancestor
// ([0048]). The interpolation factor is f = clamp((p − t_A) / (t_B − t_A), 0, 1), A the pick before
// and B the pick after (f = 0 when t_A = t_B).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {

struct SelectionSettings {
  double ancestor_handicap = 4.0;      ///< score × exp(ancestor_handicap · levels up)
  double missing_side_factor = 200.0;  ///< score × this when a node has nothing on one side
  /// Restricted drawing (svo_builder.hpp, build_svo): regions of the SVO that touch are drawn
  /// from data at most one level apart, a finer one drawn coarser where needed. On by default:
  /// it completes the restricted working set that spatial blending assumes, and on the
  /// benchmark tours it changed mean image PSNR by at most 0.01 dB (docs/benchmarks.md,
  /// "Restricted working set").
  bool restricted = true;
};

/// A keyframe node in the atlas.
struct ResidentKeyframe {
  KeyframeId keyframe = no_keyframe;
  std::uint32_t slot = 0;
};

/// The resident keyframe nodes grouped by spatial node and sorted by t, for the selection.
class ResidentKeyframes {
 public:
  /// Replaces the contents (entries in any order).
  void assign(const SpatialIndex& index, std::span<const ResidentKeyframe> entries);
  /// The node's resident keyframe nodes, sorted by time step.
  std::span<const ResidentKeyframe> of_node(std::uint32_t node) const;
  std::size_t size() const { return entries_.size(); }

 private:
  std::vector<ResidentKeyframe> entries_;
  std::vector<std::uint32_t> first_, count_;  ///< per node; count 0 when none
};

struct KeyframePick {
  KeyframeId keyframe = no_keyframe;  ///< no_keyframe: nothing resident here or above
  std::uint32_t t = 0;
  std::uint32_t slot = 0;
  std::uint32_t lod_difference = 0;  ///< levels above the spatial node (0: its own brick)
  double score = 0;                  ///< distance × handicaps (smaller is better)
  bool exact = false;                ///< own brick, or a constant ancestor (exact data)
  bool valid() const { return keyframe != no_keyframe; }
};

struct KeyframePair {
  KeyframePick a, b;  ///< before and after the playhead
  float factor = 0;   ///< value = (1 − factor)·A + factor·B
  bool valid() const { return a.valid() && b.valid(); }
  /// Both picks come from ancestors (not exact): an ancestor draws this node ([0048]).
  bool drawn_by_ancestor() const { return !a.exact && !b.exact; }
  /// Both picks are the node's own level of detail (or exact constants).
  bool at_full_detail() const { return valid() && a.exact && b.exact; }
};

/// The time steps nearest a playhead at which nodes store their state (a keyframe node, or a
/// constant subtree's), remembered for one playhead: every descendant of a node asks for its
/// ancestors' times, so one selection pass over a view looks each node up once per side.
class StoredTimes {
 public:
  /// Starts over for `index` (which must not change until the next start) and playhead p;
  /// remember = false: every question is looked up afresh (no memory per node).
  void start(const SpatialIndex& index, double playhead, bool remember = true);
  /// The nearest step on the before (t ≤ p) or after (t ≥ p) side at which `node` has a keyframe
  /// node (constant_only: one that is a constant subtree); −1 when it has none there.
  double nearest(std::uint32_t node, bool after, bool constant_only);

 private:
  const SpatialIndex* index_ = nullptr;
  double playhead_ = 0;
  std::uint32_t generation_ = 0;
  std::vector<std::uint32_t> stamp_;  ///< 4 per node: generation_ when values_ holds the answer
  std::vector<double> values_;
};

/// Two keyframe nodes for spatial node `node` at playhead p (keyframe units), from `resident`.
/// `stored`: a StoredTimes started for this index and playhead, shared by the calls of one pass
/// (null: looked up for this call alone). `min_lod_difference`: candidates from fewer levels above
/// the node are passed over, except constant subtrees (exact data); the restricted drawing of
/// svo_builder.hpp draws a node coarser this way.
KeyframePair select_keyframe_pair(const SpatialIndex& index, std::uint32_t node, double playhead,
                                  const ResidentKeyframes& resident,
                                  const SelectionSettings& settings = {},
                                  StoredTimes* stored = nullptr,
                                  std::uint32_t min_lod_difference = 0);

}  // namespace volreel::stream
