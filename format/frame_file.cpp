// frame_file.cpp: writing and validating frame files, and reading one whole.
#include "volreel/format/frame_file.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <utility>

#include "volreel/format/bytes.hpp"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::format {

namespace fs = std::filesystem;

std::vector<LevelGeometry> level_geometry(std::array<std::uint32_t, 3> dims, BrickShape shape) {
  const std::uint32_t interior = shape.interior();
  std::vector<LevelGeometry> levels;
  LevelGeometry g;
  g.dims = dims;
  for (;;) {
    for (std::size_t a = 0; a < 3; ++a) g.grid[a] = (g.dims[a] + interior - 1) / interior;
    levels.push_back(g);
    if (g.grid[0] <= 1 && g.grid[1] <= 1 && g.grid[2] <= 1) break;
    for (std::size_t a = 0; a < 3; ++a) g.dims[a] = (g.dims[a] + 1) / 2;
  }
  std::reverse(levels.begin(), levels.end());
  return levels;
}

double coded_block_share(std::array<std::uint32_t, 3> dims, BrickShape shape) {
  double blocks = 0;
  for (const LevelGeometry& g : level_geometry(dims, shape)) {
    // The blocks the encoder codes (coded_box): on each axis, summed over the bricks of a row.
    double product = 1;
    for (std::size_t a = 0; a < 3; ++a) {
      std::uint64_t count = 0;
      for (std::uint32_t x = 0; x < g.grid[a]; ++x) {
        std::array<std::uint32_t, 3> position{0, 0, 0};
        position[a] = x;
        count += coded_box(shape, position, g.dims)[a];
      }
      product *= static_cast<double>(count);
    }
    blocks += product;
  }
  const double side = brick_block_size;
  return blocks * side * side * side / (static_cast<double>(dims[0]) * dims[1] * dims[2]);
}

std::array<std::uint32_t, 3> coded_box(BrickShape shape, std::array<std::uint32_t, 3> position,
                                       std::array<std::uint32_t, 3> dims) {
  const std::int64_t interior = shape.interior(), side = brick_block_size,
                     n = shape.blocks_per_axis();
  std::array<std::uint32_t, 3> box{};
  for (std::size_t a = 0; a < 3; ++a) {
    // Block j starts at level voxel I·p − 1 + 6j; it is coded while that is at most dims.
    const std::int64_t room = std::int64_t{dims[a]} + 1 - interior * std::int64_t{position[a]};
    box[a] = static_cast<std::uint32_t>(std::clamp<std::int64_t>(room / side + 1, 1, n));
  }
  return box;
}

double stored_brick_share(std::array<std::uint32_t, 3> dims, BrickShape shape) {
  double bricks = 0;
  for (const LevelGeometry& g : level_geometry(dims, shape))
    bricks += static_cast<double>(g.grid[0]) * g.grid[1] * g.grid[2];
  const double side = shape.size;
  return bricks * side * side * side / (static_cast<double>(dims[0]) * dims[1] * dims[2]);
}

BrickShape choose_brick_shape(std::array<std::uint32_t, 3> dims) {
  struct Candidate {
    std::uint32_t size;
    double coded, stored;
  };
  std::vector<Candidate> all;  // every size, smallest first
  for (std::uint32_t size = min_brick_size; size <= max_brick_size; size += brick_block_size)
    all.push_back({size, coded_block_share(dims, {size}), stored_brick_share(dims, {size})});
  // The least coded share among `candidates`, the smaller size on a tie within 1 %.
  const auto least_coded = [](const std::vector<Candidate>& candidates) {
    double least = std::numeric_limits<double>::infinity();
    for (const Candidate& c : candidates) least = std::min(least, c.coded);
    for (const Candidate& c : candidates)
      if (c.coded <= least * 1.01) return c;
    return Candidate{max_brick_size, least, 0};  // not reached: the least is one of them
  };
  const Candidate best = least_coded(all);
  double fewest = std::numeric_limits<double>::infinity();
  for (const Candidate& c : all) fewest = std::min(fewest, c.stored);
  const double voxels = static_cast<double>(dims[0]) * dims[1] * dims[2];
  if (4 * best.stored * voxels <= max_stored_brick_bytes || best.stored <= 2 * fewest)
    return {best.size};
  std::vector<Candidate> lean;
  for (const Candidate& c : all)
    if (c.stored <= 2 * fewest) lean.push_back(c);
  return {least_coded(lean).size};
}

