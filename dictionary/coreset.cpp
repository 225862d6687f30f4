// coreset.cpp: Halton frame selection and the one-pass importance sampler that yields every level
// of the coreset hierarchy (see coreset.hpp for the method).
#include "volreel/dictionary/coreset.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
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

/// The streaming sampler: n slots, each an independent size-1 weighted reservoir (probability
/// proportional to block energy), so that any prefix of the slots is a sample of its own.
class StreamingSampler {
 public:
  StreamingSampler(int block_size, std::size_t slots, std::uint64_t seed)
      : block_size_(block_size),
        m_(static_cast<std::size_t>(block_size) * static_cast<std::size_t>(block_size) *
           static_cast<std::size_t>(block_size)),
        slots_(slots),
        slot_values_(slots * m_),
        slot_energy_(slots, 0.0f),
        slot_block_(slots, std::numeric_limits<std::uint64_t>::max()),
        rng_(seed) {}

  void add_frame(std::span<const float> volume, Dims dims) {
    const BlockGrid grid(dims, block_size_);
    const auto blocks = static_cast<std::int64_t>(grid.block_count());
    const std::uint64_t frame = frames_++;

    // 1. Energy of every block (parallel; per block, so independent of the thread count), and
    //    the value range.
    energy_.resize(static_cast<std::size_t>(blocks));
    float lo = std::numeric_limits<float>::infinity(), hi = -lo;
#pragma omp parallel reduction(min : lo) reduction(max : hi)
    {
      std::vector<float> block(m_);
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
        energy_[static_cast<std::size_t>(b)] = static_cast<float>(e);
        lo = std::min(lo, bmin + mean);
        hi = std::max(hi, bmax + mean);
      }
    }
    value_min_ = std::min(value_min_, static_cast<double>(lo));
    value_max_ = std::max(value_max_, static_cast<double>(hi));
    population_blocks_ += static_cast<double>(blocks);

    // 2. Reservoir updates, in block order (sequential: this is what makes the draw reproducible).
    //    Block b replaces the content of each slot independently with q = e_b / E_b; the slots it
    //    takes are visited by geometric skips (failures before a success ~ floor(ln U / ln(1−q))).
    taken_.assign(slots_, -1);
    for (std::int64_t b = 0; b < blocks; ++b) {
      const double e = static_cast<double>(energy_[static_cast<std::size_t>(b)]);
      if (!(e > 0)) continue;
      population_energy_ += e;
      const double q = e / population_energy_;
      if (q >= 1.0) {
        std::fill(taken_.begin(), taken_.end(), b);
        continue;
      }
      const double log_fail = std::log1p(-q);
      if (!(log_fail < 0)) continue;  // q below double precision: no slot takes the block
      double position = -1;
      for (;;) {
        const double skip = std::floor(std::log1p(-rng_.uniform()) / log_fail);
        position += skip + 1;
        if (position >= static_cast<double>(slots_)) break;
        taken_[static_cast<std::size_t>(position)] = b;
      }
    }

