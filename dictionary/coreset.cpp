// coreset.cpp: Halton frame selection and the one-pass importance sampler that yields every level
// of the coreset hierarchy (see coreset.hpp for the method).
#include "volreel/dictionary/coreset.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "volreel/datasets/prng.hpp"
#include "volreel/dictionary/blocks.hpp"

namespace volreel::dictionary {

namespace {

/// Base-2 radical inverse: the bits of i mirrored about the binary point (van der Corput).
double radical_inverse_base2(std::uint64_t i) {
  std::uint64_t r = 0;
  for (int bit = 0; bit < 64; ++bit, i >>= 1) r = (r << 1) | (i & 1u);
  return static_cast<double>(r >> 11) * 0x1.0p-53;
}

std::size_t slot_count(const CoresetOptions& options) {
  if (options.block_size < 1 || options.block_size > 64)
    throw InputError("block size " + std::to_string(options.block_size) + " is outside 1..64");
  if (options.levels < 0 || options.levels > 30)
    throw InputError("coreset levels " + std::to_string(options.levels) + " is outside 0..30");
  const auto m = static_cast<std::uint64_t>(options.block_size) *
                 static_cast<std::uint64_t>(options.block_size) *
                 static_cast<std::uint64_t>(options.block_size);
  const std::uint64_t slots = options.coreset_voxels / m;
  if (slots < (std::uint64_t{1} << options.levels))
    throw InputError("coreset size " + std::to_string(options.coreset_voxels) + " voxels holds " +
                     std::to_string(slots) + " blocks of " + std::to_string(m) +
                     " voxels, fewer than the 2^" + std::to_string(options.levels) +
                     " needed for " + std::to_string(options.levels) + " levels of halving");
  return static_cast<std::size_t>(slots);
}

/// One uniform variate in [0, 1) per (seed, frame, slot, which): a draw does not depend on the
/// order frames are visited in, the threads, or the process that visits them.
double keyed_uniform(std::uint64_t seed, std::uint64_t t, std::uint64_t slot, std::uint64_t which) {
  SplitMix64 a(seed ^ SplitMix64(t * 4 + which).next());
  SplitMix64 b(a.next() ^ (slot * 0xD1B54A32D192ED03ull));
  return b.uniform();
}

}  // namespace

/// The sampler: n slots, each holding the draw with the smallest key so far (coreset.hpp).
struct CoresetDraw::State {
  int block_size = 6;
  std::size_t m = 0, slots = 0;
  std::uint64_t seed = 1;
  std::vector<double> slot_key;           // +inf: no draw yet
  std::vector<float> slot_values;         // slots × m
  std::vector<float> slot_energy;         // e_b of the block in the slot
  std::vector<std::uint64_t> slot_block;  // frame << 40 | block: identifies the block in a slot
  struct Frame {
    std::uint64_t t = 0;
    double energy = 0, blocks = 0, lo = 0, hi = 0;
  };
  std::vector<Frame> frames;  // the frames drawn from, with their totals
};

CoresetDraw::CoresetDraw(const CoresetOptions& options) : state_(std::make_unique<State>()) {
  State& s = *state_;
  s.block_size = options.block_size;
  s.m = static_cast<std::size_t>(options.block_size) *
        static_cast<std::size_t>(options.block_size) * static_cast<std::size_t>(options.block_size);
  s.slots = slot_count(options);
  s.seed = options.seed;
  s.slot_key.assign(s.slots, std::numeric_limits<double>::infinity());
  s.slot_values.assign(s.slots * s.m, 0.0f);
  s.slot_energy.assign(s.slots, 0.0f);
  s.slot_block.assign(s.slots, std::numeric_limits<std::uint64_t>::max());
}

CoresetDraw::~CoresetDraw() = default;
CoresetDraw::CoresetDraw(CoresetDraw&&) noexcept = default;
CoresetDraw& CoresetDraw::operator=(CoresetDraw&&) noexcept = default;

void CoresetDraw::add_frame(std::size_t t, std::span<const float> volume, Dims dims) {
  State& s = *state_;
  const BlockGrid grid(dims, s.block_size);
  const auto blocks = static_cast<std::int64_t>(grid.block_count());

  // 1. Energy of every block (parallel; per block, so independent of the thread count), and the
  //    value range.
  std::vector<double> cumulative(static_cast<std::size_t>(blocks));
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
#pragma omp parallel reduction(min : lo) reduction(max : hi)
  {
    std::vector<float> block(s.m);
#pragma omp for schedule(static)
    for (std::int64_t b = 0; b < blocks; ++b) {
      const float mean = grid.extract(volume, static_cast<std::size_t>(b), block.data());
      double e = 0;
      float bmin = block[0], bmax = block[0];
      for (float v : block) {
        e += static_cast<double>(v) * static_cast<double>(v);
        bmin = std::min(bmin, v);
        bmax = std::max(bmax, v);
      }
      // Stored as float (the slot's energy), summed as double.
      cumulative[static_cast<std::size_t>(b)] = static_cast<double>(static_cast<float>(e));
      lo = std::min(lo, bmin + mean);
      hi = std::max(hi, bmax + mean);
    }
  }
  // 2. The frame's energy E_f, and the running sums that the inverse CDF searches (in order).
  for (std::size_t b = 1; b < cumulative.size(); ++b) cumulative[b] += cumulative[b - 1];
  const double energy = cumulative.empty() ? 0.0 : cumulative.back();
  s.frames.push_back(
      {t, energy, static_cast<double>(blocks), static_cast<double>(lo), static_cast<double>(hi)});
  if (!(energy > 0)) return;

  // 3. Each slot's draw from this frame: key −ln(1 − u)/E_f, block by the inverse CDF at u'·E_f;
  //    a slot takes it when the key is below the one it holds (and copies the block then).
  const auto slots = static_cast<std::int64_t>(s.slots);
#pragma omp parallel for schedule(static)
  for (std::int64_t k = 0; k < slots; ++k) {
    const auto slot = static_cast<std::size_t>(k);
    const double key = -std::log1p(-keyed_uniform(s.seed, t, slot, 0)) / energy;
    if (!(key < s.slot_key[slot])) continue;
    const double target = keyed_uniform(s.seed, t, slot, 1) * energy;
    auto it = std::upper_bound(cumulative.begin(), cumulative.end(), target);
    if (it == cumulative.end()) --it;  // rounding at the top end
    // A block of zero energy has an empty interval: step back to the last block with energy.
    while (it != cumulative.begin() && *it == *(it - 1)) --it;
    const auto b = static_cast<std::size_t>(it - cumulative.begin());
    const double e = b == 0 ? cumulative[0] : cumulative[b] - cumulative[b - 1];
    s.slot_key[slot] = key;
    grid.extract(volume, b, s.slot_values.data() + slot * s.m);
    s.slot_energy[slot] = static_cast<float>(e);
    s.slot_block[slot] = static_cast<std::uint64_t>(t) << 40 | static_cast<std::uint64_t>(b);
  }
}

void CoresetDraw::merge(const CoresetDraw& other) {
  State& s = *state_;
  const State& o = *other.state_;
  if (o.slots != s.slots || o.m != s.m || o.seed != s.seed)
    throw std::invalid_argument("CoresetDraw::merge: draws of different coreset options");
  for (std::size_t slot = 0; slot < s.slots; ++slot) {
    if (!(o.slot_key[slot] < s.slot_key[slot])) continue;
    s.slot_key[slot] = o.slot_key[slot];
    s.slot_energy[slot] = o.slot_energy[slot];
    s.slot_block[slot] = o.slot_block[slot];
    std::copy_n(o.slot_values.data() + slot * s.m, s.m, s.slot_values.data() + slot * s.m);
  }
  s.frames.insert(s.frames.end(), o.frames.begin(), o.frames.end());
}

namespace {

template <class T>
void put(std::vector<std::byte>& out, const T* values, std::size_t count) {
  const std::size_t at = out.size(), bytes = count * sizeof(T);
  out.resize(at + bytes);
  if (bytes > 0) std::memcpy(out.data() + at, values, bytes);
}

template <class T>
void take(std::span<const std::byte> in, std::size_t& at, T* values, std::size_t count) {
  if (at > in.size() || in.size() - at < count * sizeof(T))
    throw std::invalid_argument("CoresetDraw::from_bytes: the bytes end early");
  std::memcpy(values, in.data() + at, count * sizeof(T));
  at += count * sizeof(T);
}

}  // namespace

std::vector<std::byte> CoresetDraw::to_bytes() const {
  const State& s = *state_;
  std::vector<std::byte> out;
  const std::uint64_t frames = s.frames.size();
  put(out, &frames, 1);
  put(out, s.frames.data(), s.frames.size());
  put(out, s.slot_key.data(), s.slots);
  put(out, s.slot_energy.data(), s.slots);
  put(out, s.slot_block.data(), s.slots);
  put(out, s.slot_values.data(), s.slot_values.size());
  return out;
}

CoresetDraw CoresetDraw::from_bytes(std::span<const std::byte> bytes,
                                    const CoresetOptions& options) {
  CoresetDraw d(options);
  State& s = *d.state_;
  std::size_t at = 0;
  std::uint64_t frames = 0;
  take(bytes, at, &frames, 1);
  if (frames > bytes.size() / sizeof(State::Frame))
    throw std::invalid_argument("CoresetDraw::from_bytes: the bytes end early");
  s.frames.resize(static_cast<std::size_t>(frames));
  take(bytes, at, s.frames.data(), s.frames.size());
  take(bytes, at, s.slot_key.data(), s.slots);
  take(bytes, at, s.slot_energy.data(), s.slots);
  take(bytes, at, s.slot_block.data(), s.slots);
  take(bytes, at, s.slot_values.data(), s.slot_values.size());
  if (at != bytes.size())
    throw std::invalid_argument("CoresetDraw::from_bytes: bytes left over (other options?)");
  return d;
}

CoresetHierarchy CoresetDraw::finish(int levels) const {
  const State& s = *state_;
  CoresetHierarchy h;
  h.block_size = s.block_size;
  // The frames' totals in frame order, whichever process drew them.
  std::vector<State::Frame> frames = s.frames;
  std::sort(frames.begin(), frames.end(),
            [](const State::Frame& a, const State::Frame& b) { return a.t < b.t; });
  h.value_min = std::numeric_limits<double>::infinity();
  h.value_max = -h.value_min;
  for (const State::Frame& f : frames) {
    h.population_blocks += f.blocks;
    h.population_energy += f.energy;
    h.value_min = std::min(h.value_min, f.lo);
    h.value_max = std::max(h.value_max, f.hi);
  }
  h.levels.resize(static_cast<std::size_t>(levels) + 1);
  if (!(h.population_energy > 0)) return h;  // every block flat: nothing to learn from
  for (int l = 0; l <= levels; ++l) {
    // Level l: the first n_l slots, with slots holding the same block merged.
    const std::size_t n_l = s.slots >> (levels - l);
    std::vector<std::size_t> order(n_l);
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return s.slot_block[a] < s.slot_block[b];
    });
    std::vector<std::size_t> first_slot;
    std::vector<std::size_t> copies;
    for (std::size_t i = 0; i < n_l; ++i) {
      if (i > 0 && s.slot_block[order[i]] == s.slot_block[order[i - 1]]) {
        ++copies.back();
      } else {
        first_slot.push_back(order[i]);
        copies.push_back(1);
      }
    }
    Coreset& c = h.levels[static_cast<std::size_t>(l)];
    c.draws = n_l;
    c.blocks.resize(static_cast<Eigen::Index>(s.m), static_cast<Eigen::Index>(first_slot.size()));
    c.weights.resize(first_slot.size());
    for (std::size_t j = 0; j < first_slot.size(); ++j) {
      const std::size_t slot = first_slot[j];
      std::copy_n(s.slot_values.data() + slot * s.m, s.m,
                  c.blocks.col(static_cast<Eigen::Index>(j)).data());
      // Hansen–Hurwitz: copies / (n_l · p_b) with p_b = e_b / E.
      c.weights[j] =
          static_cast<float>(static_cast<double>(copies[j]) * h.population_energy /
                             (static_cast<double>(n_l) * static_cast<double>(s.slot_energy[slot])));
    }
  }
  return h;
}