std::uint64_t morton3(std::uint32_t x, std::uint32_t y, std::uint32_t z) {
  std::uint64_t code = 0;
  for (int bit = 0; bit < 21; ++bit) {
    code |= static_cast<std::uint64_t>((x >> bit) & 1u) << (3 * bit);
    code |= static_cast<std::uint64_t>((y >> bit) & 1u) << (3 * bit + 1);
    code |= static_cast<std::uint64_t>((z >> bit) & 1u) << (3 * bit + 2);
  }
  return code;
}

std::uint32_t histogram_bin(float v, float lo, float hi) {
  if (!(hi > lo)) return 0;
  const float t = (v - lo) / (hi - lo) * static_cast<float>(histogram_bins);
  if (!(t > 0)) return 0;  // also NaN
  if (t >= static_cast<float>(histogram_bins - 1)) return histogram_bins - 1;
  return static_cast<std::uint32_t>(t);
}

namespace {

template <class T>
T load(std::span<const std::byte> bytes, std::uint64_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

std::string str(std::uint64_t v) {
  return std::to_string(v);
}

}  // namespace

std::vector<std::byte> serialize_frame(const FrameContents& frame) {
  FrameHeader h = frame.header;
  std::memcpy(h.magic, frame_magic.data(), 8);
  h.format_version = frame_format_version;
  h.header_bytes = sizeof(FrameHeader);
  if (!valid_brick_size(h.brick_size))
    throw FormatError("<memory>", "frame header's brick size " + str(h.brick_size) +
                                      " is not a multiple of 6 in 12..66");
  h.brick_apron = brick_apron;
  h.level_count = static_cast<std::uint32_t>(frame.levels.size());
  h.node_count = static_cast<std::uint32_t>(frame.nodes.size());
  h.brick_count = static_cast<std::uint32_t>(frame.payloads.size());
  h.level_table_offset = sizeof(FrameHeader);
  h.node_table_offset = h.level_table_offset + sizeof(LevelEntry) * frame.levels.size();
  h.brick_offsets_offset = h.node_table_offset + sizeof(Node) * frame.nodes.size();
  h.brick_crcs_offset =
      h.brick_offsets_offset + sizeof(std::uint64_t) * (frame.payloads.size() + 1);
  h.payload_offset = (h.brick_crcs_offset + 4 * frame.payloads.size() + 7) / 8 * 8;
  std::uint64_t payload_bytes = 0;
  for (const auto& p : frame.payloads) {
    if (p.size() % 4 != 0)
      throw FormatError("<memory>",
                        "brick payload of " + str(p.size()) + " bytes is not a multiple of 4");
    payload_bytes += p.size();
  }
  h.payload_bytes = payload_bytes;
  const auto geometry = level_geometry({h.dims[0], h.dims[1], h.dims[2]}, {h.brick_size});
  if (geometry.size() != frame.levels.size())
    throw FormatError("<memory>", "frame has " + str(frame.levels.size()) +
                                      " levels, its dims need " + str(geometry.size()));

  std::vector<std::byte> out;
  out.reserve(h.payload_offset + payload_bytes + 4);
  detail::append_value(out, h);
  for (std::size_t l = 0; l < frame.levels.size(); ++l) {
    LevelEntry e = frame.levels[l];
    for (int a = 0; a < 3; ++a) {
      e.dims[a] = geometry[l].dims[static_cast<std::size_t>(a)];
      e.grid[a] = geometry[l].grid[static_cast<std::size_t>(a)];
    }
    detail::append_value(out, e);
  }
  for (const Node& n : frame.nodes) detail::append_value(out, n);
  std::uint64_t offset = 0;
  detail::append_value(out, offset);
  for (const auto& p : frame.payloads) {
    offset += p.size();
    detail::append_value(out, offset);
  }
  for (const auto& p : frame.payloads) detail::append_value(out, crc32c(p));
  out.resize(h.payload_offset, std::byte{0});
  const std::uint32_t index_crc = crc32c(std::span<const std::byte>(out).subspan(
      h.level_table_offset, h.payload_offset - h.level_table_offset));
  std::memcpy(out.data() + offsetof(FrameHeader, index_crc), &index_crc, 4);
  for (const auto& p : frame.payloads) {
    const std::size_t at = out.size();
    out.resize(at + p.size());
    if (!p.empty()) std::memcpy(out.data() + at, p.data(), p.size());
  }
  const std::uint32_t crc = crc32c(out);
  detail::append_value(out, crc);
  return out;
}

FrameView::FrameView(std::span<const std::byte> bytes, fs::path name)
    : FrameView(bytes, std::move(name), bytes.size()) {}

FrameView::FrameView(std::span<const std::byte> bytes, fs::path name, std::uint64_t file_size)
    : bytes_(bytes), name_(std::move(name)), file_size_(file_size) {
  const auto fail = [&](std::uint64_t offset, const std::string& expected,
                        const std::string& found) {
    throw FormatError(name_, offset, expected, found);
  };
  // 1. Header.
  if (bytes.size() > file_size)
    fail(file_size, "a frame file of " + str(file_size) + " bytes", str(bytes.size()) + " bytes");
  if (bytes.size() < sizeof(FrameHeader))
    fail(0, "a frame file of at least " + str(sizeof(FrameHeader)) + " bytes",
         str(bytes.size()) + " bytes (truncated)");
  header_ = load<FrameHeader>(bytes, 0);
  const FrameHeader& h = header_;
  if (std::memcmp(h.magic, frame_magic.data(), 8) != 0)
    fail(0, "magic \"VREELFRM\"", "other bytes (not a volreel frame file)");
  if (h.format_version != frame_format_version)
    fail(offsetof(FrameHeader, format_version),
         "format version " + str(frame_format_version) +
             (h.format_version < frame_format_version
                  ? " (a file of an older volreel: encode the series again)"
                  : ""),
         str(h.format_version));
  if (h.header_bytes != sizeof(FrameHeader))
    fail(offsetof(FrameHeader, header_bytes), "header size " + str(sizeof(FrameHeader)),
         str(h.header_bytes));
  if (h.codec > 1) fail(offsetof(FrameHeader, codec), "codec 0 (ksvd) or 1 (zfp)", str(h.codec));
  for (int a = 0; a < 3; ++a)
    if (h.dims[a] == 0 || h.dims[a] > (1u << 24))
      fail(offsetof(FrameHeader, dims) + 4u * static_cast<unsigned>(a), "dimension in 1..16777216",
           str(h.dims[a]));
  if (!valid_brick_size(h.brick_size))
    fail(offsetof(FrameHeader, brick_size), "brick size a multiple of 6 in 12..66",
         str(h.brick_size));
  if (h.brick_apron != brick_apron)
    fail(offsetof(FrameHeader, brick_apron), "apron 1", str(h.brick_apron));
  const bool ksvd = h.codec == static_cast<std::uint32_t>(Codec::ksvd);
  if (ksvd && h.block_size != 6)
    fail(offsetof(FrameHeader, block_size), "block size 6", str(h.block_size));
  if (ksvd && (h.atom_count == 0 || h.atom_count > dictionary_max_atoms))
    fail(offsetof(FrameHeader, atom_count), "atom count in 1.." + str(dictionary_max_atoms),
         str(h.atom_count));
  if (!ksvd && h.block_size != 0)
    fail(offsetof(FrameHeader, block_size), "block size 0 (zfp)", str(h.block_size));
  if (!ksvd && h.atom_count != 0)
    fail(offsetof(FrameHeader, atom_count), "atom count 0 (zfp)", str(h.atom_count));
  if (h.fixed_sparsity > 216)  // at most one atom per value of a 6³ block
    fail(offsetof(FrameHeader, fixed_sparsity), "fixed sparsity 0..216", str(h.fixed_sparsity));
  if (!std::isfinite(h.value_min) || !std::isfinite(h.value_max) || h.value_min > h.value_max)
    fail(offsetof(FrameHeader, value_min), "a finite value range min <= max",
         "[" + number_text(h.value_min) + ", " + number_text(h.value_max) + "]");
  const auto geometry = level_geometry({h.dims[0], h.dims[1], h.dims[2]}, {h.brick_size});
  if (h.level_count != geometry.size())
    fail(offsetof(FrameHeader, level_count),
         str(geometry.size()) + " levels for dims " + str(h.dims[0]) + "x" + str(h.dims[1]) + "x" +
             str(h.dims[2]) + " in bricks of " + str(h.brick_size),
         str(h.level_count));
  std::uint64_t max_nodes = 0;
  for (const auto& g : geometry) max_nodes += std::uint64_t{g.grid[0]} * g.grid[1] * g.grid[2];
  if (h.node_count == 0 || h.node_count > max_nodes)
    fail(offsetof(FrameHeader, node_count), "node count in 1.." + str(max_nodes),
         str(h.node_count));
  if (h.brick_count > h.node_count)
    fail(offsetof(FrameHeader, brick_count), "brick count in 0.." + str(h.node_count) + " (nodes)",
         str(h.brick_count));
  // 2. Section offsets: exactly back to back.
  const std::uint64_t levels_at = sizeof(FrameHeader);
  const std::uint64_t nodes_at = levels_at + sizeof(LevelEntry) * std::uint64_t{h.level_count};
  const std::uint64_t offsets_at = nodes_at + sizeof(Node) * std::uint64_t{h.node_count};
  const std::uint64_t crcs_at = offsets_at + 8 * (std::uint64_t{h.brick_count} + 1);
  const std::uint64_t payload_at = (crcs_at + 4 * std::uint64_t{h.brick_count} + 7) / 8 * 8;
  if (h.level_table_offset != levels_at)
    fail(offsetof(FrameHeader, level_table_offset), "level table at " + str(levels_at),
         str(h.level_table_offset));
  if (h.node_table_offset != nodes_at)
    fail(offsetof(FrameHeader, node_table_offset), "node table at " + str(nodes_at),
         str(h.node_table_offset));
  if (h.brick_offsets_offset != offsets_at)
    fail(offsetof(FrameHeader, brick_offsets_offset), "brick offsets at " + str(offsets_at),
         str(h.brick_offsets_offset));
  if (h.brick_crcs_offset != crcs_at)
    fail(offsetof(FrameHeader, brick_crcs_offset), "brick CRCs at " + str(crcs_at),
         str(h.brick_crcs_offset));
  if (h.payload_offset != payload_at)
    fail(offsetof(FrameHeader, payload_offset), "payloads at " + str(payload_at),
         str(h.payload_offset));
  if (bytes.size() < payload_at)
    fail(bytes.size(), "index sections up to offset " + str(payload_at), "end of file (truncated)");
  if (h.payload_bytes > file_size || file_size != payload_at + h.payload_bytes + 4)
    fail(offsetof(FrameHeader, payload_bytes),
         "file size " + str(payload_at) +
             " + payload bytes + 4 = " + str(payload_at + h.payload_bytes + 4),
         str(file_size) + " bytes (payload bytes " + str(h.payload_bytes) + ")");
  const std::uint32_t index_crc = crc32c(bytes.subspan(levels_at, payload_at - levels_at));
  if (index_crc != h.index_crc)
    fail(offsetof(FrameHeader, index_crc),
         "index CRC-32C " + str(index_crc) + " of bytes [" + str(levels_at) + ", " +
             str(payload_at) + ")",
         str(h.index_crc) + " (index corrupt)");
  for (std::uint64_t at = crcs_at + 4 * std::uint64_t{h.brick_count}; at < payload_at; ++at)
    if (bytes[at] != std::byte{0}) fail(at, "zero padding before the payloads", "a nonzero byte");
  // 3. Level table: geometry and contiguous node ranges.
  levels_.resize(h.level_count);
  std::uint32_t next_node = 0;
  for (std::uint32_t l = 0; l < h.level_count; ++l) {
    const std::uint64_t at = levels_at + sizeof(LevelEntry) * l;
    const LevelEntry e = load<LevelEntry>(bytes, at);
    const auto& g = geometry[l];
    // The index CRC above holds the level table as written: where it disagrees with the
    // geometry of the header's dims and brick size, the header is what changed.
    for (std::size_t a = 0; a < 3; ++a)
      if (e.dims[a] != g.dims[a] || e.grid[a] != g.grid[a])
        fail(offsetof(FrameHeader, dims),
             "header dims and brick size that give level " + str(l) + " the size " +
                 str(e.dims[a]) + " and grid " + str(e.grid[a]) + " along " + "xyz"[a] +
                 " that the level table records (offset " + str(at) + ", under a good index CRC)",
             "dims " + str(h.dims[0]) + "x" + str(h.dims[1]) + "x" + str(h.dims[2]) +
                 ", brick size " + str(h.brick_size) + " (size " + str(g.dims[a]) + ", grid " +
                 str(g.grid[a]) + ")");
    if (e.first_node != next_node)
      fail(at, "level " + str(l) + " first node " + str(next_node), str(e.first_node));
    const std::uint64_t cells = std::uint64_t{g.grid[0]} * g.grid[1] * g.grid[2];
    if (e.node_count > cells || (l == 0 && e.node_count != 1))
      fail(at + 4,
           "level " + str(l) + " node count in " +
               (l == 0 ? std::string("1..1") : "0.." + str(cells)),
           str(e.node_count));
    next_node += e.node_count;
    if (next_node > h.node_count)
      fail(at + 4, "level node counts summing to " + str(h.node_count), "more");
    levels_[l] = e;
  }
  if (next_node != h.node_count)
    fail(levels_at, "level node counts summing to " + str(h.node_count), str(next_node));
  // 4. Nodes: types, bricks, and child links that tile each level in order; positions follow.
  //    Bricks are numbered in node order; a node without one (no_brick) is not a keyframe at
  //    this time step, and an empty node always has one.
  positions_.assign(h.node_count, {});
  level_first_brick_.assign(h.level_count + 1, 0);
  std::uint32_t next_brick = 0;
  for (std::uint32_t l = 0; l < h.level_count; ++l) {
    const LevelEntry& e = levels_[l];
    level_first_brick_[l] = next_brick;
    std::uint32_t expected_child = l + 1 < h.level_count ? levels_[l + 1].first_node : 0;
    for (std::uint32_t i = e.first_node; i < e.first_node + e.node_count; ++i) {
      const std::uint64_t at = nodes_at + sizeof(Node) * i;
      const Node n = load<Node>(bytes, at);
      const auto type = static_cast<std::uint32_t>(n.type());
      if (type > 2) fail(at + 4, "node " + str(i) + " type 0..2", str(type));
      if (n.brick == no_brick) {
        if (n.type() == NodeType::empty)
          fail(at, "node " + str(i) + " (empty) brick " + str(next_brick), "none (no_brick)");
      } else if (n.brick != next_brick || next_brick >= h.brick_count) {
        fail(at,
             "node " + str(i) + " brick index " +
                 (next_brick < h.brick_count
                      ? str(next_brick) + " or none (no_brick)"
                      : std::string("none (all ") + str(h.brick_count) + " bricks numbered)"),
             str(n.brick));
      } else {
        ++next_brick;
      }
      const bool finest = l + 1 == h.level_count;
      if (n.type() == NodeType::leaf && !finest)
        fail(at + 4, "node " + str(i) + " of level " + str(l) + ": inner or empty", "leaf");
      if (n.type() == NodeType::inner && finest)
        fail(at + 4, "node " + str(i) + " of the finest level: leaf or empty", "inner");
      if (n.type() != NodeType::inner) {
        if (n.first_child() != 0)
          fail(at + 4, "node " + str(i) + " first child 0", str(n.first_child()));
        continue;
      }
      if (n.first_child() != expected_child)
        fail(at + 4, "node " + str(i) + " first child " + str(expected_child),
             str(n.first_child()));
      const NodePosition& p = positions_[i];
      const auto& child_grid = geometry[l + 1].grid;
      std::uint32_t c = expected_child;
      for (std::uint32_t d = 0; d < 8; ++d) {
        const std::uint32_t cx = 2 * p.x + (d & 1u), cy = 2 * p.y + ((d >> 1) & 1u),
                            cz = 2 * p.z + (d >> 2);
        if (cx >= child_grid[0] || cy >= child_grid[1] || cz >= child_grid[2]) continue;
        if (c >= levels_[l + 1].first_node + levels_[l + 1].node_count)
          fail(at + 4, "children of node " + str(i) + " within level " + str(l + 1),
               "past its end");
        positions_[c] = {l + 1, cx, cy, cz};
        ++c;
      }
      expected_child = c;
    }
    level_first_brick_[l + 1] = next_brick;
    if (l + 1 == h.level_count && next_brick != h.brick_count)
      fail(offsetof(FrameHeader, brick_count),
           "brick count " + str(next_brick) + " (the nodes with a brick)", str(h.brick_count));
    if (l + 1 < h.level_count &&
        expected_child != levels_[l + 1].first_node + levels_[l + 1].node_count)
      fail(nodes_at + sizeof(Node) * e.first_node,
           "children of level " + str(l) + " covering level " + str(l + 1) + " (" +
               str(levels_[l + 1].node_count) + " nodes)",
           str(expected_child - levels_[l + 1].first_node) + " children");
  }
  // 5. Brick offsets: start at 0, nondecreasing, multiples of 4, end at payload_bytes.
  std::uint64_t previous = 0;
  for (std::uint32_t b = 0; b <= h.brick_count; ++b) {
    const std::uint64_t at = offsets_at + 8 * std::uint64_t{b};
    const auto v = load<std::uint64_t>(bytes, at);
    if (b == 0 && v != 0) fail(at, "brick offset 0", str(v));
    if (v < previous || v > h.payload_bytes || v % 4 != 0)
      fail(at,
           "brick " + str(b) + " offset, a multiple of 4 in [" + str(previous) + ", " +
               str(h.payload_bytes) + "]",
           str(v));
    if (b == h.brick_count && v != h.payload_bytes)
      fail(at, "end offset " + str(h.payload_bytes), str(v));
    previous = v;
  }
  // 6. Histograms and constant subtrees: every node's histogram has a bin (a brick has voxels) and
  //    holds its children's; an empty node's brick is a constant, and its histogram (and that of a
  //    constant finest-level brick) is that constant's bin alone.
  for (std::uint32_t i = 0; i < h.node_count; ++i) {
    const std::uint64_t at = nodes_at + sizeof(Node) * i;
    const Node n = node(i);
    if (n.histogram == 0) fail(at + 8, "node " + str(i) + " histogram with a bin set", "none");
    const std::uint64_t payload_size = n.brick == no_brick ? 0 : brick_payload_bytes(n.brick);
    if (n.type() == NodeType::empty && payload_size != 4)
      fail(brick_offset(n.brick),
           "a 4-byte constant payload for brick " + str(n.brick) + " (its node is empty)",
           str(payload_size) + " bytes");
    // (The constant itself is checked where the payloads are held; a reader of single bricks
    // checks each against its CRC.)
    if (payload_size == 4 && n.type() != NodeType::inner && has_payloads()) {
      const std::span<const std::byte> payload = brick_bytes(n.brick);
      const float value = load<float>(payload, 0);
      const std::uint64_t bin = std::uint64_t{1} << histogram_bin(value, h.value_min, h.value_max);
      if (n.histogram != bin)
        fail(at + 8, "node " + str(i) + " histogram of its constant's bin alone (" + str(bin) + ")",
             str(n.histogram));
    }
    if (n.type() == NodeType::inner) {
      const std::uint32_t first = n.first_child();
      const std::uint32_t level = positions_[i].level;
      const std::uint32_t end = levels_[level + 1].first_node + levels_[level + 1].node_count;
      for (std::uint32_t c = first;
           c < end && positions_[c].level == level + 1 && positions_[c].x / 2 == positions_[i].x &&
           positions_[c].y / 2 == positions_[i].y && positions_[c].z / 2 == positions_[i].z;
           ++c)
        if ((node(c).histogram & ~n.histogram) != 0)
          fail(at + 8, "node " + str(i) + " histogram holding its child " + str(c) + "'s",
               "bins the child has and it lacks");
    }
  }
}

Node FrameView::node(std::uint32_t i) const {
  return load<Node>(bytes_, header_.node_table_offset + sizeof(Node) * std::uint64_t{i});
}

std::uint64_t FrameView::brick_offset(std::uint32_t b) const {
  return header_.payload_offset +
         load<std::uint64_t>(bytes_, header_.brick_offsets_offset + 8 * std::uint64_t{b});
}

std::uint64_t FrameView::brick_payload_bytes(std::uint32_t b) const {
  return brick_offset(b + 1) - brick_offset(b);
}

std::span<const std::byte> FrameView::brick_bytes(std::uint32_t b) const {
  const std::uint64_t begin = brick_offset(b), end = brick_offset(b + 1);
  if (!has_payloads())
    throw FormatError(name_, begin, "the payload of brick " + str(b) + " in memory",
                      "the frame's index alone (its bricks are read one by one)");
  return bytes_.subspan(begin, end - begin);
}

std::uint32_t FrameView::brick_crc(std::uint32_t b) const {
  return load<std::uint32_t>(bytes_, header_.brick_crcs_offset + 4 * std::uint64_t{b});
}

std::span<const std::byte> FrameView::checked_brick_bytes(std::uint32_t b) const {
  const std::span<const std::byte> payload = brick_bytes(b);
  const std::uint32_t found = crc32c(payload), expected = brick_crc(b);
  if (found != expected)
    throw FormatError(name_, brick_offset(b),
                      "brick " + str(b) + " payload of CRC-32C " + str(expected) + " (the index's)",
                      str(found) + " (payload corrupt)");
  return payload;
}

std::uint64_t FrameView::payload_end_for_depth(std::uint32_t depth) const {
  if (depth >= header_.level_count) return header_.payload_offset + header_.payload_bytes;
  return brick_offset(level_first_brick_[depth]);
}

std::uint32_t FrameView::find_node(const NodePosition& p) const {
  if (p.level >= header_.level_count) return no_node_index;
  const LevelEntry& e = levels_[p.level];
  const std::uint64_t key = morton3(p.x, p.y, p.z);
  // Nodes of a level are in Morton order.
  std::uint32_t lo = e.first_node, hi = e.first_node + e.node_count;
  while (lo < hi) {
    const std::uint32_t mid = lo + (hi - lo) / 2;
    const NodePosition& q = positions_[mid];
    if (morton3(q.x, q.y, q.z) < key)
      lo = mid + 1;
    else
      hi = mid;
  }
  if (lo == e.first_node + e.node_count) return no_node_index;
  const NodePosition& q = positions_[lo];
  return q.x == p.x && q.y == p.y && q.z == p.z ? lo : no_node_index;
}

void FrameView::check_payload_crc() const {
  if (!has_payloads())
    throw FormatError(name_, header_.payload_offset, "the whole frame file in memory",
                      "its index alone");
  const std::uint64_t end = bytes_.size() - 4;
  const std::uint32_t want = crc32c(bytes_.subspan(0, end));
  const auto found = load<std::uint32_t>(bytes_, end);
  if (want != found)
    throw FormatError(name_, end, "file CRC-32C " + str(want), str(found) + " (file corrupt)");
}

FrameFile::FrameFile(const fs::path& path)
    : held_(detail::read_whole_file(path, std::numeric_limits<std::uint64_t>::max())),
      view_(held_, path) {}

}  // namespace volreel::format
