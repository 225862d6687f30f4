// spatial_index.hpp: the spatial octree and its keyframe nodes (Cesium patent [0034], [0058]–
// [0059]; docs/design.md, "Streaming"). The spatial octree is the same for every frame: it is the
// union of the frames' brick octrees (format/SPEC.md "Frame file"). Each spatial node
// (level, x, y, z) lists its keyframe nodes, one per time step whose frame file has a brick there
// (a frame may leave a node without one: the node is then drawn by interpolating its neighbouring
// keyframes, format/SPEC.md "Keyframes"), sorted by time step; a keyframe node points at that
// brick's bytes (file, absolute offset, length). Residency in the atlas is keyed by (level, x, y,
// z, keyframe), so a node that leaves the view and comes back finds its brick where it left it.
//
// Geometry (player/include/volreel/player/svo_layout.h): with L levels, a node of level l at brick
// coordinates c covers finest voxels [c·34·2^(L−1−l), (c+1)·34·2^(L−1−l)) per axis; bounds() clips
// that box to the volume. Children of c are 2c + (i & 1, (i >> 1) & 1, (i >> 2) & 1), octant i.
//
// A node of type `empty` in frame t (format::NodeType::empty) is a constant subtree: frame t has
// no bricks below it. Its keyframe node is marked subtree_constant; the selection treats it as
// exact data for the descendants (selection.hpp).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

#include "volreel/format/container.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::stream {

/// A spatial node's position: octree level (0 = root) and brick coordinates within the level.
struct NodeKey {
  std::uint32_t level = 0, x = 0, y = 0, z = 0;
  friend bool operator==(const NodeKey&, const NodeKey&) = default;
};

/// A keyframe node's identity, the residency key of the atlas: spatial node and time step t.
struct KeyframeKey {
  std::uint32_t level = 0, x = 0, y = 0, z = 0, t = 0;
  friend bool operator==(const KeyframeKey&, const KeyframeKey&) = default;
};

struct NodeKeyHash {
  std::size_t operator()(const NodeKey& k) const noexcept;
};
struct KeyframeKeyHash {
  std::size_t operator()(const KeyframeKey& k) const noexcept;
};

/// Dense index of a keyframe node inside a SpatialIndex (0 .. keyframe_count()−1).
using KeyframeId = std::uint32_t;
inline constexpr std::uint32_t no_node = 0xFFFFFFFFu;
inline constexpr KeyframeId no_keyframe = 0xFFFFFFFFu;

/// One time step's brick at a spatial node: where its bytes are.
struct KeyframeNode {
  std::uint32_t t = 0;            ///< time step (keyframe index)
  std::uint32_t brick = 0;        ///< brick index inside frame t's file
  std::uint64_t offset = 0;       ///< absolute byte offset of the payload in the frame file
  std::uint32_t bytes = 0;        ///< payload length
  std::uint32_t crc32c = 0;       ///< the payload's CRC-32C (the frame's index)
  std::uint64_t histogram = 0;    ///< the node's 64-bin histogram over the sequence's value range
  bool constant = false;          ///< 4-byte payload: every voxel of the brick is one value
  bool subtree_constant = false;  ///< node type `empty`: the whole subtree is that value
};

struct SpatialNode {
  NodeKey key;
  std::array<std::uint32_t, 3> lo{}, hi{};  ///< bounds in finest voxels, clipped to the volume
  std::uint32_t parent = no_node;
  std::array<std::uint32_t, 8> children{no_node, no_node, no_node, no_node,
                                        no_node, no_node, no_node, no_node};
  bool has_children = false;
  std::uint32_t first_keyframe = 0, keyframe_count = 0;  ///< range in the index's keyframe array
};

class SpatialIndex;

/// Builds a SpatialIndex one frame at a time (frames in any order).
class SpatialIndexBuilder {
 public:
  /// dims: the volume's finest size; frame_count: time steps of the series.
  SpatialIndexBuilder(std::array<std::uint32_t, 3> dims, std::size_t frame_count);
  /// Adds frame t's nodes and bricks; `file` is where a loader reads the bytes. Throws
  /// format::FormatError if the frame's dims or levels disagree with the index.
  void add_frame(std::uint32_t t, const format::FrameView& frame, std::filesystem::path file);
  SpatialIndex build() &&;

 private:
  struct Entry {
    NodeKey key;
    KeyframeNode keyframe;
  };
  std::array<std::uint32_t, 3> dims_;
  std::size_t frame_count_;
  std::vector<format::LevelGeometry> geometry_;
  std::vector<std::filesystem::path> files_;
  std::vector<Entry> entries_;
};

class SpatialIndex {
 public:
  SpatialIndex() = default;

  std::array<std::uint32_t, 3> dims() const { return dims_; }
  std::uint32_t level_count() const { return static_cast<std::uint32_t>(geometry_.size()); }
  std::size_t frame_count() const { return files_.size(); }
  /// Finest voxels per axis of one voxel of level l: 2^(L−1−l).
  std::uint32_t voxel_size(std::uint32_t level) const { return 1u << (level_count() - 1 - level); }

  std::size_t node_count() const { return nodes_.size(); }
  /// The root is node 0 (when the index is not empty); nodes are breadth-first, Morton order
  /// inside a level.
  const SpatialNode& node(std::uint32_t id) const { return nodes_[id]; }
  /// no_node if absent.
  std::uint32_t find(const NodeKey& key) const;
  /// The ancestor `up` levels above node id (up = 0: id itself), or no_node past the root.
  std::uint32_t ancestor(std::uint32_t id, std::uint32_t up) const;

  std::size_t keyframe_count() const { return keyframes_.size(); }
  /// The node's keyframe nodes, sorted by t.
  std::span<const KeyframeNode> keyframes(std::uint32_t node) const;
  const KeyframeNode& keyframe(KeyframeId id) const { return keyframes_[id]; }
  std::uint32_t node_of(KeyframeId id) const { return keyframe_node_[id]; }
  /// The keyframe node of `node` at time step t, or no_keyframe.
  KeyframeId find_keyframe(std::uint32_t node, std::uint32_t t) const;
  KeyframeId find_keyframe(const KeyframeKey& key) const;
  KeyframeKey key(KeyframeId id) const;

  /// The file of frame t (empty if the frame was not indexed).
  const std::filesystem::path& frame_file(std::uint32_t t) const { return files_[t]; }

 private:
  friend class SpatialIndexBuilder;
  std::array<std::uint32_t, 3> dims_{};
  std::vector<format::LevelGeometry> geometry_;
  std::vector<std::filesystem::path> files_;
  std::vector<SpatialNode> nodes_;
  std::unordered_map<NodeKey, std::uint32_t, NodeKeyHash> lookup_;
  std::vector<KeyframeNode> keyframes_;
  std::vector<std::uint32_t> keyframe_node_;
};

/// Indexes every frame of a container (Container::open_frame: header, levels, nodes, offsets and
/// the index CRC are validated). A frame that is missing or fails validation is left out and its
/// error ("frames/000003.vrf: offset 148: expected …") appended to `errors`; nothing is thrown for
/// a bad frame.
SpatialIndex build_spatial_index(const format::Container& container,
                                 std::vector<std::string>* errors = nullptr);

}  // namespace volreel::stream
