// frame_file.hpp: the frame file (`frames/NNNNNN.vrf`): one time step as an octree of bricks
// (MTV-Player §3.2, Fig. 3) — header, level table, node table (128-bit nodes, breadth-first and
// Morton order inside a level), brick offsets, brick payloads, CRC-32C. Byte diagrams in
// format/SPEC.md, "Frame file". Parsing validates every count, offset and length before use and
// throws FormatError naming the file, the offset, what was expected and what was found.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

namespace volreel::format {

static_assert(std::endian::native == std::endian::little, "volreel's files are little-endian");

inline constexpr std::array<char, 8> frame_magic = {'V', 'R', 'E', 'E', 'L', 'F', 'R', 'M'};
/// Version of the frame file layout, independent of the program version.
inline constexpr std::uint32_t frame_format_version = 10;

inline constexpr std::uint32_t brick_apron = 1;       ///< voxels copied from each neighbour
inline constexpr std::uint32_t brick_block_size = 6;  ///< voxels per block axis (VR_BLOCK_SIZE)
/// Stored voxels per brick axis that a container may have: multiples of 6 in 12..66.
inline constexpr std::uint32_t min_brick_size = 12, max_brick_size = 66;
inline constexpr std::uint32_t default_brick_size = 36;

/// A container's brick tiling: bricks of size³ stored voxels, the (size − 2)³ interior and a
/// 1-voxel apron copied from the neighbours, cut into (size / 6)³ blocks of 6³.
struct BrickShape {
  std::uint32_t size = default_brick_size;  ///< stored voxels per axis
  constexpr std::uint32_t interior() const { return size - 2 * brick_apron; }
  constexpr std::uint32_t blocks_per_axis() const { return size / brick_block_size; }
  constexpr std::uint32_t blocks() const {
    return blocks_per_axis() * blocks_per_axis() * blocks_per_axis();
  }
  constexpr std::size_t voxels() const { return std::size_t{size} * size * size; }
  constexpr bool operator==(const BrickShape&) const = default;
};
/// Whether `size` is a brick size a container may have (a multiple of 6 in 12..66).
constexpr bool valid_brick_size(std::uint64_t size) {
  return size >= min_brick_size && size <= max_brick_size && size % brick_block_size == 0;
}
inline constexpr std::uint32_t max_levels = 16;
/// Node::brick of a node that has no brick at this time step (not one of its keyframes).
inline constexpr std::uint32_t no_brick = 0xFFFFFFFFu;
/// "No such node" (FrameView::find_node).
inline constexpr std::uint32_t no_node_index = 0xFFFFFFFFu;
inline constexpr std::uint32_t histogram_bins = 64;

enum class Codec : std::uint32_t { ksvd = 0, zfp = 1 };
/// inner: has children; leaf: finest level; empty: the node and its whole subtree are one
/// constant value (its brick is a 4-byte constant payload; no children are stored).
enum class NodeType : std::uint32_t { inner = 0, leaf = 1, empty = 2 };

/// On-disk header, 144 bytes at offset 0.
struct FrameHeader {
  char magic[8];                       //   0  "VREELFRM"
  std::uint32_t format_version;        //   8  frame_format_version
  std::uint32_t header_bytes;          //  12  144
  std::uint32_t codec;                 //  16  Codec
  std::uint32_t frame_index;           //  20  time step t
  std::uint32_t dims[3];               //  24  volume size x, y, z at the finest level
  std::uint32_t brick_size;            //  36  BrickShape::size: 12..66, a multiple of 6
  std::uint32_t brick_apron;           //  40  1
  std::uint32_t block_size;            //  44  6 (ksvd) or 0 (zfp)
  std::uint32_t level_count;           //  48  levels L; level 0 is the root, L−1 the finest
  std::uint32_t node_count;            //  52
  std::uint32_t brick_count;           //  56  nodes with a brick at this time step (≤ nodes)
  std::uint32_t atom_count;            //  60  K of the dictionary the codes index (ksvd), else 0
  float value_min;                     //  64  histogram range (the sequence's value range)
  float value_max;                     //  68
  double codec_parameter;              //  72  ksvd: ε (0 for fixed sparsity); zfp: accuracy
  std::uint64_t level_table_offset;    //  80  = 144
  std::uint64_t node_table_offset;     //  88  = level_table_offset + 32·L
  std::uint64_t brick_offsets_offset;  //  96  = node_table_offset + 16·node_count
  std::uint64_t payload_offset;        // 104  = brick_crcs_offset + 4·brick_count, rounded up
                                       //       to a multiple of 8 (4 zero bytes if odd)
  std::uint64_t payload_bytes;         // 112  file size = payload_offset + payload_bytes + 4
  std::uint32_t index_crc;             // 120  CRC-32C of bytes [level_table_offset, payload_offset)
  std::uint32_t fixed_sparsity;        // 124  ksvd fixed-rate S, 0 for variable rate
  std::uint64_t container_id;          // 128  the container's identifier (manifest.json)
  std::uint64_t brick_crcs_offset;     // 136  = brick_offsets_offset + 8·(brick_count + 1)
};
static_assert(sizeof(FrameHeader) == 144);
static_assert(offsetof(FrameHeader, container_id) == 128);
static_assert(offsetof(FrameHeader, brick_crcs_offset) == 136);
static_assert(offsetof(FrameHeader, codec) == 16);
static_assert(offsetof(FrameHeader, dims) == 24);
static_assert(offsetof(FrameHeader, level_count) == 48);
static_assert(offsetof(FrameHeader, value_min) == 64);
static_assert(offsetof(FrameHeader, codec_parameter) == 72);
static_assert(offsetof(FrameHeader, level_table_offset) == 80);
static_assert(offsetof(FrameHeader, payload_bytes) == 112);
static_assert(offsetof(FrameHeader, index_crc) == 120);

/// One level of the octree, 32 bytes.
struct LevelEntry {
  std::uint32_t first_node;  //   0  index of the level's first node
  std::uint32_t node_count;  //   4
  std::uint32_t dims[3];     //   8  size of the level's volume in voxels (finest = frame)
  std::uint32_t grid[3];     //  20  bricks per axis = ceil(dims / interior)
};
static_assert(sizeof(LevelEntry) == 32);
static_assert(offsetof(LevelEntry, grid) == 20);

/// One spatial node, 128 bits (MTV-Player §3.2).
struct Node {
  std::uint32_t brick;           //   0  brick index (bricks numbered in node order), or no_brick:
                                 //      not a keyframe of the node (time_step.hpp interpolates)
  std::uint32_t child_and_type;  //   4  bits 0..29 first child (0 unless inner), 30..31 NodeType
  std::uint64_t histogram;       //   8  bit b: a voxel of the subtree lies in bin b of 64
                                 //      over [value_min, value_max]
  NodeType type() const { return static_cast<NodeType>(child_and_type >> 30); }
  std::uint32_t first_child() const { return child_and_type & 0x3FFFFFFFu; }
};
static_assert(sizeof(Node) == 16);
static_assert(offsetof(Node, histogram) == 8);

/// Level geometry of a frame of `dims` in bricks of `shape` (finest level last):
/// dims_{l} = ceil(dims_{l+1} / 2), grid = ceil(dims / interior), as many levels as it takes
/// until the grid is 1×1×1.
struct LevelGeometry {
  std::array<std::uint32_t, 3> dims{};
  std::array<std::uint32_t, 3> grid{};
};
std::vector<LevelGeometry> level_geometry(std::array<std::uint32_t, 3> dims, BrickShape shape);

/// Per voxel of a volume of `dims`, the values of the 6³ blocks the encoder codes (coded_box:
/// those holding a voxel of their level or the voxel just past its end), over all levels of
/// bricks of `shape`: what the tiling costs.
double coded_block_share(std::array<std::uint32_t, 3> dims, BrickShape shape);
/// The coded blocks of brick `position` of a level of size `dims` (a ksvd payload's box word,
/// brick_decode.h): on each axis the blocks that hold a voxel of the level or the voxel just past
/// its end, which a renderer's linear filter reads at the volume's far face (1..n each).
std::array<std::uint32_t, 3> coded_box(BrickShape shape, std::array<std::uint32_t, 3> position,
                                       std::array<std::uint32_t, 3> dims);
/// Per voxel of a volume of `dims`, the values of the whole bricks of `shape` over all levels:
/// what the encoder's frames, a decoded level and the player's atlas hold in memory.
double stored_brick_share(std::array<std::uint32_t, 3> dims, BrickShape shape);
/// The brick shape whose coded_block_share is the least for `dims` (the smaller size on a tie
/// within 1 %: finer units to stream). Where a frame's bricks of that shape would take more than
/// max_stored_brick_bytes as float32 and hold more than twice the values per voxel the leanest
/// shape's do (a volume thin along an axis: a plane of 4096² in bricks of 66³ holds 93 values per
/// voxel, 6 GB), the least coded share among the shapes within twice the leanest.
BrickShape choose_brick_shape(std::array<std::uint32_t, 3> dims);
/// A frame's whole bricks (float32, all levels) above which choose_brick_shape weighs memory:
/// what the encoder holds of a frame, and a player's atlas of all of it.
inline constexpr double max_stored_brick_bytes = 1024.0 * 1024 * 1024;

/// Morton code of brick coordinates (x in the lowest bit of each triple), up to 21 bits per axis.
std::uint64_t morton3(std::uint32_t x, std::uint32_t y, std::uint32_t z);

/// Bin of value v in the 64-bin histogram over [lo, hi] (clamped).
std::uint32_t histogram_bin(float v, float lo, float hi);

/// A frame to be written: what the encoder produces.
struct FrameContents {
  FrameHeader header{};            ///< codec, frame index, dims, brick size, atom count, value
                                   ///< range, codec parameter, fixed sparsity; the rest is
                                   ///< filled in
  std::vector<LevelEntry> levels;  ///< first_node and node_count per level (dims/grid filled in)
  std::vector<Node> nodes;
  std::vector<std::vector<std::byte>> payloads;  ///< one per brick; each a multiple of 4 bytes
};

/// The file's bytes; fills in magic, version, sizes, offsets, the brick CRCs, the index CRC and the
/// file CRC.
std::vector<std::byte> serialize_frame(const FrameContents& frame);

/// Position of a node in the octree, computed by the reader from the child links.
struct NodePosition {
  std::uint32_t level = 0;
  std::uint32_t x = 0, y = 0, z = 0;  ///< brick coordinates within the level's grid
};

/// A validated view of a frame file's bytes (owned elsewhere: memory map or vector). The
/// constructor checks the header, the level table, every node and every brick offset, and the index
/// CRC; check_payload_crc() checks the CRC of the whole file, checked_brick_bytes() one brick's
/// CRC. Payload contents are checked when a brick is decoded (decoder.hpp).
class FrameView {
 public:
  FrameView() = default;
  /// Throws FormatError naming `name`, the offset, what was expected and what was found.
  FrameView(std::span<const std::byte> bytes, std::filesystem::path name);
  /// The index alone: `bytes` are the file's first bytes, at least up to the payloads, of a file
  /// of `file_size` bytes (a remote frame, whose bricks are read by range and checked against their
  /// CRCs). Everything but the payloads is checked as for a whole file; brick_bytes() and
  /// check_payload_crc() then throw.
  FrameView(std::span<const std::byte> bytes, std::filesystem::path name, std::uint64_t file_size);

