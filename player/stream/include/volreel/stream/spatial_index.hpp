// spatial_index.hpp: the spatial octree and its keyframe nodes (Cesium patent [0034], [0058]–
// [0059]; docs/design.md, "Streaming"). The spatial octree is the same for every frame: the
// frame geometry's nodes (format/SPEC.md "Frame file"), of which those that a held frame has are
// present (the union of the held frames' brick octrees). Each spatial node (level, x, y, z) lists
// its keyframe nodes, one per held time step whose frame file has a brick there (a frame may leave
// a node without one: the node is then drawn by interpolating its neighbouring keyframes,
// format/SPEC.md "Keyframes"), sorted by time step; a keyframe node points at that brick's bytes
// (file, absolute offset, length). Residency in the atlas is keyed by (level, x, y, z, keyframe),
// so a node that leaves the view and comes back finds its brick where it left it.
//
// Time window. A container whose keyframe nodes fit IndexOptions::memory_bytes is held whole from
// the start. A larger one (a 1024³ frame has 34,472 nodes; ten thousand of them would hold
// hundreds of millions of keyframe nodes) holds a window of consecutive frames around the
// playhead: follow() moves it with the playhead, a background thread reads the frame indexes
// the window lacks (nearest the playhead first, ahead of it in its direction of travel), and each
// follow() adds those that extend the held range, within a time budget, and drops frames that
// left the window. A seek outside the held range empties it and starts again at the playhead.
// Keyframe ids (node, t) stay the same while the window moves; a keyframe node exists in the index
// only while its frame is held.
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
#include <deque>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <unordered_map>
#include <utility>
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

/// A keyframe node's id inside a SpatialIndex: its spatial node and time step, (node << 32) | t.
/// Ids order keyframe nodes by node, then by t; they stay the same while the time window moves.
using KeyframeId = std::uint64_t;
inline constexpr std::uint32_t no_node = 0xFFFFFFFFu;
inline constexpr KeyframeId no_keyframe = ~KeyframeId{0};
constexpr KeyframeId keyframe_id(std::uint32_t node, std::uint32_t t) {
  return (KeyframeId{node} << 32) | t;
}

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

/// A spatial node's held keyframe nodes, sorted by t. The time window grows and shrinks the list
/// at both ends, so it is one contiguous block with room on either side (a slide moves the held
/// nodes back to the middle now and then: O(1) a node on average). Their time steps are also kept
/// on their own: the searches by time that the scheduler and the selection run for every visited
/// node each frame touch a tenth of the cache lines (a time step is 4 bytes, a keyframe node 40).
class KeyframeList {
 public:
  std::size_t size() const { return end_ - begin_; }
  bool empty() const { return end_ == begin_; }
  const KeyframeNode& operator[](std::size_t i) const { return nodes_[begin_ + i]; }
  const KeyframeNode* begin() const { return nodes_.data() + begin_; }
  const KeyframeNode* end() const { return nodes_.data() + end_; }
  const KeyframeNode& front() const { return nodes_[begin_]; }
  const KeyframeNode& back() const { return nodes_[end_ - 1]; }
  /// The held time steps, ascending: times()[i] == (*this)[i].t.
  std::span<const std::uint32_t> times() const { return {times_.data() + begin_, size()}; }
  /// The position of the first keyframe node at a time step ≥ t (size() if none is).
  std::size_t lower_bound(std::uint32_t t) const;
  /// The position of the keyframe node at time step t (size() if there is none).
  std::size_t find(std::uint32_t t) const;
  /// Held keyframe nodes marked subtree_constant.
  std::size_t subtree_constants() const { return subtree_constants_; }
  /// Keyframe nodes the list has room for.
  std::size_t capacity() const { return nodes_.size(); }

  /// At the front, k.t must be below front().t; at the back, above back().t.
  void push_front(const KeyframeNode& k);
  void push_back(const KeyframeNode& k);
  void pop_front();
  void pop_back();

 private:
  std::vector<KeyframeNode> nodes_;
  std::vector<std::uint32_t> times_;
  std::size_t begin_ = 0, end_ = 0;
  std::size_t subtree_constants_ = 0;
  /// Moves the held nodes (into a larger block when they fill half of it) so that the side
  /// `front` has room for at least one more.
  void make_room(bool front);
};

