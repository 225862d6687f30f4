// brick_coding.cpp: one brick's payload — a constant, the ksvd payload (block means to b bits,
// sparse codes quantized at a uniform step with a least-squares refit, optionally extending the
// pursuit after quantization), or a zfp stream — and the blocks' owned shares that weigh their
// atoms.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "detail.hpp"
#include "volreel/format/brick_decode.h"
#include "volreel/format/decoder.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/format/zfp_stream.hpp"

namespace volreel::encoder::detail {

namespace {

/// Mid-tread quantizer of the block means over [lo, hi] with `levels`+1 steps:
/// q = round((v − bias)/scale).
struct MeanQuantizer {
  float bias = 0, scale = 0;
  std::uint32_t levels = 0;
  MeanQuantizer(float lo, float hi, std::uint32_t n)
      : bias(lo), scale(hi > lo ? (hi - lo) / static_cast<float>(n) : 0.0f), levels(n) {}
  std::uint32_t quantize(double v) const {
    if (!(scale > 0)) return 0;
    const double q = std::round((v - static_cast<double>(bias)) / static_cast<double>(scale));
    return static_cast<std::uint32_t>(std::clamp(q, 0.0, static_cast<double>(levels)));
  }
  float value(std::uint32_t q) const { return bias + scale * static_cast<float>(q); }
};

/// Uniform quantizer of the coefficients, centred on zero: q = round(v/scale), |q| ≤ limit; a
/// coefficient that rounds to 0 is no code at all.
struct Quantizer {
  float scale = 0;
  std::int32_t limit = 0;
  Quantizer(float step, std::int32_t most) : scale(step), limit(most) {}
  std::int32_t quantize(double v) const {
    if (!(scale > 0)) return 0;
    const double q = std::round(v / static_cast<double>(scale));
    return static_cast<std::int32_t>(
        std::clamp(q, -static_cast<double>(limit), static_cast<double>(limit)));
  }
  float value(std::int32_t q) const { return scale * static_cast<float>(q); }
};

/// x_0 of the solution of the symmetric positive definite n×n system m·x = t (Cholesky, in place);
/// NaN if m is not positive definite.
double solve_first(double (&m)[15][15], double (&t)[15], int n) {
  for (int j = 0; j < n; ++j) {
    double d = m[j][j];
    for (int k = 0; k < j; ++k) d -= m[j][k] * m[j][k];
    if (!(d > 1e-12)) return std::nan("");
    const double l = std::sqrt(d);
    m[j][j] = l;
    for (int i = j + 1; i < n; ++i) {
      double v = m[i][j];
      for (int k = 0; k < j; ++k) v -= m[i][k] * m[j][k];
      m[i][j] = v / l;
    }
  }
  for (int i = 0; i < n; ++i) {  // L z = t
    for (int k = 0; k < i; ++k) t[i] -= m[i][k] * t[k];
    t[i] /= m[i][i];
  }
  for (int i = n - 1; i >= 0; --i) {  // Lᵀ x = z
    for (int k = i + 1; k < n; ++k) t[i] -= m[k][i] * t[k];
    t[i] /= m[i][i];
  }
  return t[0];
}

/// r[v] −= c·atom[v] over a block (out of line, so that it is vectorized, not interchanged).
[[gnu::noinline]] void subtract_scaled(float* __restrict r, const float* __restrict atom, float c) {
#pragma omp simd
  for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) r[v] -= c * atom[v];
}

/// Quantized coefficients of one block on support a[0..s) (in order). Without refit (or with more
/// than max_refit_atoms atoms) each OMP coefficient is rounded; with refit step k solves the
/// trailing (s−k)×(s−k) normal equations G x = Dᵀy with the first k coefficients fixed at their
/// quantized values, and rounds x_0, so later coefficients absorb the rounding error of earlier
/// ones. Orthonormal atoms (G = I) make x_0 the coefficient itself, so they are rounded without
/// refit. Returns the squared error of the quantized block (mean error included) and fills q.
constexpr int max_refit_atoms = 15;  ///< beyond this many atoms, each coefficient is rounded

double quantize_block(const float* y, float mean_error, const std::int32_t* a, const float* c,
                      int s, const Eigen::MatrixXf& atoms, const Quantizer& cq, bool refit,
                      std::int32_t* q) {
  if (!refit || s <= 1 || s > max_refit_atoms) {
    for (int k = 0; k < s; ++k) q[k] = cq.quantize(static_cast<double>(c[k]));
  } else {
    double g[15][15], rhs[15], fixed[15];
    for (int r = 0; r < s; ++r) {
      const float* d = atoms.col(a[r]).data();
      float dot = 0;
#pragma omp simd reduction(+ : dot)
      for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) dot += d[v] * y[v];
      rhs[r] = static_cast<double>(dot);
      // DᵀD of the support from the atoms themselves: the K×K Gram matrix is too large for the
      // cache, and s² random reads from it cost more than s²/2 short dot products.
      for (int k = 0; k <= r; ++k) {
        const float* e = atoms.col(a[k]).data();
        float gd = 0;
#pragma omp simd reduction(+ : gd)
        for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) gd += d[v] * e[v];
        g[r][k] = g[k][r] = static_cast<double>(gd);
      }
    }
    for (int k = 0; k < s; ++k) {
      const int n = s - k;
      double m[15][15], t[15];
      for (int r = 0; r < n; ++r) {
        t[r] = rhs[k + r];
        for (int j = 0; j < k; ++j) t[r] -= g[k + r][j] * fixed[j];
        for (int j = 0; j < n; ++j) m[r][j] = g[k + r][k + j];
      }
      const double value = solve_first(m, t, n);
      q[k] = cq.quantize(std::isfinite(value) ? value : static_cast<double>(c[k]));
      fixed[k] = static_cast<double>(cq.value(q[k]));
    }
  }
  // The residual atom by atom (contiguous columns, vectorizable), then its energy.
  alignas(64) float r[VR_BLOCK_LENGTH];
  for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) r[v] = y[v] + mean_error;
  for (int k = 0; k < s; ++k) subtract_scaled(r, atoms.col(a[k]).data(), cq.value(q[k]));
  double e = 0;
  for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v)
    e += static_cast<double>(r[v]) * static_cast<double>(r[v]);
  return e;
}

