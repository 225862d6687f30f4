// keyframes.cpp: the greedy keyframe choice along each node's time line (keyframes.hpp).
#include "volreel/encoder/keyframes.hpp"

#include <algorithm>
#include <cmath>
#include <exception>
#include <stdexcept>

#include "volreel/format/brick_decode.h"

namespace volreel::encoder {

namespace {

using format::brick_voxels;

/// Whether the interpolation (1 − f)·a + f·b stands in for the brick at a step: original o, coded
/// c (what storing it would give), under the rule's bounds.
bool interpolation_holds(const float* o, const float* c, const float* a, const float* b, float f,
                         double eps, double max_abs, bool energy, const KeyframeRule& rule) {
  if (rule.within_coded_error) eps = 0;
  const double block_factor = rule.block_factor;
  // In double: the interpolation itself; a decoder's float arithmetic adds a rounding of the
  // value (none where a = b).
  const double f1 = static_cast<double>(f), f0 = 1.0 - f1;
  double total = 0, total_coded = 0;
  const double block_tolerance = VR_BLOCK_LENGTH * eps * eps;
  for (std::uint32_t bz = 0; bz < VR_BLOCKS_PER_AXIS; ++bz)
    for (std::uint32_t by = 0; by < VR_BLOCKS_PER_AXIS; ++by)
      for (std::uint32_t bx = 0; bx < VR_BLOCKS_PER_AXIS; ++bx) {
        double e = 0, e_coded = 0;
        for (std::uint32_t z = 0; z < VR_BLOCK_SIZE; ++z)
          for (std::uint32_t y = 0; y < VR_BLOCK_SIZE; ++y) {
            const std::size_t row =
                ((bz * VR_BLOCK_SIZE + z) * format::brick_size + by * VR_BLOCK_SIZE + y) *
                    format::brick_size +
                bx * VR_BLOCK_SIZE;
            for (std::uint32_t x = 0; x < VR_BLOCK_SIZE; ++x) {
              const std::size_t v = row + x;
              const double interpolated =
                  f0 * static_cast<double>(a[v]) + f1 * static_cast<double>(b[v]);
              const double d = static_cast<double>(o[v]) - interpolated;
              const double dc = static_cast<double>(o[v]) - static_cast<double>(c[v]);
              if (max_abs > 0 && std::abs(d) > max_abs) return false;
              e += d * d;
              e_coded += dc * dc;
            }
          }
        if (!energy) continue;
        if (e > block_factor * std::max(block_tolerance, e_coded)) return false;
        total += e;
        total_coded += e_coded;
      }
  return !energy ||
         total <= rule.brick_factor *
                      std::max(static_cast<double>(brick_voxels) * eps * eps, total_coded);
}

}  // namespace

std::vector<std::vector<char>> choose_keyframes(std::span<const CodedFrame* const> frames,
                                                const format::AtomTable& atoms,
                                                const KeyframeRule& rule, KeyframeStats* stats) {
  const std::size_t n = frames.size();
  std::vector<std::vector<char>> keep(n);
  if (n == 0) return keep;
  const std::size_t cells = frames[0]->bricks.size();
  for (std::size_t f = 0; f < n; ++f) {
    if (frames[f]->bricks.size() != cells || frames[f]->originals.size() != cells * brick_voxels)
      throw std::invalid_argument(
          "choose_keyframes: frames of one geometry, coded with their originals");
    keep[f].assign(cells, 1);
  }
  // Per frame and brick: covered by an empty ancestor (not in the frame's tree), so its state is
  // that ancestor's constant.
  std::vector<std::vector<char>> covered(n, std::vector<char>(cells, 0));
  std::vector<std::vector<float>> cover_value(n, std::vector<float>(cells, 0));
  for (std::size_t f = 0; f < n; ++f) {
    const CodedFrame& cf = *frames[f];
    for (std::size_t i = 1; i < cells; ++i) {  // parents come before their children
      const std::size_t p = cf.parent[i];
      if (covered[f][p] || cf.bricks[p].subtree_constant) {
        covered[f][i] = 1;
        cover_value[f][i] = covered[f][p] ? cover_value[f][p] : cf.bricks[p].value;
      }
    }
  }
  std::size_t nodes = 0, interpolated = 0;
  std::exception_ptr error;
  const format::Codec codec = static_cast<format::Codec>(frames[0]->header.codec);
#pragma omp parallel reduction(+ : nodes, interpolated)
  {
    std::vector<float> states(n * brick_voxels), coded(brick_voxels);
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t ci = 0; ci < static_cast<std::ptrdiff_t>(cells); ++ci) {
      const auto i = static_cast<std::size_t>(ci);
      try {
        // Each step's stored state of this node, as a decoder would have it.
        const auto state = [&](std::size_t f) { return states.data() + f * brick_voxels; };
        std::vector<char> forced(n, 0);
        for (std::size_t f = 0; f < n; ++f) {
          const CodedBrick& b = frames[f]->bricks[i];
          const std::span<float> out(state(f), brick_voxels);
          if (covered[f][i])
            std::fill(out.begin(), out.end(), cover_value[f][i]);
          else
            format::decode_payload(b.payload, codec, frames[f]->header.codec_parameter, atoms, out,
                                   "<encoder>", 0);
          forced[f] = f == 0 || f + 1 == n || covered[f][i] || b.subtree_constant;
          if (!covered[f][i]) ++nodes;
        }
        const std::uint32_t level = frames[0]->bricks[i].level;
        std::size_t k = 0;
        while (k + 1 < n) {
          std::size_t best = k + 1;
          for (std::size_t u = k + 2; u < n && !forced[u - 1]; ++u) {
            bool holds = true;
            for (std::size_t t = k + 1; t < u && holds; ++t) {
              const float f =
                  static_cast<float>(static_cast<double>(t - k) / static_cast<double>(u - k));
              const CodedFrame& ft = *frames[t];
              holds = interpolation_holds(ft.originals.data() + i * brick_voxels, state(t),
                                          state(k), state(u), f, ft.level_tolerance[level],
                                          ft.max_abs_error, codec == format::Codec::ksvd, rule);
            }
            if (!holds) break;
            best = u;
          }
          for (std::size_t t = k + 1; t < best; ++t) {
            keep[t][i] = 0;
            ++interpolated;
          }
          k = best;
        }
      } catch (...) {
#pragma omp critical(volreel_keyframes_error)
        if (!error) error = std::current_exception();
      }
    }
  }
  if (error) std::rethrow_exception(error);
  if (stats) {
    stats->nodes += nodes;
    stats->interpolated += interpolated;
  }
  return keep;
}

}  // namespace volreel::encoder
