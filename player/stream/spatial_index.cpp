// spatial_index.cpp: the union of the frames' brick octrees with per-node keyframe lists.
#include "volreel/stream/spatial_index.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <mutex>
#include <numeric>
#include <optional>
#include <stdexcept>
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

namespace {

/// The highest set bit of slots [a, b] (a ≤ b), or -1.
std::int64_t last_bit(const std::uint64_t* words, std::uint32_t a, std::uint32_t b) {
  for (std::uint32_t w = b >> 6;; --w) {
    std::uint64_t bits = words[w];
    if (w == b >> 6) bits &= ~std::uint64_t{0} >> (63 - (b & 63));
    if (w == a >> 6) bits &= ~std::uint64_t{0} << (a & 63);
    if (bits != 0) return std::int64_t{w} * 64 + 63 - std::countl_zero(bits);
    if (w == a >> 6) return -1;
  }
}

/// The lowest set bit of slots [a, b] (a ≤ b), or -1.
std::int64_t first_bit(const std::uint64_t* words, std::uint32_t a, std::uint32_t b) {
  for (std::uint32_t w = a >> 6;; ++w) {
    std::uint64_t bits = words[w];
    if (w == a >> 6) bits &= ~std::uint64_t{0} << (a & 63);
    if (w == b >> 6) bits &= ~std::uint64_t{0} >> (63 - (b & 63));
    if (bits != 0) return std::int64_t{w} * 64 + std::countr_zero(bits);
    if (w == b >> 6) return -1;
  }
}

}  // namespace

std::uint32_t HeldTimes::at_or_before(std::uint32_t t) const {
  if (count_ == 0 || t < begin_) return no_time;
  t = std::min(t, end_ - 1);
  // Slots (last − n, last] of the ring, descending, in at most two runs.
  const std::uint32_t n = t - begin_ + 1, last = t % ring_;
  const std::uint32_t run = std::min(n, last + 1);
  std::int64_t slot = last_bit(words_, last + 1 - run, last);
  if (slot >= 0) return t - (last - static_cast<std::uint32_t>(slot));
  if (run == n) return no_time;
  slot = last_bit(words_, ring_ - (n - run), ring_ - 1);
  return slot < 0 ? no_time : t - run - (ring_ - 1 - static_cast<std::uint32_t>(slot));
}

std::uint32_t HeldTimes::at_or_after(std::uint32_t t) const {
  if (count_ == 0 || t >= end_) return no_time;
  t = std::max(t, begin_);
  // Slots [first, first + n) of the ring, ascending, in at most two runs.
  const std::uint32_t n = end_ - t, first = t % ring_;
  const std::uint32_t run = std::min(n, ring_ - first);
  std::int64_t slot = first_bit(words_, first, first + run - 1);
  if (slot >= 0) return t + (static_cast<std::uint32_t>(slot) - first);
  if (run == n) return no_time;
  slot = first_bit(words_, 0, n - run - 1);
  return slot < 0 ? no_time : t + run + static_cast<std::uint32_t>(slot);
}