/// Mean bits at fixed rate, where no ε sets a step: a step of 1/4095 of the means' span.
constexpr std::uint32_t fixed_rate_mean_bits = 12;

/// The mean bits of a brick whose block means span [lo, hi]: `forced` when ≥ 0, else the fewest
/// bits b (0..VR_MEAN_BITS) whose quantization step (hi − lo)/(2^b − 1) is at most `step` (b = 0:
/// the one level is the midpoint, so a span up to `step` suffices), and VR_MEAN_BITS when none
/// is; fixed_rate_mean_bits when step ≤ 0.
std::uint32_t choose_mean_bits(float lo, float hi, double step, int forced) {
  if (forced >= 0) return static_cast<std::uint32_t>(forced);
  if (!(step > 0)) return fixed_rate_mean_bits;
  const double span = static_cast<double>(hi) - static_cast<double>(lo);
  for (std::uint32_t b = 0; b < VR_MEAN_BITS; ++b)
    if (span <= step * static_cast<double>(b == 0 ? 1u : (1u << b) - 1u)) return b;
  return VR_MEAN_BITS;
}

/// Largest |value| of a block's quantized residual.
double max_abs_residual(const float* y, float mean_error, const std::int32_t* a,
                        const std::int32_t* q, int s, const Eigen::MatrixXf& atoms,
                        const Quantizer& cq) {
  alignas(64) float r[VR_BLOCK_LENGTH];
  for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) r[v] = y[v] + mean_error;
  for (int k = 0; k < s; ++k) subtract_scaled(r, atoms.col(a[k]).data(), cq.value(q[k]));
  double m = 0;
  for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v)
    m = std::max(m, std::abs(static_cast<double>(r[v])));
  return m;
}

