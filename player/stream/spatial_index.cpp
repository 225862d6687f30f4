// spatial_index.cpp: the union of the frames' brick octrees with per-node keyframe lists.
#include "volreel/stream/spatial_index.hpp"

#include <algorithm>
#include <optional>
#include <thread>

#include "volreel/format/error.hpp"

namespace volreel::stream {

namespace {

std::size_t mix(std::size_t h, std::uint32_t v) {
  return h ^ (std::hash<std::uint32_t>{}(v) + 0x9E3779B97F4A7C15ull + (h << 6) + (h >> 2));
}

std::string str(std::uint64_t v) {
  return std::to_string(v);
}

}  // namespace

std::size_t NodeKeyHash::operator()(const NodeKey& k) const noexcept {
  return mix(mix(mix(mix(0, k.level), k.x), k.y), k.z);
}

std::size_t KeyframeKeyHash::operator()(const KeyframeKey& k) const noexcept {
  return mix(mix(mix(mix(mix(0, k.level), k.x), k.y), k.z), k.t);
}

SpatialIndexBuilder::SpatialIndexBuilder(std::array<std::uint32_t, 3> dims, std::size_t frame_count)
    : dims_(dims),
      frame_count_(frame_count),
      geometry_(format::level_geometry(dims)),
      files_(frame_count) {}

void SpatialIndexBuilder::add_frame(std::uint32_t t, const format::FrameView& frame,
                                    std::filesystem::path file) {
  const format::FrameHeader& h = frame.header();
  if (t >= frame_count_)
    throw format::FormatError(file, format::FormatError::no_offset,
                              "time step below " + str(frame_count_), str(t));
  for (int a = 0; a < 3; ++a)
    if (h.dims[a] != dims_[static_cast<std::size_t>(a)])
      throw format::FormatError(file, offsetof(format::FrameHeader, dims), "dims of the series",
                                "another size");
  if (frame.level_count() != geometry_.size())
    throw format::FormatError(file, offsetof(format::FrameHeader, level_count),
                              str(geometry_.size()) + " levels", str(frame.level_count()));
  for (std::uint32_t i = 0; i < frame.node_count(); ++i) {
    const format::Node n = frame.node(i);
    if (n.brick == format::no_brick) continue;  // not a keyframe of the node at step t
    const format::NodePosition& p = frame.position(i);
    KeyframeNode k;
    k.t = t;
    k.brick = n.brick;
    k.offset = frame.brick_offset(n.brick);
    k.bytes = static_cast<std::uint32_t>(frame.brick_offset(n.brick + 1) - k.offset);
    k.crc32c = frame.brick_crc(n.brick);
    k.constant = k.bytes == 4;
    k.subtree_constant = n.type() == format::NodeType::empty;
    k.histogram = n.histogram;
    entries_.push_back({{p.level, p.x, p.y, p.z}, k});
  }
  files_[t] = std::move(file);
}

SpatialIndex SpatialIndexBuilder::build() && {
  SpatialIndex index;
  index.dims_ = dims_;
  index.geometry_ = std::move(geometry_);
  index.files_ = std::move(files_);
  const std::uint32_t levels = index.level_count();

  // 1. Sort entries by node (level, then Morton order inside a level), then time step.
  std::sort(entries_.begin(), entries_.end(), [](const Entry& a, const Entry& b) {
    if (a.key.level != b.key.level) return a.key.level < b.key.level;
    const std::uint64_t ma = format::morton3(a.key.x, a.key.y, a.key.z),
                        mb = format::morton3(b.key.x, b.key.y, b.key.z);
    if (ma != mb) return ma < mb;
    return a.keyframe.t < b.keyframe.t;
  });

  // 2. One spatial node per distinct key, its keyframes contiguous.
  index.keyframes_.reserve(entries_.size());
  index.keyframe_node_.reserve(entries_.size());
  for (std::size_t i = 0; i < entries_.size(); ++i) {
    const Entry& e = entries_[i];
    if (index.nodes_.empty() || !(index.nodes_.back().key == e.key)) {
      SpatialNode n;
      n.key = e.key;
      const std::uint64_t span = std::uint64_t{format::brick_interior}
                                 << (levels - 1 - e.key.level);
      const std::uint32_t c[3] = {e.key.x, e.key.y, e.key.z};
      for (std::size_t a = 0; a < 3; ++a) {
        n.lo[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(c[a] * span, dims_[a]));
        n.hi[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>((c[a] + 1) * span, dims_[a]));
      }
      n.first_keyframe = static_cast<std::uint32_t>(index.keyframes_.size());
      index.lookup_.emplace(e.key, static_cast<std::uint32_t>(index.nodes_.size()));
      index.nodes_.push_back(n);
    }
    index.keyframes_.push_back(e.keyframe);
    index.keyframe_node_.push_back(static_cast<std::uint32_t>(index.nodes_.size() - 1));
    ++index.nodes_.back().keyframe_count;
  }
  entries_.clear();

  // 3. Parent and child links.
  for (std::uint32_t id = 0; id < index.nodes_.size(); ++id) {
    SpatialNode& n = index.nodes_[id];
    if (n.key.level + 1 >= levels) continue;
    for (std::uint32_t i = 0; i < 8; ++i) {
      const NodeKey ck{n.key.level + 1, 2 * n.key.x + (i & 1u), 2 * n.key.y + ((i >> 1) & 1u),
                       2 * n.key.z + (i >> 2)};
      const std::uint32_t c = index.find(ck);
      if (c == no_node) continue;
      n.children[i] = c;
      n.has_children = true;
      index.nodes_[c].parent = id;
    }
  }
  return index;
}

std::uint32_t SpatialIndex::find(const NodeKey& key) const {
  const auto it = lookup_.find(key);
  return it == lookup_.end() ? no_node : it->second;
}

std::uint32_t SpatialIndex::ancestor(std::uint32_t id, std::uint32_t up) const {
  for (; up > 0 && id != no_node; --up) id = nodes_[id].parent;
  return id;
}

std::span<const KeyframeNode> SpatialIndex::keyframes(std::uint32_t node) const {
  const SpatialNode& n = nodes_[node];
  return {keyframes_.data() + n.first_keyframe, n.keyframe_count};
}

KeyframeId SpatialIndex::find_keyframe(std::uint32_t node, std::uint32_t t) const {
  const auto list = keyframes(node);
  const auto it = std::lower_bound(list.begin(), list.end(), t,
                                   [](const KeyframeNode& k, std::uint32_t v) { return k.t < v; });
  if (it == list.end() || it->t != t) return no_keyframe;
  return nodes_[node].first_keyframe + static_cast<KeyframeId>(it - list.begin());
}

KeyframeId SpatialIndex::find_keyframe(const KeyframeKey& key) const {
  const std::uint32_t node = find({key.level, key.x, key.y, key.z});
  return node == no_node ? no_keyframe : find_keyframe(node, key.t);
}

KeyframeKey SpatialIndex::key(KeyframeId id) const {
  const NodeKey& n = nodes_[keyframe_node_[id]].key;
  return {n.level, n.x, n.y, n.z, keyframes_[id].t};
}

SpatialIndex build_spatial_index(const format::Container& container,
                                 std::vector<std::string>* errors) {
  const auto& m = container.manifest();
  const std::size_t frames = container.frame_count();
  SpatialIndexBuilder builder(m.dims, frames);
  // A remote container's indexes are fetched a window at a time by several threads (each one a
  // round trip or two); local ones are mapped in order.
  const std::size_t window = container.source().local_directory() ? 1 : 16;
  std::vector<std::optional<format::FrameFile>> opened(frames);
  std::vector<std::string> failures(frames);
  for (std::size_t first = 0; first < frames; first += window) {
    const std::size_t end = std::min(frames, first + window);
    const auto open = [&](std::size_t t) {
      if (!m.frames[t]) {
        failures[t] = format::frame_file_name(t) + ": frame not written (incomplete encode)";
        return;
      }
      try {
        opened[t].emplace(container.open_frame_index(t));
      } catch (const std::exception& e) {
        failures[t] = e.what();
      }
    };
    if (window == 1) {
      open(first);
    } else {
      std::vector<std::thread> threads;
      for (std::size_t t = first; t < end; ++t) threads.emplace_back(open, t);
      for (std::thread& th : threads) th.join();
    }
    for (std::size_t t = first; t < end; ++t) {
      if (opened[t]) {
        try {
          builder.add_frame(static_cast<std::uint32_t>(t), opened[t]->view(),
                            container.source().name(m.frames[t]->file));
        } catch (const std::exception& e) {
          failures[t] = e.what();
        }
      }
      if (!failures[t].empty() && errors) errors->push_back(failures[t]);
      opened[t].reset();
    }
  }
  return std::move(builder).build();
}

}  // namespace volreel::stream