  const FrameHeader& header() const { return header_; }
  Codec codec() const { return static_cast<Codec>(header_.codec); }
  const std::filesystem::path& name() const { return name_; }
  /// The bytes held: the whole file, or the index alone (has_payloads()).
  std::span<const std::byte> bytes() const { return bytes_; }
  /// The size of the frame file.
  std::uint64_t file_size() const { return file_size_; }
  /// Whether the payloads are held (a whole file), not only the index.
  bool has_payloads() const { return bytes_.size() == file_size_; }

  /// The brick tiling (the header's brick size, checked).
  BrickShape shape() const { return {header_.brick_size}; }
  std::uint32_t level_count() const { return header_.level_count; }
  const LevelEntry& level(std::uint32_t l) const { return levels_[l]; }
  std::uint32_t node_count() const { return header_.node_count; }
  std::uint32_t brick_count() const { return header_.brick_count; }
  Node node(std::uint32_t i) const;
  const NodePosition& position(std::uint32_t i) const { return positions_[i]; }
  /// Whether node i has a brick at this time step (is one of its keyframes).
  bool has_brick(std::uint32_t i) const { return node(i).brick != no_brick; }
  /// The node at (level, x, y, z), or no_node_index when the frame's tree has none there (the
  /// position lies outside the level's grid or under an empty node).
  std::uint32_t find_node(const NodePosition& p) const;
  /// Payload bytes of brick b (validated bounds, contents not checked). Throws FormatError if the
  /// view holds the index alone.
  std::span<const std::byte> brick_bytes(std::uint32_t b) const;
  /// The size of brick b's payload in bytes.
  std::uint64_t brick_payload_bytes(std::uint32_t b) const;
  /// Payload bytes of brick b after checking them against the brick's CRC-32C; throws FormatError
  /// naming the file, the payload's offset and both CRCs.
  std::span<const std::byte> checked_brick_bytes(std::uint32_t b) const;
  /// The CRC-32C of brick b's payload, as the index records it.
  std::uint32_t brick_crc(std::uint32_t b) const;
  /// File offset of brick b's payload.
  std::uint64_t brick_offset(std::uint32_t b) const;
  /// File offset where the payloads of levels 0..depth−1 end: they are exactly the bytes
  /// [payload_offset, payload_end_for_depth(depth)), so a reader that needs only the coarse levels
  /// reads the index and that prefix (MTV-Player §3.2: bricks stored breadth-first).
  std::uint64_t payload_end_for_depth(std::uint32_t depth) const;