/// The coefficient step of a brick whose largest coefficient magnitude is `largest`: `forced`
/// magnitude bits c ≥ 1 give largest/2^c; else `step` (variable rate), or with step ≤ 0 (fixed
/// rate) largest/2^(fallback − 1); never finer than largest/2^16, the most magnitude bits.
double coefficient_step(double largest, double step, int forced, std::uint32_t fallback) {
  if (!(largest > 0)) return 0;
  if (forced >= 1) return largest / std::ldexp(1.0, forced);
  if (!(step > 0)) step = largest / std::ldexp(1.0, static_cast<int>(fallback) - 1);
  return std::max(step, largest / std::ldexp(1.0, VR_MAX_COEF_BITS));
}

/// The fewest magnitude bits c (1..16) with |q| ≤ 2^c for every q of the brick.
std::uint32_t magnitude_bits(std::int64_t largest) {
  std::uint32_t c = 1;
  while (c < VR_MAX_COEF_BITS && (std::int64_t{1} << c) < largest) ++c;
  return c;
}

}  // namespace

std::vector<std::byte> constant_payload(float v) {
  std::vector<std::byte> p(4);
  std::memcpy(p.data(), &v, 4);
  return p;
}

void brick_to_blocks(format::BrickShape shape, const float* brick, float* columns, float* means) {
  for (std::uint32_t b = 0; b < shape.blocks(); ++b) {
    float* col = columns + std::size_t{b} * VR_BLOCK_LENGTH;
    double sum = 0;
    for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) {
      col[v] = brick[vr_brick_voxel(shape.blocks_per_axis(), b, v)];
      sum += static_cast<double>(col[v]);
    }
    const auto mean = static_cast<float>(sum / VR_BLOCK_LENGTH);
    for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) col[v] -= mean;
    means[b] = mean;
  }
}

void owned_block_shares(format::BrickShape shape, std::uint32_t x, std::uint32_t y, std::uint32_t z,
                        const std::array<std::uint32_t, 3>& dims, float* shares) {
  const std::uint32_t position[3] = {x, y, z};
  const std::uint32_t n = shape.blocks_per_axis();
  const std::int64_t interior = shape.interior();
  float owned[3][VR_MAX_BLOCKS_PER_AXIS];  // owned voxels of block column c on axis a
  for (std::size_t a = 0; a < 3; ++a) {
    // Stored index i holds level voxel I·p − 1 + i (I the interior): owned for 1 ≤ i ≤ I and
    // I·p − 1 + i < dim.
    const std::int64_t end =
        std::min<std::int64_t>(interior + 1, std::int64_t{dims[a]} - interior * position[a] + 1);
    for (std::uint32_t c = 0; c < n; ++c) {
      const std::int64_t lo = std::max<std::int64_t>(1, c * VR_BLOCK_SIZE),
                         hi = std::min<std::int64_t>(end, (c + 1) * VR_BLOCK_SIZE);
      owned[a][c] = static_cast<float>(std::max<std::int64_t>(0, hi - lo)) / VR_BLOCK_SIZE;
    }
  }
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    shares[b] = owned[0][b % n] * owned[1][(b / n) % n] * owned[2][b / (n * n)];
}

void owned_block_weights(format::BrickShape shape, std::uint32_t x, std::uint32_t y,
                         std::uint32_t z, const std::array<std::uint32_t, 3>& dims,
                         float* weights) {
  owned_block_shares(shape, x, y, z, dims, weights);
  for (std::uint32_t b = 0; b < shape.blocks(); ++b)
    weights[b] = weights[b] > 0 ? std::max(weights[b], 1.0f / VR_BLOCK_LENGTH) : 0.0f;
}

