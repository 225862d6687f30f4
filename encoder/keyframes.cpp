// keyframes.cpp: the greedy keyframe choice along each node's time line (keyframes.hpp).
#include "volreel/encoder/keyframes.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <stdexcept>
#include <vector>

#include "volreel/format/brick_decode.h"

namespace volreel::encoder {

namespace {

/// Squared errors of a brick against its original, per 6³ block and in all.
struct BrickError {
  std::vector<double> block;
  double total = 0;
};

/// The blocks a brick's errors are taken over: its box of coded blocks (format::coded_box), the
/// ones a renderer reads; blocks past it are padding.
using Box = std::array<std::uint32_t, 3>;

/// Adds the squared differences o − (f0·a + f1·b) of the first `blocks` blocks' voxels of one row
/// of a brick (6·blocks voxels) to their sums; returns the row's largest |difference|.
double add_row(std::uint32_t blocks, const float* o, const float* a, const float* b, double f0,
               double f1, double* block_sums) {
  double d2[format::max_brick_size];
  double largest = 0;
  for (std::uint32_t x = 0; x < blocks * VR_BLOCK_SIZE; ++x) {
    const double d = static_cast<double>(o[x]) -
                     (f0 * static_cast<double>(a[x]) + f1 * static_cast<double>(b[x]));
    d2[x] = d * d;
    largest = std::max(largest, std::abs(d));
  }
  for (std::uint32_t bx = 0; bx < blocks; ++bx) {
    double sum = 0;
    for (std::uint32_t x = 0; x < VR_BLOCK_SIZE; ++x) sum += d2[bx * VR_BLOCK_SIZE + x];
    block_sums[bx] += sum;
  }
  return largest;
}

/// The coded brick's error against the original over its box (a stored state's, for the rule).
BrickError coded_error(format::BrickShape shape, const Box& box, const float* o, const float* c) {
  const std::uint32_t side = shape.size, n = shape.blocks_per_axis();
  BrickError e;
  e.block.assign(shape.blocks(), 0.0);
  for (std::uint32_t z = 0; z < box[2] * VR_BLOCK_SIZE; ++z)
    for (std::uint32_t y = 0; y < box[1] * VR_BLOCK_SIZE; ++y) {
      const std::size_t row = (std::size_t{z} * side + y) * side;
      add_row(box[0], o + row, c + row, c + row, 1.0, 0.0,
              &e.block[((z / VR_BLOCK_SIZE) * n + y / VR_BLOCK_SIZE) * n]);
    }
  for (double v : e.block) e.total += v;
  return e;
}

/// Whether the interpolation (1 − f)·a + f·b stands in for the brick at a step: original o, the
/// error `coded` that storing it would give, under the rule's bounds. In double: the
/// interpolation itself (a decoder's float arithmetic adds a rounding of the value, none where
/// a = b). Over the brick's box; `e`: scratch of one value per block.
bool interpolation_holds(format::BrickShape shape, const Box& box, const float* o,
                         const BrickError& coded, const float* a, const float* b, float f,
                         double eps, double max_abs, bool energy, const KeyframeRule& rule,
                         std::vector<double>& e) {
  if (rule.within_coded_error) eps = 0;
  const std::uint32_t side = shape.size, n = shape.blocks_per_axis();
  const double f1 = static_cast<double>(f), f0 = 1.0 - f1;
  const double block_tolerance = VR_BLOCK_LENGTH * eps * eps;
  e.assign(shape.blocks(), 0.0);
  double total = 0;
  for (std::uint32_t bz = 0; bz < box[2]; ++bz) {
    for (std::uint32_t z = bz * VR_BLOCK_SIZE; z < (bz + 1) * VR_BLOCK_SIZE; ++z)
      for (std::uint32_t y = 0; y < box[1] * VR_BLOCK_SIZE; ++y) {
        const std::size_t row = (std::size_t{z} * side + y) * side;
        const double largest = add_row(box[0], o + row, a + row, b + row, f0, f1,
                                       &e[(bz * n + y / VR_BLOCK_SIZE) * n]);
        if (max_abs > 0 && largest > max_abs) return false;
      }
    if (!energy) continue;
    // The slab of blocks bz is complete.
    for (std::uint32_t k = bz * n * n; k < (bz + 1) * n * n; ++k) {
      if (e[k] > rule.block_factor * std::max(block_tolerance, coded.block[k])) return false;
      total += e[k];
    }
  }
  return !energy ||
         total <= rule.brick_factor *
                      std::max(static_cast<double>(shape.voxels()) * eps * eps, coded.total);
}

}  // namespace

std::vector<std::vector<char>> choose_keyframes(std::span<const CodedFrame* const> frames,
                                                const format::AtomTable& atoms,
                                                const KeyframeRule& rule) {
  const std::size_t n = frames.size();
  std::vector<std::vector<char>> keep(n);
  if (n == 0) return keep;
  const std::size_t cells = frames[0]->bricks.size();
  const format::BrickShape shape{frames[0]->header.brick_size};
  const std::size_t brick_voxels = shape.voxels();
  for (std::size_t f = 0; f < n; ++f) {
    if (frames[f]->bricks.size() != cells || frames[f]->header.brick_size != shape.size ||
        frames[f]->originals.size() != cells * brick_voxels)
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
  std::exception_ptr error;
  const format::Codec codec = static_cast<format::Codec>(frames[0]->header.codec);
#pragma omp parallel
  {
    std::vector<float> states(n * brick_voxels);
    std::vector<BrickError> coded(n);
    std::vector<double> scratch;
#pragma omp for schedule(dynamic, 1)
    for (std::ptrdiff_t ci = 0; ci < static_cast<std::ptrdiff_t>(cells); ++ci) {
      const auto i = static_cast<std::size_t>(ci);
      try {
        // Each step's stored state of this node, as a decoder would have it.
        const auto state = [&](std::size_t f) { return states.data() + f * brick_voxels; };
        std::vector<char> forced(n, 0);
        const CodedBrick& cell = frames[0]->bricks[i];
        const Box box = format::coded_box(shape, {cell.x, cell.y, cell.z},
                                          frames[0]->geometry[cell.level].dims);
        for (std::size_t f = 0; f < n; ++f) {
          const CodedBrick& b = frames[f]->bricks[i];
          const std::span<float> out(state(f), brick_voxels);
          if (covered[f][i])
            std::fill(out.begin(), out.end(), cover_value[f][i]);
          else
            format::decode_payload(b.payload, codec, frames[f]->header.codec_parameter, atoms,
                                   shape, out, "<encoder>", 0);
          forced[f] = f == 0 || f + 1 == n || covered[f][i] || b.subtree_constant;
          if (!forced[f])
            coded[f] =
                coded_error(shape, box, frames[f]->originals.data() + i * brick_voxels, state(f));
        }
        std::size_t k = 0;
        while (k + 1 < n) {
          std::size_t best = k + 1;
          for (std::size_t u = k + 2; u < n && !forced[u - 1]; ++u) {
            bool holds = true;
            for (std::size_t t = k + 1; t < u && holds; ++t) {
              const float f =
                  static_cast<float>(static_cast<double>(t - k) / static_cast<double>(u - k));
              const CodedFrame& ft = *frames[t];
              holds = interpolation_holds(shape, box, ft.originals.data() + i * brick_voxels,
                                          coded[t], state(k), state(u), f, ft.bricks[i].tolerance,
                                          ft.max_abs_error, codec == format::Codec::ksvd, rule,
                                          scratch);
            }
            if (!holds) break;
            best = u;
          }
          for (std::size_t t = k + 1; t < best; ++t) {
            keep[t][i] = 0;
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
  return keep;
}

}  // namespace volreel::encoder
