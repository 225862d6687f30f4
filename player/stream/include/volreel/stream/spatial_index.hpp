// spatial_index.hpp: the spatial octree and its keyframe nodes (Cesium patent [0034], [0058]–
// [0059]; docs/design.md, "Streaming"). The spatial octree is the same for every frame: the
// frame geometry's nodes (format/SPEC.md "Frame file"), of which those that a held frame has are
// present (the union of the held frames' brick octrees). Each spatial node (level, x, y, z) has
// keyframe nodes, one per held time step whose frame file has a brick there (a frame may leave a
// node without one: the node is then drawn by interpolating its neighbouring keyframes,
// format/SPEC.md "Keyframes"); a keyframe node points at that brick's bytes (file, absolute
// offset, length). They are kept by frame (each held frame's array, as read) with one bit per
// node and held frame saying which frames have one (HeldTimes). Residency in the atlas is keyed by
// (level, x, y, z, keyframe), so a node that leaves the view and comes back finds its brick where
// it left it.
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
// coordinates c covers finest voxels [c·I·2^(L−1−l), (c+1)·I·2^(L−1−l)) per axis, I the bricks'
// interior (the container's brick size − 2, 34 for 36³ bricks); bounds() clips
// that box to the volume. Children of c are 2c + (i & 1, (i >> 1) & 1, (i >> 2) & 1), octant i.
//
// A node of type `empty` in frame t (format::NodeType::empty) is a constant subtree: frame t has
// no bricks below it. Its keyframe node is marked subtree_constant; the selection treats it as
// exact data for the descendants (selection.hpp).
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
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

inline constexpr std::uint32_t no_time = 0xFFFFFFFFu;

/// A spatial node's held time steps (those of its keyframe nodes), as a view of one bit per held
/// frame: time step t is bit t mod ring of the node's words, for t in the held range [begin, end),
/// which is at most ring long. Adding or dropping a frame sets or clears one bit per node it has a
/// brick at, in a table small enough to stay in cache, where a list per node would take a cache
/// miss per node. The view is valid until the index's window next moves.
class HeldTimes {
 public:
  HeldTimes() = default;
  /// words: ring / 64 words of bits; count: the bits set among those of [begin, end).
  HeldTimes(const std::uint64_t* words, std::uint32_t ring, std::uint32_t begin, std::uint32_t end,
            std::uint32_t count)
      : words_(words), ring_(ring), begin_(begin), end_(end), count_(count) {}

  std::size_t size() const { return count_; }
  bool empty() const { return count_ == 0; }
  bool contains(std::uint32_t t) const {
    if (t < begin_ || t >= end_) return false;
    const std::uint32_t slot = t % ring_;
    return (words_[slot >> 6] >> (slot & 63)) & 1u;
  }
  /// The latest held time step ≤ t, or no_time.
  std::uint32_t at_or_before(std::uint32_t t) const;
  /// The earliest held time step ≥ t, or no_time.
  std::uint32_t at_or_after(std::uint32_t t) const;
  /// Calls f(t) for the held time steps in [lo, hi], ascending.
  template <class F>
  void for_each(std::uint32_t lo, std::uint32_t hi, F&& f) const {
    if (count_ == 0) return;
    lo = std::max(lo, begin_);
    hi = std::min(hi, end_ - 1);
    if (lo > hi) return;
    const std::uint32_t first = lo % ring_, n = hi - lo + 1;
    // Slots [first, first + n) of the ring, in at most two runs.
    const std::uint32_t run = std::min(n, ring_ - first);
    for_each_bit(first, first + run - 1, [&](std::uint32_t slot) { f(lo + (slot - first)); });
    if (run < n) for_each_bit(0, n - run - 1, [&](std::uint32_t slot) { f(lo + run + slot); });
  }
  /// Every held time step, ascending.
  template <class F>
  void for_each(F&& f) const {
    for_each(begin_, end_ == 0 ? 0 : end_ - 1, f);
  }

 private:
  const std::uint64_t* words_ = nullptr;
  std::uint32_t ring_ = 64, begin_ = 0, end_ = 0, count_ = 0;