namespace {

std::shared_ptr<const IndexGeometry> make_geometry(std::array<std::uint32_t, 3> dims,
                                                   format::BrickShape shape) {
  auto g = std::make_shared<IndexGeometry>();
  g->shape = shape;
  g->dims = dims;
  g->levels = format::level_geometry(dims, shape);
  const auto levels = static_cast<std::uint32_t>(g->levels.size());
  for (std::uint32_t l = 0; l < levels; ++l) {
    g->first.push_back(static_cast<std::uint32_t>(g->ids.size()));
    const auto& gl = g->levels[l].grid;
    g->ids.resize(g->ids.size() + std::size_t{gl[0]} * gl[1] * gl[2], no_node);
  }
  for (std::uint32_t l = 0; l < levels; ++l) {
    const auto& grid = g->levels[l].grid;
    std::vector<std::pair<std::uint64_t, NodeKey>> keys;
    keys.reserve(std::size_t{grid[0]} * grid[1] * grid[2]);
    for (std::uint32_t z = 0; z < grid[2]; ++z)
      for (std::uint32_t y = 0; y < grid[1]; ++y)
        for (std::uint32_t x = 0; x < grid[0]; ++x)
          keys.push_back({format::morton3(x, y, z), NodeKey{l, x, y, z}});
    std::sort(keys.begin(), keys.end(),
              [](const auto& a, const auto& b) { return a.first < b.first; });
    const std::uint64_t span = std::uint64_t{shape.interior()} << (levels - 1 - l);
    for (const auto& [morton, key] : keys) {
      SpatialNode n;
      n.key = key;
      const std::uint32_t c[3] = {key.x, key.y, key.z};
      for (std::size_t a = 0; a < 3; ++a) {
        n.lo[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>(c[a] * span, dims[a]));
        n.hi[a] = static_cast<std::uint32_t>(std::min<std::uint64_t>((c[a] + 1) * span, dims[a]));
      }
      if (l > 0) n.parent = g->find(NodeKey{l - 1, key.x / 2, key.y / 2, key.z / 2});
      g->ids[g->first[l] + key.x + grid[0] * (key.y + std::size_t{grid[1]} * key.z)] =
          static_cast<std::uint32_t>(g->nodes.size());
      g->nodes.push_back(n);
    }
  }
  return g;
}

/// Frame t's nodes and bricks. Throws format::FormatError if the frame's dims or levels disagree
/// with the geometry.
HeldFrame read_frame(const IndexGeometry& g, std::uint32_t t, const format::FrameView& frame,
                     const std::filesystem::path& file) {
  const format::FrameHeader& h = frame.header();
  for (int a = 0; a < 3; ++a)
    if (h.dims[a] != g.dims[static_cast<std::size_t>(a)])
      throw format::FormatError(file, offsetof(format::FrameHeader, dims), "dims of the series",
                                "another size");
  if (h.brick_size != g.shape.size)
    throw format::FormatError(file, offsetof(format::FrameHeader, brick_size),
                              "brick size " + str(g.shape.size) + " of the series",
                              str(h.brick_size));
  if (frame.level_count() != g.levels.size())
    throw format::FormatError(file, offsetof(format::FrameHeader, level_count),
                              str(g.levels.size()) + " levels", str(frame.level_count()));
  HeldFrame out;
  out.t = t;
  out.nodes.reserve(frame.node_count());
  out.keyframes.reserve(frame.brick_count());
  out.positions.assign(g.nodes.size(), no_node);
  for (std::uint32_t i = 0; i < frame.node_count(); ++i) {
    const format::NodePosition& p = frame.position(i);
    const std::uint32_t id = g.find(NodeKey{p.level, p.x, p.y, p.z});
    if (id == no_node)
      throw format::FormatError(file, format::FormatError::no_offset,
                                "nodes inside the level grids", "a node outside");
    out.nodes.push_back(id);
    const format::Node n = frame.node(i);
    if (n.brick == format::no_brick) continue;  // not a keyframe of the node at step t
    KeyframeNode k;
    k.t = t;
    k.brick = n.brick;
    k.offset = frame.brick_offset(n.brick);
    k.bytes = static_cast<std::uint32_t>(frame.brick_offset(n.brick + 1) - k.offset);
    k.crc32c = frame.brick_crc(n.brick);
    k.constant = k.bytes == 4;
    k.subtree_constant = n.type() == format::NodeType::empty;
    k.histogram = n.histogram;
    if (out.positions[id] != no_node)
      throw format::FormatError(file, format::FormatError::no_offset, "one brick per node",
                                "two at level " + str(p.level) + " (" + str(p.x) + ", " + str(p.y) +
                                    ", " + str(p.z) + ")");
    out.positions[id] = static_cast<std::uint32_t>(out.keyframes.size());
    out.keyframes.emplace_back(id, k);
  }
  // Reserved for every brick of the file; the index counts what it holds.
  out.keyframes.shrink_to_fit();
  return out;
}

HeldFrame failed_frame(std::uint32_t t, std::string error) {
  HeldFrame f;
  f.t = t;
  f.error = std::move(error);
  return f;
}

/// Frame t of a container as a HeldFrame from its index as opened (`file`), or from the error
/// that opening it gave; a frame not written or failing validation holds its error.
HeldFrame held_frame(const format::Container& container, const IndexGeometry& g, std::uint32_t t,
                     const format::FrameFile* file, const std::string& error) {
  const auto& m = container.manifest();
  if (!m.frames[t])
    return failed_frame(t, format::frame_file_name(t) + ": frame not written (incomplete encode)");
  if (!file) return failed_frame(t, error);
  try {
    return read_frame(g, t, file->view(), container.source().name(m.frames[t]->file));
  } catch (const std::exception& e) {
    return failed_frame(t, e.what());
  }
}

/// Frame t of a container, opened here, as a HeldFrame.
HeldFrame read_container_frame(const format::Container& container, const IndexGeometry& g,
                               std::uint32_t t) {
  if (!container.manifest().frames[t]) return held_frame(container, g, t, nullptr, "");
  try {
    const format::FrameFile f = container.open_frame_index(t);
    return held_frame(container, g, t, &f, "");
  } catch (const std::exception& e) {
    return held_frame(container, g, t, nullptr, e.what());
  }
}

}  // namespace

