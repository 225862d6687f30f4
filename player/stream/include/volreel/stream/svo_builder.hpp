// svo_builder.hpp: the array-encoded sparse voxel octree the renderers walk (Cesium patent [0049];
// layout in player/include/volreel/player/svo_layout.h), built each frame from the view traversal
// and the keyframe pairs of the pre-render selection (selection.hpp).
//
// Building, in numbered steps, from the root down the nodes the view traversal visited:
//   1. A node that is not refined (SSE at target, or finest) is a leaf: a leaf record with its
//      keyframe pair; if both picks come from ancestors it is not drawn itself — its parent marks
//      it VR_SVO_CHILD_UP and draws it from the parent's own leaf record ([0048]); with nothing
//      resident anywhere above it, it is VR_SVO_CHILD_EMPTY (a hole until the first brick arrives).
//   2. A refined node gets a node record; octants with no spatial node (outside the volume) are
//      VR_SVO_CHILD_EMPTY, octants outside the view and children drawn by an ancestor are
//      VR_SVO_CHILD_UP, drawn by this node's own leaf record (word 9).
//   3. A refined node none of whose children produced a node or leaf record collapses into a
//      leaf (step 1), so the tree goes no deeper than the data it draws.
//   4. Record 0 is always the root's node record (all octants VR_SVO_CHILD_UP when the root is a
//      leaf itself).
// Only resident keyframe nodes appear: every atlas slot in a leaf record comes from the
// ResidentKeyframes given.
#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "volreel/player/svo_layout.h"
#include "volreel/stream/priorities.hpp"
#include "volreel/stream/selection.hpp"
#include "volreel/stream/spatial_index.hpp"