  /// Calls f(slot) for the set bits of slots [a, b], ascending.
  template <class F>
  void for_each_bit(std::uint32_t a, std::uint32_t b, F&& f) const {
    for (std::uint32_t w = a >> 6; w <= b >> 6; ++w) {
      std::uint64_t bits = words_[w];
      if (w == a >> 6) bits &= ~std::uint64_t{0} << (a & 63);
      if (w == b >> 6) bits &= ~std::uint64_t{0} >> (63 - (b & 63));
      while (bits != 0) {
        f(w * 64 + static_cast<std::uint32_t>(std::countr_zero(bits)));
        bits &= bits - 1;
      }
    }
  }
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
  /// Keyframe nodes held at once, in bytes, counted as 56 bytes for each node of each held frame:
  /// the keyframe node with its node id, the node's entry in the frame's table of positions, and
  /// the node id that drops it. A container that needs more is held as a time window of as many
  /// frames as fit (at least 2·max_keyframe_gap + 4).
  std::uint64_t memory_bytes = 128ull << 20;
  /// Time follow() spends adding frames, at least one frame when one is ready.
  double follow_budget_s = 0.002;
};

/// The frame geometry's nodes (all absent), shared by an index and its copies.
struct IndexGeometry {
  format::BrickShape shape;
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
  /// Per node id of the geometry, its brick's position in `keyframes` (no_node: none).
  std::vector<std::uint32_t> positions;
  std::string error;  ///< not empty: the frame could not be read (it holds nothing)
  /// Set when held: it has every node of the geometry (its node list is then not kept).
  bool whole = false;
};

class SpatialIndex;

/// Builds a SpatialIndex one frame at a time (frames in any order); every frame is held.
class SpatialIndexBuilder {
 public:
  /// dims: the volume's finest size; frame_count: time steps of the series; shape: the bricks'.
  SpatialIndexBuilder(std::array<std::uint32_t, 3> dims, std::size_t frame_count,
                      format::BrickShape shape = {});
  /// Adds frame t's nodes and bricks; `file` is where a loader reads the bytes. Throws
  /// format::FormatError if the frame's dims, brick size or levels disagree with the index.
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
  /// The bricks' tiling (the container's brick size).
  format::BrickShape shape() const;
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
  /// The time steps of the node's held keyframe nodes.
  HeldTimes times(std::uint32_t node) const {
    return {time_bits_.data() + node * words_, ring_, held_begin_, held_end_, held_counts_[node]};
  }
  /// Those of them marked subtree_constant.
  HeldTimes constant_times(std::uint32_t node) const {
    return {constant_bits_.data() + node * words_, ring_, held_begin_, held_end_,
            constant_counts_[node]};
  }
  /// Calls f(const KeyframeNode&) for the node's held keyframe nodes, by ascending t.
  template <class F>
  void for_each_keyframe(std::uint32_t node, F&& f) const {
    times(node).for_each([&](std::uint32_t t) { f(keyframe(keyframe_id(node, t))); });
  }
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
  /// Whether a held frame within max_keyframe_gap of the playhead that the view may need failed
  /// to read: the view there cannot be drawn as encoded. A failed frame is not needed when a frame
  /// between it and the playhead stores a brick of every node (a node's drawing takes its stored
  /// states nearest the playhead on either side).
  bool failed_around(double playhead) const;
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
  /// The held frames by time step t mod ring_ (ring_ ≥ window_, a multiple of 64); a slot's
  /// frame has the time step t only while t is in the held range.
  std::vector<HeldFrame> held_;
  std::uint32_t ring_ = 64;
  std::size_t words_ = 1;  ///< ring_ / 64: words of time bits per node
  std::vector<std::uint64_t> time_bits_, constant_bits_;
  std::vector<std::uint32_t> held_counts_, constant_counts_;  ///< bits set per node
  std::size_t keyframe_count_ = 0;
  std::uint32_t held_begin_ = 0, held_end_ = 0;
  std::size_t window_ = 0;
  std::uint32_t max_gap_ = 1;
  IndexOptions options_;
  std::size_t whole_frames_ = 0;  ///< held frames with every node, counted once in held_frames
  std::shared_ptr<const format::Container> container_;  ///< windowed: where frames are read
  std::unique_ptr<Reader> reader_;

  void reset_nodes();
  void hold(HeldFrame frame, bool at_front);
  /// Sets (held) or clears the bits of the frame's keyframe nodes, with their counts.
  void mark_times(const HeldFrame& frame, bool held);
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