struct SpatialNode {
  NodeKey key;
  std::array<std::uint32_t, 3> lo{}, hi{};  ///< bounds in finest voxels, clipped to the volume
  std::uint32_t parent = no_node;
  /// Present children (a held frame has them), no_node elsewhere.
  std::array<std::uint32_t, 8> children{no_node, no_node, no_node, no_node,
                                        no_node, no_node, no_node, no_node};
  bool has_children = false;
  std::uint32_t held_frames = 0;  ///< held frames that have this node (0: absent)
  bool present() const { return held_frames > 0; }
};

struct IndexOptions {
  /// Keyframe nodes held at once, in bytes, counted as 70 bytes each: the node and its time step
  /// with the room its list keeps to grow (half as much again), and the node id that drops it. A
  /// container that needs more is held as a time window of as many frames as fit (at least
  /// 2·max_keyframe_gap + 4).
  std::uint64_t memory_bytes = 128ull << 20;
  /// Time follow() spends adding frames, at least one frame when one is ready.
  double follow_budget_s = 0.002;
};

/// The frame geometry's nodes (all absent), shared by an index and its copies.
struct IndexGeometry {
  std::array<std::uint32_t, 3> dims{};
  std::vector<format::LevelGeometry> levels;
  std::vector<SpatialNode> nodes;
  /// Node id of brick (x, y, z) of level l: ids[first[l] + x + grid_x·(y + grid_y·z)].
  std::vector<std::uint32_t> first, ids;
  /// no_node outside the level grids.
  std::uint32_t find(const NodeKey& key) const;
};

/// One frame's part of the index, read from its file.
struct HeldFrame {
  std::uint32_t t = 0;
  std::vector<std::uint32_t> nodes;                               ///< node ids it has
  std::vector<std::pair<std::uint32_t, KeyframeNode>> keyframes;  ///< node id, its brick
  std::string error;  ///< not empty: the frame could not be read (it holds nothing)
};

class SpatialIndex;

/// Builds a SpatialIndex one frame at a time (frames in any order); every frame is held.
class SpatialIndexBuilder {
 public:
  /// dims: the volume's finest size; frame_count: time steps of the series.
  SpatialIndexBuilder(std::array<std::uint32_t, 3> dims, std::size_t frame_count);
  /// Adds frame t's nodes and bricks; `file` is where a loader reads the bytes. Throws
  /// format::FormatError if the frame's dims or levels disagree with the index.
  void add_frame(std::uint32_t t, const format::FrameView& frame, std::filesystem::path file);
  SpatialIndex build() &&;

 private:
  std::shared_ptr<const IndexGeometry> geometry_;
  std::vector<std::filesystem::path> files_;
  std::vector<std::optional<HeldFrame>> frames_;
};

class SpatialIndex {
 public:
  SpatialIndex();
  ~SpatialIndex();
  /// A copy holds the same frames; a windowed index's copy reads with its own thread.
  SpatialIndex(const SpatialIndex& other);
  SpatialIndex& operator=(const SpatialIndex& other);
  SpatialIndex(SpatialIndex&&) noexcept;
  SpatialIndex& operator=(SpatialIndex&&) noexcept;

  std::array<std::uint32_t, 3> dims() const;
  std::uint32_t level_count() const;
  std::size_t frame_count() const { return files_.size(); }
  /// Finest voxels per axis of one voxel of level l: 2^(L−1−l).
  std::uint32_t voxel_size(std::uint32_t level) const { return 1u << (level_count() - 1 - level); }

  /// Every node of the frame geometry; see SpatialNode::present().
  std::size_t node_count() const { return nodes_.size(); }
  /// The root is node 0 (when the index is not empty); nodes are breadth-first, Morton order
  /// inside a level.
  const SpatialNode& node(std::uint32_t id) const { return nodes_[id]; }
  /// no_node if the geometry has no such node.
  std::uint32_t find(const NodeKey& key) const;
  /// The ancestor `up` levels above node id (up = 0: id itself), or no_node past the root.
  std::uint32_t ancestor(std::uint32_t id, std::uint32_t up) const;

