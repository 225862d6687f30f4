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
  std::uint32_t ancestor_drawn = 0;       ///< target nodes drawn by an ancestor
  std::uint32_t holes = 0;                ///< target nodes with nothing resident at all
  std::vector<std::uint32_t> used_slots;  ///< atlas slots the leaves reference (unique)
};

/// Builds the SVO for the nodes visited by `view` at playhead p from the resident keyframe nodes.
/// `hidden` (per spatial node, nonzero: no ray reached it; empty: none is) only moves target
/// nodes from SvoStats::target_nodes to hidden_targets; they are drawn alike.
SvoArrays build_svo(const SpatialIndex& index, const ViewTraversal& view,
                    const ResidentKeyframes& resident, double playhead,
                    const SelectionSettings& settings = {}, SvoStats* stats = nullptr,
                    StoredTimes* stored = nullptr, std::span<const std::uint8_t> hidden = {});

/// Structural checks of an SVO: record 0 is a root without parent; every child word's index is in
/// range and every node record is reached exactly once, from the parent it names; word 9 holds a
/// leaf exactly when some octant is VR_SVO_CHILD_UP; depth < level_count; in each leaf record the
/// slots are < slot_count, both LOD differences ≤ the depth of the node it belongs to, and the
/// factor is in [0, 1]. Returns the problems found (empty: valid).
std::vector<std::string> validate_svo(std::span<const std::uint32_t> nodes,
                                      std::span<const std::uint32_t> leaves,
                                      std::uint32_t slot_count, std::uint32_t level_count);

}  // namespace volreel::stream