// ---- The background reader of a windowed index ------------------------------------------------

struct SpatialIndex::Reader {
  enum State : std::uint8_t { idle, reading, ready, held };

  Reader(std::shared_ptr<const format::Container> c, std::shared_ptr<const IndexGeometry> g,
         std::size_t frames, std::size_t window)
      : container(std::move(c)), geometry(std::move(g)), state(frames, idle), capacity(window) {
    thread = std::thread([this] { run(); });
  }
  ~Reader() {
    {
      const std::lock_guard lock(mutex);
      stop = true;
    }
    wake.notify_all();
    thread.join();
  }
  Reader(const Reader&) = delete;
  Reader& operator=(const Reader&) = delete;

  /// The next frame to read: the idle one in the wanted range nearest the centre, those ahead in
  /// the direction of travel counting half; none while `capacity` frames wait to be held.
  std::optional<std::uint32_t> next() const {
    if (ready_frames.size() >= capacity) return std::nullopt;
    std::optional<std::uint32_t> best;
    std::uint64_t best_cost = ~std::uint64_t{0};
    for (std::uint32_t t = want_begin; t < want_end; ++t) {
      if (state[t] != idle) continue;
      const bool ahead = backwards ? t <= center : t >= center;
      const std::uint64_t d = t >= center ? t - center : center - t;
      const std::uint64_t cost = ahead ? d : 2 * d + 1;
      if (cost < best_cost) {
        best_cost = cost;
        best = t;
      }
    }
    return best;
  }

  void run() {
    std::unique_lock lock(mutex);
    while (!stop) {
      const std::optional<std::uint32_t> t = next();
      if (!t) {
        wake.wait(lock);
        continue;
      }
      state[*t] = reading;
      lock.unlock();
      HeldFrame f = read_container_frame(*container, *geometry, *t);
      lock.lock();
      if (state[*t] == reading && *t >= want_begin && *t < want_end) {
        state[*t] = ready;
        ready_frames.emplace(*t, std::move(f));
      } else if (state[*t] == reading) {
        state[*t] = idle;
      }
    }
  }

  /// Takes frame t if it was read (under the lock).
  std::optional<HeldFrame> take(std::uint32_t t) {
    const auto it = ready_frames.find(t);
    if (it == ready_frames.end()) return std::nullopt;
    HeldFrame f = std::move(it->second);
    ready_frames.erase(it);
    state[t] = held;
    return f;
  }

  std::shared_ptr<const format::Container> container;
  std::shared_ptr<const IndexGeometry> geometry;
  std::mutex mutex;
  std::condition_variable wake;
  std::vector<std::uint8_t> state;  ///< per frame
  std::unordered_map<std::uint32_t, HeldFrame> ready_frames;
  std::size_t capacity;
  std::uint32_t want_begin = 0, want_end = 0, center = 0;
  bool backwards = false, stop = false;
  std::thread thread;
};

// ---- SpatialIndexBuilder ------------------------------------------------------------------------

SpatialIndexBuilder::SpatialIndexBuilder(std::array<std::uint32_t, 3> dims, std::size_t frame_count,
                                         format::BrickShape shape)
    : geometry_(make_geometry(dims, shape)), files_(frame_count), frames_(frame_count) {}

void SpatialIndexBuilder::add_frame(std::uint32_t t, const format::FrameView& frame,
                                    std::filesystem::path file) {
  if (t >= frames_.size())
    throw format::FormatError(file, format::FormatError::no_offset,
                              "time step below " + str(frames_.size()), str(t));
  frames_[t] = read_frame(*geometry_, t, frame, file);
  files_[t] = std::move(file);
}