  /// Keyframe nodes held.
  std::size_t keyframe_count() const { return keyframe_count_; }
  /// The ids of the keyframe nodes held, in id order (by node, then t).
  std::vector<KeyframeId> held_keyframes() const;
  /// The node's held keyframe nodes, sorted by t.
  const KeyframeList& keyframes(std::uint32_t node) const { return keyframes_[node]; }
  /// A held keyframe node (find_keyframe returned its id).
  const KeyframeNode& keyframe(KeyframeId id) const;
  static std::uint32_t node_of(KeyframeId id) { return static_cast<std::uint32_t>(id >> 32); }
  /// The held keyframe node of `node` at time step t, or no_keyframe.
  KeyframeId find_keyframe(std::uint32_t node, std::uint32_t t) const;
  KeyframeId find_keyframe(const KeyframeKey& key) const;
  KeyframeKey key(KeyframeId id) const;

  /// The file of frame t (empty if the frame was not indexed).
  const std::filesystem::path& frame_file(std::uint32_t t) const { return files_[t]; }

  // ---- The time window ---------------------------------------------------------------------
  /// Held frames: [held_begin(), held_end()) (failed frames count as held, without nodes).
  std::uint32_t held_begin() const { return held_begin_; }
  std::uint32_t held_end() const { return held_end_; }
  /// The most frames held at once (frame_count() when the whole container is held).
  std::size_t window_frames() const { return window_; }
  bool windowed() const { return window_ < frame_count(); }
  /// Whether every frame within max_keyframe_gap of the playhead is held: the frames the
  /// selection and the scheduler need there.
  bool holds_around(double playhead) const;
  /// Moves the window with the playhead (keyframe units; velocity in keyframes per second, for
  /// the direction of travel): adds the frames the reader has that extend the held range (within
  /// IndexOptions::follow_budget_s), drops those outside the window, and tells the reader what
  /// to read next. Frames that failed to read add their message to `errors`. Nothing to do when
  /// the whole container is held.
  void follow(double playhead, double velocity, std::vector<std::string>* errors);
  /// Bytes the index holds: nodes, keyframe nodes and frames read but not yet added.
  std::uint64_t memory_bytes() const;

 private:
  friend class SpatialIndexBuilder;
  friend SpatialIndex build_spatial_index(const format::Container&, std::vector<std::string>*,
                                          const IndexOptions&);
  struct Reader;

  std::shared_ptr<const IndexGeometry> geometry_;
  std::vector<std::filesystem::path> files_;
  std::vector<SpatialNode> nodes_;
  std::vector<KeyframeList> keyframes_;
  std::size_t keyframe_count_ = 0;
  std::uint32_t held_begin_ = 0, held_end_ = 0;
  std::size_t window_ = 0;
  std::uint32_t max_gap_ = 1;
  IndexOptions options_;
  /// Per held frame (windowed index only), to drop it again: the nodes with its bricks, and the
  /// nodes it has unless it has every node of the geometry (whole).
  struct HeldRecord {
    bool whole = false;
    std::vector<std::uint32_t> nodes, keyframe_nodes;
  };
  std::deque<HeldRecord> held_;
  std::size_t whole_frames_ = 0;  ///< held frames with every node, counted once in held_frames
  std::shared_ptr<const format::Container> container_;  ///< windowed: where frames are read
  std::unique_ptr<Reader> reader_;

  void reset_nodes();
  void hold(HeldFrame frame, bool at_front);
  /// Adds delta to the held_frames of `ids`, linking or unlinking those that appear or vanish.
  void count_nodes(std::span<const std::uint32_t> ids, int delta);
  void drop(bool front);
  void start_reader();
};

/// Indexes a container (Container::open_frame_index: header, levels, nodes, offsets and the index
/// CRC are validated): every frame now when they fit options.memory_bytes, else a time window that
/// follow() fills (the first frames are read when follow() first runs). A frame that is missing or
/// fails validation is left out and its error ("frames/000003.vrf: offset 148: expected …")
/// appended to `errors` (for a windowed index, by the follow() that meets it); nothing is thrown
/// for a bad frame.
SpatialIndex build_spatial_index(const format::Container& container,
                                 std::vector<std::string>* errors = nullptr,
                                 const IndexOptions& options = {});

}  // namespace volreel::stream