std::vector<std::size_t> halton_frames(const std::vector<std::size_t>& candidates,
                                       std::size_t voxels_per_frame, double min_voxels) {
  const std::size_t T = candidates.size();
  std::vector<std::size_t> chosen;
  std::vector<bool> used(T, false);
  double voxels = 0;
  // The first 2^(ceil(log2 T) + 1) points of the sequence hit every frame's interval [t/T,
  // (t+1)/T).
  std::uint64_t limit = 4;
  while (limit < 2 * static_cast<std::uint64_t>(T)) limit *= 2;
  for (std::uint64_t i = 1; i <= 2 * limit && voxels < min_voxels && chosen.size() < T; ++i) {
    const auto t = std::min(
        T - 1, static_cast<std::size_t>(radical_inverse_base2(i) * static_cast<double>(T)));
    if (used[t]) continue;
    used[t] = true;
    chosen.push_back(candidates[t]);
    voxels += static_cast<double>(voxels_per_frame);
  }
  for (std::size_t t = 0; t < T && voxels < min_voxels; ++t)  // safety net; not reached in practice
    if (!used[t]) {
      used[t] = true;
      chosen.push_back(candidates[t]);
      voxels += static_cast<double>(voxels_per_frame);
    }
  return chosen;
}

std::vector<std::size_t> coreset_frames(const datasets::SeriesReader& series,
                                        const CoresetOptions& options) {
  const auto& info = series.info();
  std::vector<std::size_t> candidates = options.candidate_frames;
  if (candidates.empty()) {
    candidates.resize(info.frames);
    std::iota(candidates.begin(), candidates.end(), std::size_t{0});
  }
  for (std::size_t t : candidates)
    if (t >= info.frames)
      throw InputError("frame " + std::to_string(t) + " asked for, but " + info.source + " has " +
                       std::to_string(info.frames) + " frames");
  return halton_frames(candidates, info.dims.voxels(),
                       options.frame_factor * static_cast<double>(options.coreset_voxels));
}