SpatialIndex SpatialIndexBuilder::build() && {
  SpatialIndex index;
  index.geometry_ = std::move(geometry_);
  index.files_ = std::move(files_);
  index.window_ = index.files_.size();
  index.reset_nodes();
  for (std::size_t t = 0; t < frames_.size(); ++t) {
    HeldFrame f;
    f.t = static_cast<std::uint32_t>(t);
    index.hold(frames_[t] ? std::move(*frames_[t]) : std::move(f), false);
  }
  frames_.clear();
  return index;
}

// ---- SpatialIndex -------------------------------------------------------------------------------

SpatialIndex::SpatialIndex() = default;
SpatialIndex::~SpatialIndex() = default;
SpatialIndex::SpatialIndex(SpatialIndex&&) noexcept = default;
SpatialIndex& SpatialIndex::operator=(SpatialIndex&&) noexcept = default;

SpatialIndex::SpatialIndex(const SpatialIndex& other) {
  *this = other;
}

SpatialIndex& SpatialIndex::operator=(const SpatialIndex& other) {
  if (this == &other) return *this;
  reader_.reset();
  geometry_ = other.geometry_;
  files_ = other.files_;
  nodes_ = other.nodes_;
  held_ = other.held_;
  ring_ = other.ring_;
  words_ = other.words_;
  time_bits_ = other.time_bits_;
  constant_bits_ = other.constant_bits_;
  held_counts_ = other.held_counts_;
  constant_counts_ = other.constant_counts_;
  keyframe_count_ = other.keyframe_count_;
  held_begin_ = other.held_begin_;
  held_end_ = other.held_end_;
  window_ = other.window_;
  max_gap_ = other.max_gap_;
  options_ = other.options_;
  whole_frames_ = other.whole_frames_;
  container_ = other.container_;
  if (container_) {
    start_reader();
    const std::lock_guard lock(reader_->mutex);
    for (std::uint32_t t = held_begin_; t < held_end_; ++t) reader_->state[t] = Reader::held;
  }
  return *this;
}

std::array<std::uint32_t, 3> SpatialIndex::dims() const {
  return geometry_ ? geometry_->dims : std::array<std::uint32_t, 3>{};
}

format::BrickShape SpatialIndex::shape() const {
  return geometry_ ? geometry_->shape : format::BrickShape{};
}

std::uint32_t SpatialIndex::level_count() const {
  return geometry_ ? static_cast<std::uint32_t>(geometry_->levels.size()) : 0;
}

void SpatialIndex::reset_nodes() {
  nodes_ = geometry_->nodes;
  ring_ = static_cast<std::uint32_t>((std::max<std::size_t>(window_, 1) + 63) / 64 * 64);
  words_ = ring_ / 64;
  held_.assign(ring_, HeldFrame{});
  time_bits_.assign(nodes_.size() * words_, 0);
  constant_bits_.assign(nodes_.size() * words_, 0);
  held_counts_.assign(nodes_.size(), 0);
  constant_counts_.assign(nodes_.size(), 0);
  keyframe_count_ = 0;
  whole_frames_ = 0;
  held_begin_ = held_end_ = 0;
}

void SpatialIndex::start_reader() {
  reader_ = std::make_unique<Reader>(container_, geometry_, files_.size(), window_);
}

namespace {

std::uint32_t octant_of(const NodeKey& k) {
  return (k.x & 1u) | ((k.y & 1u) << 1) | ((k.z & 1u) << 2);
}

}  // namespace

void SpatialIndex::count_nodes(std::span<const std::uint32_t> ids, int delta) {
  for (const std::uint32_t id : ids) {
    SpatialNode& n = nodes_[id];
    const bool was = n.held_frames > 0;
    n.held_frames = static_cast<std::uint32_t>(static_cast<int>(n.held_frames) + delta);
    if (was == (n.held_frames > 0) || n.parent == no_node) continue;
    SpatialNode& p = nodes_[n.parent];
    p.children[octant_of(n.key)] = was ? no_node : id;
    p.has_children = std::any_of(p.children.begin(), p.children.end(),
                                 [](std::uint32_t c) { return c != no_node; });
  }
}