    // 3. Copy the blocks that now own a slot (only the final owner of each slot is copied).
    const auto slots = static_cast<std::int64_t>(slots_);
#pragma omp parallel for schedule(static)
    for (std::int64_t s = 0; s < slots; ++s) {
      const std::int64_t b = taken_[static_cast<std::size_t>(s)];
      if (b < 0) continue;
      const auto slot = static_cast<std::size_t>(s);
      grid.extract(volume, static_cast<std::size_t>(b), slot_values_.data() + slot * m_);
      slot_energy_[slot] = energy_[static_cast<std::size_t>(b)];
      slot_block_[slot] = frame << 40 | static_cast<std::uint64_t>(b);
    }
  }

  CoresetHierarchy finish(int levels) const {
    CoresetHierarchy h;
    h.block_size = block_size_;
    h.population_blocks = population_blocks_;
    h.population_energy = population_energy_;
    h.value_min = value_min_;
    h.value_max = value_max_;
    h.levels.resize(static_cast<std::size_t>(levels) + 1);
    if (!(population_energy_ > 0)) return h;  // every block flat: nothing to learn from
    for (int l = 0; l <= levels; ++l) {
      // Level l: the first n_l slots, with slots holding the same block merged.
      const std::size_t n_l = slots_ >> (levels - l);
      std::vector<std::size_t> order(n_l);
      std::iota(order.begin(), order.end(), std::size_t{0});
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return slot_block_[a] < slot_block_[b];
      });
      std::vector<std::size_t> first_slot;
      std::vector<std::size_t> copies;
      for (std::size_t i = 0; i < n_l; ++i) {
        if (i > 0 && slot_block_[order[i]] == slot_block_[order[i - 1]]) {
          ++copies.back();
        } else {
          first_slot.push_back(order[i]);
          copies.push_back(1);
        }
      }
      Coreset& c = h.levels[static_cast<std::size_t>(l)];
      c.draws = n_l;
      c.blocks.resize(static_cast<Eigen::Index>(m_), static_cast<Eigen::Index>(first_slot.size()));
      c.weights.resize(first_slot.size());
      for (std::size_t j = 0; j < first_slot.size(); ++j) {
        const std::size_t s = first_slot[j];
        std::copy_n(slot_values_.data() + s * m_, m_,
                    c.blocks.col(static_cast<Eigen::Index>(j)).data());
        // Hansen–Hurwitz: copies / (n_l · p_b) with p_b = e_b / E.
        c.weights[j] =
            static_cast<float>(static_cast<double>(copies[j]) * population_energy_ /
                               (static_cast<double>(n_l) * static_cast<double>(slot_energy_[s])));
      }
    }
    return h;
  }

 private:
  int block_size_;
  std::size_t m_, slots_;
  std::vector<float> slot_values_;  // slots × m
  std::vector<float> slot_energy_;
  std::vector<std::uint64_t> slot_block_;  // frame << 40 | block: identifies the block in a slot
  std::vector<float> energy_;              // scratch: energies of the current frame's blocks
  std::vector<std::int64_t> taken_;        // scratch: block that took each slot in this frame
  SplitMix64 rng_;
  std::uint64_t frames_ = 0;
  double population_blocks_ = 0, population_energy_ = 0;
  double value_min_ = std::numeric_limits<double>::infinity();
  double value_max_ = -std::numeric_limits<double>::infinity();
};

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

}  // namespace

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

CoresetHierarchy build_coreset_hierarchy(const datasets::SeriesReader& series,
                                         const CoresetOptions& options, const Progress& progress) {
  const std::size_t slots = slot_count(options);
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
  const auto frames =
      halton_frames(candidates, info.dims.voxels(),
                    options.frame_factor * static_cast<double>(options.coreset_voxels));
  StreamingSampler sampler(options.block_size, slots, options.seed);
  std::vector<float> volume(info.dims.voxels());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    progress.report(static_cast<double>(i), static_cast<double>(frames.size()),
                    "frame " + std::to_string(frames[i]));
    series.read_frame(frames[i], volume);
    sampler.add_frame(volume, info.dims);
  }
  progress.report(static_cast<double>(frames.size()), static_cast<double>(frames.size()));
  CoresetHierarchy h = sampler.finish(options.levels);
  h.frames = frames;
  return h;
}

CoresetHierarchy build_coreset_hierarchy(const std::vector<Volume>& frames,
                                         const CoresetOptions& options) {
  StreamingSampler sampler(options.block_size, slot_count(options), options.seed);
  for (const Volume& v : frames) sampler.add_frame(v.data, v.dims);
  CoresetHierarchy h = sampler.finish(options.levels);
  h.frames.resize(frames.size());
  std::iota(h.frames.begin(), h.frames.end(), std::size_t{0});
  return h;
}

}  // namespace volreel::dictionary