CoresetDraw draw_coreset(const datasets::SeriesReader& series, const CoresetOptions& options,
                         std::span<const std::size_t> frames, const Progress& progress) {
  CoresetDraw draw(options);
  std::vector<float> volume(series.info().dims.voxels());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    progress.report(static_cast<double>(i), static_cast<double>(frames.size()),
                    "frame " + std::to_string(frames[i]));
    series.read_frame(frames[i], volume);
    draw.add_frame(frames[i], volume, series.info().dims);
  }
  progress.report(static_cast<double>(frames.size()), static_cast<double>(frames.size()));
  return draw;
}

CoresetHierarchy build_coreset_hierarchy(const datasets::SeriesReader& series,
                                         const CoresetOptions& options, const Progress& progress) {
  slot_count(options);  // the options checked before any frame is read
  const auto frames = coreset_frames(series, options);
  CoresetHierarchy h = draw_coreset(series, options, frames, progress).finish(options.levels);
  h.frames = frames;
  return h;
}

CoresetHierarchy build_coreset_hierarchy(const std::vector<Volume>& frames,
                                         const CoresetOptions& options) {
  CoresetDraw draw(options);
  for (std::size_t t = 0; t < frames.size(); ++t) draw.add_frame(t, frames[t].data, frames[t].dims);
  CoresetHierarchy h = draw.finish(options.levels);
  h.frames.resize(frames.size());
  std::iota(h.frames.begin(), h.frames.end(), std::size_t{0});
  return h;
}

std::string too_few_blocks_warning(const CoresetHierarchy& hierarchy, int atoms) {
  const auto blocks = hierarchy.levels.empty()
                          ? std::size_t{0}
                          : static_cast<std::size_t>(hierarchy.largest().blocks.cols());
  if (blocks == 0 || 2 * static_cast<std::size_t>(atoms) <= blocks) return {};
  std::size_t fewer = 1;
  while (4 * fewer <= blocks) fewer *= 2;  // a power of two, at most half the blocks
  return "K = " + std::to_string(atoms) + " atoms from " + std::to_string(blocks) +
         " distinct training blocks: K-SVD fits an atom to the blocks that use it, so most atoms "
         "keep their start and still cost their bytes in every container; train fewer (e.g. "
         "--atoms " +
         std::to_string(fewer) + ") or on more or larger frames";
}

}  // namespace volreel::dictionary