/// Step 1: means to b bits over [min, max] of the brick's block means, b the fewest bits whose
/// step is at most options.mean_step (choose_mean_bits). Step 2: the coefficient step
/// (coefficient_step: options.coef_step in variable rate). Step 3: coefficients quantized block by
/// block (quantize_block). Step 4 ("quantization inside the pursuit"): while a block's quantized
/// error exceeds m·ε² (options.target_energy) or one of its values is off by more than
/// options.max_abs_error, and it has fewer than Smax atoms, add the atom most correlated with the
/// quantized residual and quantize again; keep it only if the error falls. Step 5 (pointwise bound
/// only): if a block still misses the bound, code the brick again with half the step, down to
/// the finest step 16 magnitude bits allow. Coefficients that round to 0 are left out, and each
/// block's codes are packed in increasing atom order (the entropy coder's gaps).
std::vector<std::byte> quantize_brick(format::BrickShape shape, const float* columns,
                                      const float* means, const dictionary::SparseCodes& codes,
                                      std::size_t first_block, const Eigen::MatrixXf& atoms,
                                      const QuantizeOptions& options, BrickQuantization* result) {
  const std::uint32_t blocks = shape.blocks(), per_axis = shape.blocks_per_axis();
  const vr_uint box = options.box != 0 ? options.box : vr_make_box(per_axis, per_axis, per_axis);
  const auto coded = [&](std::uint32_t b) { return vr_block_in_box(box, per_axis, b); };
  float mean_lo = means[0], mean_hi = means[0];  // block 0 is always coded
  for (std::uint32_t b = 1; b < blocks; ++b)
    if (coded(b)) {
      mean_lo = std::min(mean_lo, means[b]);
      mean_hi = std::max(mean_hi, means[b]);
    }
  double largest = 0;
  for (std::uint32_t b = 0; b < blocks; ++b) {
    if (!coded(b)) continue;
    const std::size_t i = first_block + b;
    for (int k = 0; k < codes.count[i]; ++k)
      largest = std::max(largest, std::abs(static_cast<double>(codes.coefficients_of(i)[k])));
  }
  const double first_step =
      coefficient_step(largest, options.coef_step, options.coef_bits, options.fixed_coef_bits);
  const double finest_step = largest / std::ldexp(1.0, VR_MAX_COEF_BITS);

  format::KsvdPayloadParts parts;
  parts.sparsity.assign(blocks, 0);
  parts.mean.assign(blocks, 0);
  parts.band_split = options.band_split;
  parts.from_split = options.from_split;
  const std::uint32_t first_atom = options.from_split ? options.band_split : 0;
  for (vr_uint a = 0; a < 3; ++a) parts.box[a] = vr_box_blocks(box, a);
  parts.mean_bits = choose_mean_bits(mean_lo, mean_hi, options.mean_step, options.mean_bits);
  parts.atom_bits =
      std::max<std::uint32_t>(1, format::bits_for_count(static_cast<std::uint64_t>(atoms.cols())));
  const float mean_mid = mean_lo + (mean_hi - mean_lo) / 2;
  const MeanQuantizer mq = parts.mean_bits == 0
                               ? MeanQuantizer(mean_mid, mean_mid, 0)
                               : MeanQuantizer(mean_lo, mean_hi, (1u << parts.mean_bits) - 1u);
  const bool pointwise = options.max_abs_error > 0;
  const bool refit = options.refit && !options.orthonormal_atoms;
  const int max_atoms = std::min<int>(options.max_atoms, (1 << VR_MAX_SPARSITY_BITS) - 1);
  const std::size_t slots = static_cast<std::size_t>(std::max(max_atoms, codes.max_atoms)) + 1;
  // What each block's quantization gives, kept per block so that blocks can be quantized in any
  // order (in parallel) and the brick's sums still add up in block order.
  struct BlockResult {
    std::vector<std::pair<std::uint32_t, std::int32_t>> codes;  // atom, value; sorted, no zeros
    double error = 0;
    bool missed = false;
  };
  std::vector<BlockResult> block_results(blocks);
  // One thread's buffers.
  struct Scratch {
    Eigen::VectorXf residual, correlation;
    std::vector<std::int32_t> a, q, q2;
    std::vector<float> c;
    std::vector<std::pair<std::uint32_t, std::int32_t>> block_codes;
    explicit Scratch(std::size_t n) : residual(VR_BLOCK_LENGTH), a(n), q(n), q2(n), c(n) {}
  };
  for (double step = first_step;; step /= 2) {
    const Quantizer cq(static_cast<float>(step), std::int32_t{1} << VR_MAX_COEF_BITS);
    const auto code_block = [&](std::uint32_t b, Scratch& w) {
      BlockResult& out = block_results[b];
      auto &a = w.a, &q = w.q, &q2 = w.q2;
      auto& c = w.c;
      const std::size_t i = first_block + b;
      int s = codes.count[i];
      std::copy_n(codes.atoms_of(i), s, a.data());
      std::copy_n(codes.coefficients_of(i), s, c.data());
      const float* y = columns + std::size_t{b} * VR_BLOCK_LENGTH;
      const std::uint32_t qmean = mq.quantize(static_cast<double>(means[b]));
      const float mean_error = means[b] - mq.value(qmean);
      double e = quantize_block(y, mean_error, a.data(), c.data(), s, atoms, cq, refit, q.data());
      const auto misses = [&](double energy, const std::int32_t* quantized, int n) {
        if (options.target_energy >= 0 && energy > options.target_energy) return true;
        return pointwise && max_abs_residual(y, mean_error, a.data(), quantized, n, atoms, cq) >
                                options.max_abs_error;
      };
      bool miss = misses(e, q.data(), s);
      while (miss && s < max_atoms && cq.scale > 0) {
        // The quantized residual, its best new atom, and a fresh quantization with it.
        for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) {
          float r = y[v] + mean_error;
          for (int k = 0; k < s; ++k)
            r -= cq.value(q[static_cast<std::size_t>(k)]) *
                 atoms(static_cast<Eigen::Index>(v), a[static_cast<std::size_t>(k)]);
          w.residual(static_cast<Eigen::Index>(v)) = r;
        }
        w.correlation.noalias() = atoms.transpose() * w.residual;
        for (int k = 0; k < s; ++k) w.correlation(a[static_cast<std::size_t>(k)]) = 0;
        Eigen::Index best = 0;
        w.correlation.cwiseAbs().maxCoeff(&best);
        a[static_cast<std::size_t>(s)] = static_cast<std::int32_t>(best);
        c[static_cast<std::size_t>(s)] = w.correlation(best);
        // Past max_refit_atoms each coefficient is rounded on its own: keep the ones already
        // quantized where they are.
        if (s + 1 > max_refit_atoms)
          for (int k = 0; k < s; ++k)
            c[static_cast<std::size_t>(k)] = cq.value(q[static_cast<std::size_t>(k)]);
        const double e2 =
            quantize_block(y, mean_error, a.data(), c.data(), s + 1, atoms, cq, refit, q2.data());
        const bool miss2 = misses(e2, q2.data(), s + 1);
        // Keep the atom when it lowers the squared error, or (pointwise) when it meets the bound.
        if (!(e2 < e) && (!pointwise || miss2)) break;
        ++s;
        e = e2;
        miss = miss2;
        std::copy_n(q2.begin(), s, q.begin());
      }
      out.missed = miss && pointwise;
      out.error = e;
      // The block's codes: zeros left out, in increasing atom order (an atom twice adds up).
      auto& block_codes = w.block_codes;
      block_codes.clear();
      for (int k = 0; k < s; ++k)
        block_codes.emplace_back(static_cast<std::uint32_t>(a[static_cast<std::size_t>(k)]),
                                 q[static_cast<std::size_t>(k)]);
      std::sort(block_codes.begin(), block_codes.end());
      out.codes.clear();
      for (std::size_t k = 0; k < block_codes.size();) {
        const std::uint32_t atom = block_codes[k].first;
        std::int64_t value = 0;
        for (; k < block_codes.size() && block_codes[k].first == atom; ++k)
          value += block_codes[k].second;
        value = std::clamp<std::int64_t>(value, -cq.limit, cq.limit);
        if (value != 0) out.codes.emplace_back(first_atom + atom, static_cast<std::int32_t>(value));
      }
      parts.mean[b] = qmean;
    };
    // A brick's blocks are independent: with options.parallel_blocks (the caller codes fewer
    // bricks at once than there are threads) they are shared among the threads, in runs of
    // `share` blocks; a brick of no more than one run (12³: 8 blocks) is coded on this thread,
    // since a parallel region would hand the other threads nothing but its wake-up and barrier,
    // for every brick of a column of them (a volume long along z).
    constexpr std::uint32_t share = 8;
#pragma omp parallel if (options.parallel_blocks && blocks > share)
    {
      Scratch scratch(slots);
#pragma omp for schedule(dynamic, share)
      for (std::ptrdiff_t bi = 0; bi < static_cast<std::ptrdiff_t>(blocks); ++bi) {
        const auto b = static_cast<std::uint32_t>(bi);
        if (coded(b)) code_block(b, scratch);  // others: sparsity and mean 0, no entry
      }
    }
    parts.atoms.clear();
    parts.values.clear();
    double brick_error = 0, weighted_error = 0;
    std::size_t missed = 0;
    std::uint32_t most_atoms = 0;
    std::int64_t largest_q = 1;
    for (std::uint32_t b = 0; b < blocks; ++b) {
      if (!coded(b)) continue;
      const BlockResult& r = block_results[b];
      for (const auto& [atom, value] : r.codes) {
        parts.atoms.push_back(atom);
        parts.values.push_back(value);
        largest_q = std::max<std::int64_t>(largest_q, value < 0 ? -std::int64_t{value} : value);
      }
      const auto kept = static_cast<std::uint32_t>(r.codes.size());
      parts.sparsity[b] = kept;
      most_atoms = std::max(most_atoms, kept);
      missed += r.missed;
      brick_error += r.error;
      weighted_error +=
          (options.block_weights ? static_cast<double>(options.block_weights[b]) : 1.0) * r.error;
    }
    if (missed > 0 && step / 2 >= finest_step && options.coef_bits < 1) continue;
    parts.coef_bits = magnitude_bits(largest_q);
    parts.sparsity_bits = format::bits_for_count(std::uint64_t{most_atoms} + 1);
    parts.dequantization[0] = mq.bias;
    parts.dequantization[1] = mq.scale;
    parts.dequantization[2] = cq.scale;
    result->squared_error += brick_error;
    result->weighted_error += weighted_error;
    result->codes += parts.atoms.size();
    result->blocks_over_bound += missed;
    return format::pack_ksvd_payload(parts);
  }
}

std::vector<std::byte> zfp_payload(format::BrickShape shape, const float* brick, double accuracy) {
  format::ZfpStream zfp(format::ZfpMode::accuracy(accuracy), shape.size, shape.size, shape.size);
  std::vector<std::byte> buffer(zfp.maximum_size());
  const std::size_t size = zfp.compress(brick, buffer.data(), buffer.size());
  if (size == 0) throw std::runtime_error("zfp_compress failed");
  buffer.resize((size + 3) / 4 * 4);
  // A zfp stream of 4 bytes would read as a constant brick; never happens for 12³ and up
  // (≥ 27 blocks).
  if (buffer.size() == 4) buffer.resize(8);
  return buffer;
}

}  // namespace volreel::encoder::detail