namespace volreel::stream {

struct SvoArrays {
  std::vector<std::uint32_t> nodes;   ///< VR_SVO_NODE_WORDS words per node record
  std::vector<std::uint32_t> leaves;  ///< VR_SVO_LEAF_WORDS words per leaf record
  /// Per node record, the spatial node it stands for (no_node: the root of an SVO that draws
  /// nothing; a root that is a leaf itself is node 0's record).
  std::vector<std::uint32_t> node_ids;
};

struct SvoStats {
  std::uint32_t target_nodes = 0;     ///< visited nodes that are not refined: the desired LOD
  std::uint32_t at_target_nodes = 0;  ///< of those, drawn with both keyframes at full detail
  /// Visited nodes that are not refined but hidden (no ray reached them in the last frame drawn):
  /// not in target_nodes.
  std::uint32_t hidden_targets = 0;
  std::uint32_t node_records = 0, leaf_records = 0;
  std::uint32_t ancestor_drawn = 0;  ///< target nodes drawn by an ancestor
  std::uint32_t holes = 0;           ///< target nodes with nothing resident at all
  std::uint32_t blended_leaves = 0;  ///< leaf records whose weights blend (not all 255)
  /// Restricted drawing: nodes whose own keyframe pair was chosen coarser so that the regions
  /// they draw touch none drawn two or more levels coarser.
  std::uint32_t restricted_nodes = 0;
  std::uint32_t restriction_builds = 0;   ///< extra builds the restriction took
  std::vector<std::uint32_t> used_slots;  ///< atlas slots the leaves reference (unique)
};

/// Level-of-detail blending (Thiele, Matthes, Froehlich §4.2–4.3; svo_layout.h words 4–8).
struct LodBlendSettings {
  /// Temporal blending: a region that was drawn from an ancestor's bricks in the last build and is
  /// now drawn from its own fades in from its parent's drawing over this many seconds. 0: off,
  /// the default: it lowered image PSNR and did not lower popping measurably in `volreel bench
  /// stream` (docs/design.md, "Level-of-detail blending").
  double fade_s = 0.0;
  /// Fade-out on collapse: a node whose children drew it in the last build and that is now drawn
  /// by itself keeps drawing the children's bricks (their own, at the playhead's times), fading
  /// towards its own drawing over this many seconds (docs/design.md, "Level-of-detail
  /// blending"). 0: at once. On by default: on `volreel bench stream`'s tours it removed the jump
  /// of a collapse and never lowered image PSNR (the finer data is shown longer).
  double fade_out_s = 0.3;
  /// Spatial blending: a region's corners next to a region drawn coarser take the parent's
  /// drawing, so that the value goes over smoothly towards the coarser neighbour. Off by default:
  /// without a restricted working set it lowered image PSNR and did not lower the seam metric in
  /// `volreel bench stream` (docs/design.md, "Level-of-detail blending").
  bool spatial = false;
};

/// Scratch of the restricted drawing (SelectionSettings::restricted), per spatial node: the
/// regions one build draws and the data level each node's own drawing is held to.
struct DrawnRegions {
  std::uint32_t pass = 0;               ///< passes so far (stamps below: 0 never)
  std::uint32_t caps_from = 0;          ///< first pass of the current build (caps older are void)
  std::vector<std::uint32_t> stamp;     ///< pass that drew the node's region (or refined it)
  std::vector<std::uint32_t> owner;     ///< the node whose keyframe pair draws the region
  std::vector<std::uint8_t> level;      ///< its data level (exact_level: exact constants)
  std::vector<std::uint8_t> refined;    ///< a node record, drawn by its children
  std::vector<std::uint32_t> cap_pass;  ///< pass that set the node's cap
  std::vector<std::uint8_t> cap;        ///< the finest data level the node's own pair may draw at
  std::vector<std::uint32_t> nodes;     ///< the regions the current pass recorded
  static constexpr std::uint8_t exact_level = 255;
  /// Sizes the per-node arrays for an index of `node_count` nodes (clears them when it changes).
  void reset(std::size_t node_count);
  void start_build();  ///< caps set before now are void
  void start_pass();   ///< regions recorded before now are void
};

/// What level-of-detail blending keeps from one build to the next, per spatial node, and the
/// scratch of one build. Pass the same object to every build_svo of one view.
struct LodBlendState {
  LodBlendSettings settings;
  DrawnRegions drawn;       ///< the restricted drawing's scratch (used also when nothing blends)
  std::uint32_t build = 0;  ///< builds so far (stamps below: 0 never)
  std::vector<std::uint32_t> visited_build;  ///< last build the view visited the node in
  std::vector<std::uint32_t> own_build;      ///< last build it was drawn from a leaf of its own
  std::vector<double> since;                 ///< when it was first drawn from its own leaf
  std::vector<std::uint32_t> out_build;      ///< last build it faded out (a collapse)
  std::vector<double> out_since;             ///< when its collapse began
  // One build's regions, per spatial node: drawn (own leaf or an ancestor's as "up") at data
  // level `region_level` with temporal weight `region_t`, or a node record (refined).
  std::vector<std::uint32_t> region_build;
  std::vector<std::uint8_t> region_level, region_refined;
  std::vector<float> region_t;
  /// Sizes the per-node arrays for an index of `nodes` nodes (clears them when it changes). The
  /// state belongs to one index: call reset(0) before using it with another of the same size.
  void reset(std::size_t nodes);
};

/// Builds the SVO for the nodes visited by `view` at playhead p from the resident keyframe nodes.
/// `hidden` (per spatial node, nonzero: no ray reached it; empty: none is) only moves target
/// nodes from SvoStats::target_nodes to hidden_targets; they are drawn alike.
/// Restricted drawing (settings.restricted, Thiele, Matthes, Froehlich §4.1 applied to what is
/// drawn): where two regions of the SVO touch (by a face, an edge or a corner), their data levels
/// differ by at most one. While bricks stream in, a node drawn from its own bricks can touch one
/// drawn from a grandparent's; the finer one is then drawn coarser, its pair chosen again from at
/// least the level above the coarse neighbour's + 1 (select_keyframe_pair's min_lod_difference),
/// and the build repeats until no region needs it (SvoStats::restricted_nodes). A region's data
/// level here counts exact constants as exact: they neither take nor impose a limit.
/// `blend` (null: no blending, every leaf's weights VR_SVO_BLEND_NONE; with `blend` and neither
/// fade_s nor spatial set, only its scratch is used): level-of-detail blending
/// at time `now` (seconds on the caller's clock). A node drawn from a leaf record of its own (a
/// VR_SVO_CHILD_LEAF child) gets its parent's keyframe pair as its coarse pair (LOD differences
/// + 1) and corner weights: the least of its temporal weight min(1, (now − since) / fade_s) and
/// those of the regions drawn at the same data level that share the corner (only while the node
/// itself is fading in: one that has faded in keeps 1 when a neighbour starts), or 0 when a region
/// sharing the corner is drawn at a coarser data level (a region's data level: its node's level
/// minus the LOD difference of the coarser keyframe it reads). A node's `since` is the build's
/// `now` when it is first drawn from its own leaf after being visited and drawn from an
/// ancestor's leaf in the previous build; a node not visited then, drawn by its children (a
/// collapse) or by nothing (a hole) is drawn at once (weight 1).
SvoArrays build_svo(const SpatialIndex& index, const ViewTraversal& view,
                    const ResidentKeyframes& resident, double playhead,
                    const SelectionSettings& settings = {}, SvoStats* stats = nullptr,
                    StoredTimes* stored = nullptr, std::span<const std::uint8_t> hidden = {},
                    LodBlendState* blend = nullptr, double now = 0);

/// Structural checks of an SVO: record 0 is a root without parent; every child word's index is in
/// range and every node record is reached exactly once, from the parent it names; word 9 holds a
/// leaf exactly when some octant is VR_SVO_CHILD_UP; depth < level_count; in each leaf record the
/// slots are < slot_count, both LOD differences ≤ the depth of the node it belongs to, and the
/// factor is in [0, 1]; a leaf that blends (weights not VR_SVO_BLEND_NONE) has a coarse pair whose
/// slots are < slot_count, whose LOD differences are in [1, depth] and whose factor is in [0, 1].
/// Returns the problems found (empty: valid).
std::vector<std::string> validate_svo(std::span<const std::uint32_t> nodes,
                                      std::span<const std::uint32_t> leaves,
                                      std::uint32_t slot_count, std::uint32_t level_count);

}  // namespace volreel::stream
