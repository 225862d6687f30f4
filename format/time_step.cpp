// time_step.cpp: time steps with interpolated nodes (time_step.hpp).
#include "volreel/format/time_step.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "volreel/format/error.hpp"

namespace volreel::format {

namespace {

std::string str(std::uint64_t v) {
  return std::to_string(v);
}

std::string describe(const NodePosition& p) {
  return "(level " + str(p.level) + ", brick " + str(p.x) + " " + str(p.y) + " " + str(p.z) + ")";
}

}  // namespace

TimeStepDecoder::TimeStepDecoder(std::size_t frame_count, std::uint32_t max_gap, AtomTable atoms,
                                 Opener opener)
    : frame_count_(frame_count),
      max_gap_(std::max<std::uint32_t>(max_gap, 1)),
      atoms_(atoms),
      opener_(std::move(opener)) {}

TimeStepDecoder::TimeStepDecoder(const Container& container)
    : TimeStepDecoder(container.frame_count(), container.manifest().max_keyframe_gap,
                      container.atoms(),
                      [&container](std::size_t t) { return container.open_frame(t); }) {}

const FrameView& TimeStepDecoder::frame(std::size_t t) {
  auto it = open_.find(t);
  if (it == open_.end()) it = open_.emplace(t, opener_(t)).first;
  return it->second.view();
}

void TimeStepDecoder::forget_frames_far_from(std::size_t t) {
  for (auto it = open_.begin(); it != open_.end();) {
    const std::size_t d = it->first > t ? it->first - t : t - it->first;
    it = d > max_gap_ ? open_.erase(it) : std::next(it);
  }
}

StoredState TimeStepDecoder::stored_state(std::size_t from, const NodePosition& p, int direction,
                                          const FrameView& origin, std::uint32_t node) {
  for (std::uint32_t step = 1; step < max_gap_; ++step) {
    if (direction < 0 ? from < step : from + step >= frame_count_) break;
    const std::size_t s = direction < 0 ? from - step : from + step;
    const FrameView& f = frame(s);
    const std::uint32_t j = f.find_node(p);
    if (j != no_node_index) {
      if (f.has_brick(j)) return {s, f.node(j).brick, 0};
      continue;  // not a keyframe there either
    }
    // Not in frame s's tree: an empty ancestor holds it.
    for (std::uint32_t up = 1; up <= p.level; ++up) {
      const NodePosition a{p.level - up, p.x >> up, p.y >> up, p.z >> up};
      const std::uint32_t k = f.find_node(a);
      if (k == no_node_index) continue;
      if (f.node(k).type() != NodeType::empty)
        throw FormatError(f.name(), f.header().node_table_offset + sizeof(Node) * std::uint64_t{k},
                          "node " + str(k) + " " + describe(a) + " empty or with the child " +
                              describe(p) + " (frame " + str(from) + " has it)",
                          "an inner node without it");
      const std::span<const std::byte> payload = f.checked_brick_bytes(f.node(k).brick);
      float value;
      std::memcpy(&value, payload.data(), 4);
      if (!std::isfinite(value))
        throw FormatError(f.name(), f.brick_offset(f.node(k).brick),
                          "brick payload: a finite constant", "NaN or infinity");
      return {s, no_brick, value};
    }
    throw FormatError(f.name(), FormatError::no_offset,
                      "the node " + describe(p) + " or an empty ancestor of it", "neither");
  }
  throw FormatError(origin.name(),
                    origin.header().node_table_offset + sizeof(Node) * std::uint64_t{node},
                    "node " + str(node) + " " + describe(p) + " without a brick stored within " +
                        str(max_gap_ - 1) + " time steps " + (direction < 0 ? "before" : "after") +
                        " it (the container's max_keyframe_gap is " + str(max_gap_) + ")",
                    "none");
}

NodeSource TimeStepDecoder::source(std::size_t t, std::uint32_t node) {
  const FrameView& f = frame(t);
  if (node >= f.node_count())
    throw FormatError(f.name(),
                      "no node " + str(node) + " (frame has " + str(f.node_count()) + ")");
  NodeSource src;
  if (f.has_brick(node)) {
    src.a = {t, f.node(node).brick, 0};
    src.b = src.a;
    return src;
  }
  const NodePosition p = f.position(node);
  src.a = stored_state(t, p, -1, f, node);
  src.b = stored_state(t, p, +1, f, node);
  if (src.b.t - src.a.t > max_gap_)
    throw FormatError(f.name(), f.header().node_table_offset + sizeof(Node) * std::uint64_t{node},
                      "node " + str(node) + " " + describe(p) + " between stored states at most " +
                          str(max_gap_) + " time steps apart (max_keyframe_gap)",
                      "steps " + str(src.a.t) + " and " + str(src.b.t));
  src.factor =
      static_cast<float>(static_cast<double>(t - src.a.t) / static_cast<double>(src.b.t - src.a.t));
  src.interpolated = true;
  return src;
}

void TimeStepDecoder::check_keyframes(std::size_t t) {
  forget_frames_far_from(t);
  const FrameView& f = frame(t);
  for (std::uint32_t i = 0; i < f.node_count(); ++i)
    if (!f.has_brick(i)) source(t, i);
}

void decode_state(const FrameView& frame, const StoredState& state, const AtomTable& atoms,
                  std::span<float> out) {
  if (state.brick == no_brick)
    std::fill(out.begin(), out.end(), state.constant);
  else
    decode_brick(frame, state.brick, atoms, out);
}

void TimeStepDecoder::decode(std::size_t t, std::uint32_t level, std::span<float> out) {
  if (t >= frame_count_)
    throw FormatError("<container>",
                      "no time step " + str(t) + " (the series has " + str(frame_count_) + ")");
  forget_frames_far_from(t);
  const FrameView& f = frame(t);
  // 1. The nodes that make the level, and where each takes its values (this opens the frames
  //    interpolated nodes need, before the parallel part).
  const std::vector<std::uint32_t> work = level_work(f, level);
  const LevelEntry& target = f.level(level);
  const std::array<std::uint32_t, 3> dims{target.dims[0], target.dims[1], target.dims[2]};
  if (out.size() != std::size_t{dims[0]} * dims[1] * dims[2])
    throw FormatError(f.name(), "decode: output of the wrong size");
  std::vector<NodeSource> sources(work.size());
  std::vector<const FrameView*> frame_a(work.size()), frame_b(work.size());
  for (std::size_t w = 0; w < work.size(); ++w) {
    sources[w] = source(t, work[w]);
    frame_a[w] = &frame(sources[w].a.t);
    frame_b[w] = &frame(sources[w].b.t);
  }
  // 2. Decode, interpolate, place: two nodes at a time, their stored bricks (up to four) decoded
  //    together (decode_bricks reads their codes two at a time in step).
  std::exception_ptr error;
  const std::size_t voxels = f.shape().voxels();
  const auto pairs = static_cast<std::ptrdiff_t>((work.size() + 1) / 2);
#pragma omp parallel
  {
    std::vector<float> states(4 * voxels);  // node j's states a and b at 2j and 2j + 1
#pragma omp for schedule(dynamic, 2)
    for (std::ptrdiff_t p = 0; p < pairs; ++p) {
      const std::size_t first = 2 * static_cast<std::size_t>(p);
      const std::size_t count = std::min<std::size_t>(2, work.size() - first);
      const auto state_values = [&](std::size_t i) {
        return std::span<float>(states.data() + i * voxels, voxels);
      };
      BrickToDecode bricks[4];
      std::size_t stored = 0;
      for (std::size_t j = 0; j < count; ++j) {
        const NodeSource& src = sources[first + j];
        const std::pair<const FrameView*, const StoredState*> used[2] = {
            {frame_a[first + j], &src.a}, {frame_b[first + j], &src.b}};
        for (std::size_t i = 0; i < (src.interpolated ? 2u : 1u); ++i) {
          const auto [frame, state] = used[i];
          if (state->brick == no_brick)
            std::ranges::fill(state_values(2 * j + i), state->constant);
          else
            bricks[stored++] = {frame, state->brick, state_values(2 * j + i)};
        }
      }
      try {
        decode_bricks({bricks, stored}, atoms_);
      } catch (const FormatError&) {
#pragma omp critical(volreel_time_step_error)
        if (!error) error = std::current_exception();
        continue;
      }
      for (std::size_t j = 0; j < count; ++j) {
        const NodeSource& src = sources[first + j];
        const std::span<float> a = state_values(2 * j);
        if (src.interpolated) {
          const std::span<const float> b = state_values(2 * j + 1);
          const float f1 = src.factor, f0 = 1.0f - f1;
          for (std::size_t v = 0; v < a.size(); ++v) a[v] = f0 * a[v] + f1 * b[v];
        }
        place_in_level(f.position(work[first + j]), level, dims, f.shape(), a, out);
      }
    }
  }
  if (error) std::rethrow_exception(error);
}

LevelVolume TimeStepDecoder::decode(std::size_t t, std::uint32_t level) {
  const FrameView& f = frame(t);
  if (level >= f.level_count())
    throw FormatError(
        f.name(), "no level " + str(level) + " (frame has " + str(f.level_count()) + " levels)");
  LevelVolume v;
  const LevelEntry& e = f.level(level);
  v.dims = {e.dims[0], e.dims[1], e.dims[2]};
  v.data.resize(std::size_t{e.dims[0]} * e.dims[1] * e.dims[2]);
  decode(t, level, v.data);
  return v;
}

}  // namespace volreel::format