void SpatialIndex::hold(HeldFrame frame, bool at_front) {
  // A frame with every node of the geometry (the usual case) counts once for all of them while
  // any such frame is held: adding and dropping it touches its bricks only.
  frame.whole = frame.nodes.size() == nodes_.size();
  if (!frame.whole) {
    count_nodes(frame.nodes, +1);
  } else if (whole_frames_++ == 0) {
    std::vector<std::uint32_t> all(nodes_.size());
    std::iota(all.begin(), all.end(), 0u);
    count_nodes(all, +1);
  }
  // A whole frame's nodes are all of them; a frame of a whole index is never dropped.
  if (frame.whole || !windowed()) frame.nodes = std::vector<std::uint32_t>();
  mark_times(frame, true);
  if (held_begin_ == held_end_) {
    held_begin_ = frame.t;
    held_end_ = frame.t + 1;
  } else if (at_front) {
    held_begin_ = frame.t;
  } else {
    held_end_ = frame.t + 1;
  }
  held_[frame.t % ring_] = std::move(frame);
}

void SpatialIndex::mark_times(const HeldFrame& frame, bool held) {
  const std::uint32_t slot = frame.t % ring_;
  const std::uint64_t bit = std::uint64_t{1} << (slot & 63);
  const std::size_t word = slot >> 6;
  const int delta = held ? 1 : -1;
  for (const auto& [id, k] : frame.keyframes) {
    std::uint64_t& times = time_bits_[id * words_ + word];
    times = held ? times | bit : times & ~bit;
    held_counts_[id] = static_cast<std::uint32_t>(static_cast<int>(held_counts_[id]) + delta);
    if (k.subtree_constant) {
      std::uint64_t& constants = constant_bits_[id * words_ + word];
      constants = held ? constants | bit : constants & ~bit;
      constant_counts_[id] =
          static_cast<std::uint32_t>(static_cast<int>(constant_counts_[id]) + delta);
    }
  }
  if (held)
    keyframe_count_ += frame.keyframes.size();
  else
    keyframe_count_ -= frame.keyframes.size();
}

void SpatialIndex::drop(bool front) {
  const std::uint32_t t = front ? held_begin_ : held_end_ - 1;
  const std::uint32_t slot = t % ring_;
  const HeldFrame frame = std::move(held_[slot]);
  held_[slot] = HeldFrame{};
  mark_times(frame, false);
  if (!frame.whole) {
    count_nodes(frame.nodes, -1);
  } else if (--whole_frames_ == 0) {
    std::vector<std::uint32_t> all(nodes_.size());
    std::iota(all.begin(), all.end(), 0u);
    count_nodes(all, -1);
  }
  if (front)
    ++held_begin_;
  else
    --held_end_;
  {
    const std::lock_guard lock(reader_->mutex);
    reader_->state[t] = Reader::idle;
  }
}

bool SpatialIndex::holds_around(double playhead) const {
  if (!windowed()) return true;
  const auto last = static_cast<double>(frame_count() - 1);
  const double p = std::clamp(playhead, 0.0, last);
  const auto lo = static_cast<std::uint32_t>(std::max(0.0, std::floor(p) - max_gap_));
  const auto hi = static_cast<std::uint32_t>(std::min(last, std::ceil(p) + max_gap_));
  return held_begin_ <= lo && hi < held_end_;
}

bool SpatialIndex::failed_around(double playhead) const {
  if (frame_count() == 0) return false;
  const auto last = static_cast<double>(frame_count() - 1);
  const double p = std::clamp(playhead, 0.0, last);
  const auto lo = static_cast<std::uint32_t>(std::max(0.0, std::floor(p) - max_gap_));
  const auto hi = static_cast<std::uint32_t>(std::min(last, std::ceil(p) + max_gap_));
  const auto before = static_cast<std::uint32_t>(std::floor(p));
  const auto after = static_cast<std::uint32_t>(std::ceil(p));
  // Frame u read, with a brick of every node.
  const auto stores_all = [&](std::uint32_t u) {
    if (u < held_begin_ || u >= held_end_) return false;
    const HeldFrame& f = held_[u % ring_];
    return f.error.empty() && f.whole && f.keyframes.size() == nodes_.size();
  };
  for (std::uint32_t t = std::max(lo, held_begin_); t <= hi && t < held_end_; ++t) {
    if (held_[t % ring_].error.empty()) continue;
    bool shielded = false;
    for (std::uint32_t u = after; t > after && u < t && !shielded; ++u) shielded = stores_all(u);
    for (std::uint32_t u = t + 1; t < before && u <= before && !shielded; ++u)
      shielded = stores_all(u);
    if (!shielded) return true;
  }
  return false;
}