  /// Throws FormatError if the trailing CRC-32C does not match the file.
  void check_payload_crc() const;

 private:
  std::span<const std::byte> bytes_;
  std::filesystem::path name_;
  std::uint64_t file_size_ = 0;
  FrameHeader header_{};
  std::vector<LevelEntry> levels_;
  std::vector<NodePosition> positions_;
  std::vector<std::uint32_t> level_first_brick_;  ///< per level, then the brick count
};

/// A validated frame file: its bytes held in memory (the whole file, or its index alone).
class FrameFile {
 public:
  /// The file at `path`, read whole (detail::read_whole_file). Throws FormatError.
  explicit FrameFile(const std::filesystem::path& path);
  /// The whole file's bytes, or (file_size larger) its index alone; `name` names it in messages.
  FrameFile(std::vector<std::byte> bytes, std::filesystem::path name, std::uint64_t file_size)
      : held_(std::move(bytes)), view_(held_, std::move(name), file_size) {}
  FrameFile(FrameFile&&) noexcept = default;  // the view's span follows the moved buffer
  FrameFile& operator=(FrameFile&&) noexcept = default;
  FrameFile(const FrameFile&) = delete;
  FrameFile& operator=(const FrameFile&) = delete;
  const FrameView& view() const { return view_; }

 private:
  std::vector<std::byte> held_;
  FrameView view_;
};

}  // namespace volreel::format