void SpatialIndex::follow(double playhead, double velocity, std::vector<std::string>* errors) {
  if (!reader_ || frame_count() == 0) return;
  const auto frames = static_cast<std::uint32_t>(frame_count());
  const auto window = static_cast<std::uint32_t>(window_);
  const double p = std::clamp(playhead, 0.0, static_cast<double>(frames - 1));
  const auto center = static_cast<std::uint32_t>(std::floor(p));
  // The window: a quarter behind the playhead while playing (at least the frames the selection
  // reaches, max_keyframe_gap from floor and ceil of the playhead), half while still.
  const std::uint32_t trail = std::max(max_gap_ + 2, window / 4);
  const std::uint32_t behind = velocity > 0   ? trail
                               : velocity < 0 ? window - std::min(window, trail)
                                              : window / 2;
  std::uint32_t begin = center - std::min(center, behind);
  const std::uint32_t end = std::min(frames, begin + window);
  begin = end - std::min(end, window);

  // A seek outside the held range starts again at the playhead.
  if (held_begin_ < held_end_ && (center < held_begin_ || center >= held_end_))
    while (held_begin_ < held_end_) drop(false);
  while (held_begin_ < held_end_ && held_begin_ < begin) drop(true);
  while (held_begin_ < held_end_ && held_end_ > end) drop(false);
  if (held_begin_ == held_end_) held_begin_ = held_end_ = center;

  // Add what the reader has at either end of the held range: ahead first, except that the frames
  // the selection needs (max_keyframe_gap around the playhead) come before any others.
  const auto started = std::chrono::steady_clock::now();
  const bool backwards = velocity < 0;
  const auto need_lo = static_cast<std::uint32_t>(std::max(0.0, std::floor(p) - max_gap_));
  const auto need_hi =
      static_cast<std::uint32_t>(std::min<double>(frames - 1, std::ceil(p) + max_gap_));
  for (bool first = true;; first = false) {
    if (!first &&
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() >=
            options_.follow_budget_s)
      break;
    std::optional<HeldFrame> f;
    bool at_front = false;
    {
      const std::lock_guard lock(reader_->mutex);
      // An empty range starts with the playhead's own frame.
      const bool empty = held_begin_ == held_end_;
      const bool front_short = held_begin_ > need_lo, back_short = held_end_ <= need_hi;
      const bool ahead_short = backwards ? front_short : back_short;
      const bool behind_short = backwards ? back_short : front_short;
      const bool front_first = !empty && (backwards != (behind_short && !ahead_short));
      for (const bool front : {front_first, !front_first}) {
        if (front && held_begin_ > begin && held_begin_ <= end)
          f = reader_->take(held_begin_ - 1);
        else if (!front && held_end_ < end && held_end_ >= begin)
          f = reader_->take(held_end_);
        if (f) {
          at_front = front;
          break;
        }
      }
    }
    if (!f) break;
    if (!f->error.empty() && errors) errors->push_back(f->error);
    hold(std::move(*f), at_front);
  }

  // Tell the reader what to read next; frames read for another window are dropped.
  {
    const std::lock_guard lock(reader_->mutex);
    reader_->want_begin = begin;
    reader_->want_end = end;
    reader_->center = center;
    reader_->backwards = backwards;
    for (auto it = reader_->ready_frames.begin(); it != reader_->ready_frames.end();) {
      if (it->first < begin || it->first >= end) {
        reader_->state[it->first] = Reader::idle;
        it = reader_->ready_frames.erase(it);
      } else {
        ++it;
      }
    }
  }
  reader_->wake.notify_all();
}

std::uint64_t SpatialIndex::memory_bytes() const {
  const auto frame_bytes = [](const HeldFrame& f) {
    return (f.nodes.capacity() + f.positions.capacity()) * sizeof(std::uint32_t) +
           f.keyframes.capacity() * sizeof(f.keyframes[0]);
  };
  std::uint64_t bytes = nodes_.size() * (sizeof(SpatialNode) + 2 * sizeof(std::uint32_t)) +
                        (time_bits_.size() + constant_bits_.size()) * sizeof(std::uint64_t) +
                        held_.size() * sizeof(HeldFrame);
  for (const HeldFrame& f : held_) bytes += frame_bytes(f);
  if (reader_) {
    const std::lock_guard lock(reader_->mutex);
    for (const auto& [t, f] : reader_->ready_frames) bytes += frame_bytes(f);
  }
  return bytes;
}

std::uint32_t IndexGeometry::find(const NodeKey& key) const {
  if (key.level >= levels.size()) return no_node;
  const auto& grid = levels[key.level].grid;
  if (key.x >= grid[0] || key.y >= grid[1] || key.z >= grid[2]) return no_node;
  return ids[first[key.level] + key.x + grid[0] * (key.y + std::size_t{grid[1]} * key.z)];
}

std::uint32_t SpatialIndex::find(const NodeKey& key) const {
  return geometry_ ? geometry_->find(key) : no_node;
}

std::uint32_t SpatialIndex::ancestor(std::uint32_t id, std::uint32_t up) const {
  for (; up > 0 && id != no_node; --up) id = nodes_[id].parent;
  return id;
}

const KeyframeNode& SpatialIndex::keyframe(KeyframeId id) const {
  const std::uint32_t node = node_of(id);
  const auto t = static_cast<std::uint32_t>(id & 0xFFFFFFFFu);
  if (t >= held_begin_ && t < held_end_) {
    const HeldFrame& f = held_[t % ring_];
    if (node < f.positions.size() && f.positions[node] != no_node)
      return f.keyframes[f.positions[node]].second;
  }
  throw std::logic_error("keyframe node " + str(node) + " at t " + str(t) +
                         " is not held by the index");
}

std::vector<KeyframeId> SpatialIndex::held_keyframes() const {
  std::vector<KeyframeId> ids;
  ids.reserve(keyframe_count_);
  for (std::uint32_t n = 0; n < nodes_.size(); ++n)
    times(n).for_each([&](std::uint32_t t) { ids.push_back(keyframe_id(n, t)); });
  return ids;
}

KeyframeId SpatialIndex::find_keyframe(std::uint32_t node, std::uint32_t t) const {
  if (node >= nodes_.size() || !times(node).contains(t)) return no_keyframe;
  return keyframe_id(node, t);
}

KeyframeId SpatialIndex::find_keyframe(const KeyframeKey& key) const {
  const std::uint32_t node = find({key.level, key.x, key.y, key.z});
  return node == no_node ? no_keyframe : find_keyframe(node, key.t);
}

KeyframeKey SpatialIndex::key(KeyframeId id) const {
  const NodeKey& n = nodes_[node_of(id)].key;
  return {n.level, n.x, n.y, n.z, static_cast<std::uint32_t>(id & 0xFFFFFFFFu)};
}

SpatialIndex build_spatial_index(const format::Container& container,
                                 std::vector<std::string>* errors, const IndexOptions& options) {
  const auto& m = container.manifest();
  const std::size_t frames = container.frame_count();
  SpatialIndex index;
  index.geometry_ = make_geometry(m.dims, m.shape());
  index.files_.resize(frames);
  for (std::size_t t = 0; t < frames; ++t)
    if (m.frames[t]) index.files_[t] = container.source().name(m.frames[t]->file);
  index.options_ = options;
  index.max_gap_ = std::max<std::uint32_t>(1, m.max_keyframe_gap);
  // Keyframe nodes per frame at most (every node stored): the node with its node id, its entry
  // in the frame's positions, and a node id to drop the frame's nodes again.
  const std::uint64_t frame_bytes =
      index.geometry_->nodes.size() *
      (sizeof(std::pair<std::uint32_t, KeyframeNode>) + 2 * sizeof(std::uint32_t));
  const std::uint64_t fit = options.memory_bytes / std::max<std::uint64_t>(1, frame_bytes);
  if (fit < frames) {
    const std::uint64_t least = std::min<std::uint64_t>(frames, 2ull * index.max_gap_ + 4);
    index.window_ = static_cast<std::size_t>(std::max(fit, least));
  } else {
    index.window_ = frames;
  }
  index.reset_nodes();
  if (index.windowed()) {
    index.container_ = std::make_shared<const format::Container>(container);
    index.start_reader();
    return index;
  }
  // A remote container's indexes are fetched a batch at a time by several threads.
  std::vector<std::size_t> all(frames);
  for (std::size_t t = 0; t < frames; ++t) all[t] = t;
  format::for_each_frame_index(
      container, all, [&](std::size_t t, const format::FrameFile* file, const std::string& error) {
        HeldFrame f =
            held_frame(container, *index.geometry_, static_cast<std::uint32_t>(t), file, error);
        if (!f.error.empty() && errors) errors->push_back(f.error);
        index.hold(std::move(f), false);
      });
  return index;
}

}  // namespace volreel::stream
