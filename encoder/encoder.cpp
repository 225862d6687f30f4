// encoder.cpp: the brick hierarchy, sparse coding with quantization, zfp bricks, the node table,
// and the series-to-container loop with resume and rate control.
#include "volreel/encoder/encoder.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>
#include <string>

#include <Eigen/Cholesky>

#include "volreel/format/brick_decode.h"
#include "volreel/format/crc32c.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/zfp_stream.hpp"

namespace volreel::encoder {

namespace detail {
/// How a brick's codes are quantized.
struct QuantizeOptions {
  bool refit = true;  ///< sequential least-squares refit (see quantize_block)
  double target_energy =
      -1;  ///< m·ε²: extend the pursuit while the quantized error exceeds it (< 0: never)
  int max_atoms = 15;
  bool optimize_interval =
      true;  ///< choose the 6-bit interval by squared error (may clip extremes)
  /// The largest step of a brick's quantized block means: each brick takes the fewest bits
  /// (0..12) whose step over its means' range is at most this. 0: always 12 bits.
  double mean_step = 0;
  int mean_bits = -1;  ///< ≥ 0: every brick takes exactly this many mean bits (overrides mean_step)
};
}  // namespace detail
using detail::QuantizeOptions;

namespace fs = std::filesystem;
using format::brick_interior;
using format::brick_size;
using format::brick_voxels;

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

constexpr std::size_t chunk_bricks =
    32;  ///< bricks coded per batch-OMP call (memory: 32·36³ floats ×2)

std::size_t clamp_index(std::int64_t i, std::uint32_t n) {
  return static_cast<std::size_t>(std::clamp<std::int64_t>(i, 0, static_cast<std::int64_t>(n) - 1));
}

/// Linear quantizer over [lo, hi] with `levels`+1 steps: q = round((v − bias)/scale).
struct Quantizer {
  float bias = 0, scale = 0;
  std::uint32_t levels = 0;
  Quantizer(float lo, float hi, std::uint32_t n)
      : bias(lo), scale(hi > lo ? (hi - lo) / static_cast<float>(n) : 0.0f), levels(n) {}
  std::uint32_t quantize(double v) const {
    if (!(scale > 0)) return 0;
    const double q = std::round((v - static_cast<double>(bias)) / static_cast<double>(scale));
    return static_cast<std::uint32_t>(std::clamp(q, 0.0, static_cast<double>(levels)));
  }
  float value(std::uint32_t q) const { return bias + scale * static_cast<float>(q); }
};

std::vector<std::byte> constant_payload(float v) {
  std::vector<std::byte> p(4);
  std::memcpy(p.data(), &v, 4);
  return p;
}

/// One node of the full octree while encoding.
struct Cell {
  std::uint32_t level = 0, x = 0, y = 0, z = 0;
  std::uint64_t morton = 0;
  std::vector<std::byte> payload;
  std::size_t codes = 0;  ///< ksvd codes in the payload
  std::uint64_t histogram = 0;
  bool constant = false, subtree_constant = false;
  float value = 0;
};

/// Copies the 216 blocks of a 36³ brick into 216 columns of `columns` (m × 216, zero-mean) and
/// their means into `means`.
void brick_to_blocks(const float* brick, float* columns, float* means) {
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
    float* col = columns + std::size_t{b} * VR_BLOCK_LENGTH;
    double sum = 0;
    for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) {
      col[v] = brick[vr_brick_voxel(b, v)];
      sum += static_cast<double>(col[v]);
    }
    const auto mean = static_cast<float>(sum / VR_BLOCK_LENGTH);
    for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) col[v] -= mean;
    means[b] = mean;
  }
}

/// Share of each of the 216 blocks of brick (x, y, z) of a level of size `dims` that the decoder
/// reads: voxels of the brick's interior (stored index 1..34 on each axis) inside the level.
void owned_block_shares(std::uint32_t x, std::uint32_t y, std::uint32_t z,
                        const std::array<std::uint32_t, 3>& dims, float* shares) {
  const std::uint32_t position[3] = {x, y, z};
  float owned[3][VR_BLOCKS_PER_AXIS];  // owned voxels of block column c on axis a
  for (std::size_t a = 0; a < 3; ++a) {
    // Stored index i holds level voxel 34·p − 1 + i: owned for 1 ≤ i ≤ 34 and 34·p − 1 + i < dim.
    const std::int64_t end = std::min<std::int64_t>(
        brick_interior + 1, std::int64_t{dims[a]} - std::int64_t{brick_interior} * position[a] + 1);
    for (std::uint32_t c = 0; c < VR_BLOCKS_PER_AXIS; ++c) {
      const std::int64_t lo = std::max<std::int64_t>(1, c * VR_BLOCK_SIZE),
                         hi = std::min<std::int64_t>(end, (c + 1) * VR_BLOCK_SIZE);
      owned[a][c] = static_cast<float>(std::max<std::int64_t>(0, hi - lo)) / VR_BLOCK_SIZE;
    }
  }
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b)
    shares[b] = owned[0][b % VR_BLOCKS_PER_AXIS] * owned[1][(b / VR_BLOCKS_PER_AXIS) % VR_BLOCKS_PER_AXIS] *
                owned[2][b / (VR_BLOCKS_PER_AXIS * VR_BLOCKS_PER_AXIS)];
}

/// The shares as weights of the Lagrangian rule: at least 1/216 (one voxel), so that as ε → 0
/// every block is still coded up to Smax.
void owned_block_weights(std::uint32_t x, std::uint32_t y, std::uint32_t z,
                         const std::array<std::uint32_t, 3>& dims, float* weights) {
  owned_block_shares(x, y, z, dims, weights);
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) weights[b] = std::max(weights[b], 1.0f / VR_BLOCK_LENGTH);
}

/// Adds a stored brick's payload to the byte breakdown and sparsity histogram of a frame.
void add_to_breakdown(const Cell& c, const std::array<std::uint32_t, 3>& level_dims, bool coarse,
                      bool ksvd, FrameStats& st) {
  ByteBreakdown& b = st.breakdown;
  const std::size_t size = c.payload.size();
  float shares[VR_BLOCKS_PER_BRICK];  // of each block, the voxels that are the level's own
  owned_block_shares(c.x, c.y, c.z, level_dims, shares);
  if (c.constant) {
    b.constant_bricks += size;
  } else if (!ksvd) {
    b.zfp_streams += size;
  } else {
    vr_uint words[VR_MAX_PAYLOAD_WORDS] = {};
    std::memcpy(words, c.payload.data(), std::min(size, sizeof words));
    const vr_uint entry_bits = vr_entry_bits(vr_mean_bits(words));
    b.brick_headers += 4 * VR_HEADER_WORDS;
    b.block_entries += 2 * vr_entry_units(entry_bits);
    b.codes += 2 * c.codes;
    b.alignment += size - vr_payload_bytes(entry_bits, static_cast<vr_uint>(c.codes));
    ++st.mean_bits_histogram[vr_mean_bits(words)];
    for (std::uint32_t k = 0; k < VR_BLOCKS_PER_BRICK; ++k) {
      const vr_uint sparsity = vr_entry_sparsity(vr_block_entry(words, entry_bits, k));
      ++st.sparsity_histogram[sparsity];
      if (!coarse) b.finest_owned_codes += 2.0 * sparsity * static_cast<double>(shares[k]);
    }
  }
  if (coarse) b.coarse_levels += size;
  // The blocks' owned shares average to the brick's interior voxels inside the level: the rest of
  // the 36³ are apron or padding.
  double owned = 0;
  for (float share : shares) owned += static_cast<double>(share);
  b.aprons_and_padding += static_cast<double>(size) * (1 - owned / VR_BLOCKS_PER_BRICK);
}

}  // namespace

ByteBreakdown& ByteBreakdown::operator+=(const ByteBreakdown& o) {
  frame_tables += o.frame_tables;
  constant_bricks += o.constant_bricks;
  brick_headers += o.brick_headers;
  block_entries += o.block_entries;
  codes += o.codes;
  alignment += o.alignment;
  zfp_streams += o.zfp_streams;
  coarse_levels += o.coarse_levels;
  aprons_and_padding += o.aprons_and_padding;
  finest_owned_codes += o.finest_owned_codes;
  return *this;
}

Pyramid build_pyramid(const Volume& frame) {
  Pyramid p;
  p.geometry = format::level_geometry({static_cast<std::uint32_t>(frame.dims.x),
                                       static_cast<std::uint32_t>(frame.dims.y),
                                       static_cast<std::uint32_t>(frame.dims.z)});
  const std::size_t levels = p.geometry.size();
  p.levels.resize(levels);
  p.levels[levels - 1] = frame.data;
  for (std::size_t l = levels - 1; l > 0; --l) {
    const auto& fine_dims = p.geometry[l].dims;
    const auto& dims = p.geometry[l - 1].dims;
    const std::vector<float>& fine = p.levels[l];
    std::vector<float>& coarse = p.levels[l - 1];
    coarse.resize(std::size_t{dims[0]} * dims[1] * dims[2]);
    const auto nz = static_cast<std::ptrdiff_t>(dims[2]);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < nz; ++k)
      for (std::uint32_t j = 0; j < dims[1]; ++j)
        for (std::uint32_t i = 0; i < dims[0]; ++i) {
          double sum = 0;
          for (std::uint32_t c = 0; c < 8; ++c) {
            const std::size_t x = clamp_index(2 * std::int64_t{i} + (c & 1), fine_dims[0]);
            const std::size_t y = clamp_index(2 * std::int64_t{j} + ((c >> 1) & 1), fine_dims[1]);
            const std::size_t z = clamp_index(2 * k + (c >> 2), fine_dims[2]);
            sum += static_cast<double>(fine[(z * fine_dims[1] + y) * fine_dims[0] + x]);
          }
          coarse[(static_cast<std::size_t>(k) * dims[1] + j) * dims[0] + i] =
              static_cast<float>(sum / 8);
        }
  }
  return p;
}

void extract_brick(const Pyramid& pyramid, std::size_t level, std::uint32_t x, std::uint32_t y,
                   std::uint32_t z, std::span<float> out) {
  const auto& dims = pyramid.geometry[level].dims;
  const std::vector<float>& v = pyramid.levels[level];
  const std::int64_t x0 = std::int64_t{x} * brick_interior - 1,
                     y0 = std::int64_t{y} * brick_interior - 1,
                     z0 = std::int64_t{z} * brick_interior - 1;
  std::size_t xs[brick_size];
  for (std::uint32_t a = 0; a < brick_size; ++a) xs[a] = clamp_index(x0 + a, dims[0]);
  for (std::uint32_t c = 0; c < brick_size; ++c) {
    const std::size_t zz = clamp_index(z0 + c, dims[2]);
    for (std::uint32_t b = 0; b < brick_size; ++b) {
      const std::size_t yy = clamp_index(y0 + b, dims[1]);
      const float* row = v.data() + (zz * dims[1] + yy) * dims[0];
      float* dst = out.data() + (std::size_t{c} * brick_size + b) * brick_size;
      for (std::uint32_t a = 0; a < brick_size; ++a) dst[a] = row[xs[a]];
    }
  }
}

FrameEncoder::FrameEncoder(const dictionary::Dictionary* dictionary, CodingSettings settings)
    : dictionary_(dictionary), settings_(settings) {
  if (settings_.codec == format::Codec::ksvd) {
    if (!dictionary_) throw InputError("the ksvd codec needs a dictionary");
    if (dictionary_->block_size != 6 || dictionary_->block_length() != 216)
      throw InputError("the dictionary has blocks of " + std::to_string(dictionary_->block_size) +
                       "^3; volreel's bricks need 6^3");
    if (dictionary_->atom_count() < 1 || dictionary_->atom_count() > 1024)
      throw InputError("the dictionary has " + std::to_string(dictionary_->atom_count()) +
                       " atoms; the 10-bit atom index allows 1..1024");
    if (settings_.max_atoms < 1 || settings_.max_atoms > 15)
      throw InputError("Smax must be in 1..15 (4-bit sparsity field)");
    if (settings_.fixed_sparsity < 0 || settings_.fixed_sparsity > 15)
      throw InputError("--fixed-sparsity must be in 1..15");
    if (settings_.fixed_sparsity == 0 &&
        !(settings_.tolerance > 0 && std::isfinite(settings_.tolerance)))
      throw InputError("the tolerance must be positive and finite");
    if (settings_.mean_bits < -1 || settings_.mean_bits > static_cast<int>(VR_MEAN_BITS))
      throw InputError("--mean-bits must be auto or 0..12");
    if (!(settings_.mean_step_factor > 0 && std::isfinite(settings_.mean_step_factor)))
      throw InputError("the mean step factor must be positive and finite");
    if (settings_.fixed_sparsity == 0 && settings_.rule == VariableRateRule::lagrangian &&
        !(settings_.lagrangian_factor > 0 && std::isfinite(settings_.lagrangian_factor)))
      throw InputError("the Lagrangian factor must be positive and finite");
    if (!(settings_.level_tolerance_factor >= 1 && settings_.level_tolerance_factor <= 16))
      throw InputError("the level tolerance factor must be in [1, 16]");
    dictionary::SparseCodingOptions o;
    o.selection = settings_.selection;
    if (settings_.fixed_sparsity > 0) {
      o.tolerance = 0;
      o.max_atoms = settings_.fixed_sparsity;
    } else if (settings_.rule == VariableRateRule::lagrangian) {
      o.tolerance = 0;
      o.max_atoms = settings_.max_atoms;
      o.min_atom_gain = atom_gain_threshold();
    } else {
      o.tolerance = settings_.tolerance;
      o.max_atoms = settings_.max_atoms;
    }
    omp_ = std::make_shared<dictionary::BatchOmp>(dictionary_->atoms, o);
  } else if (!(settings_.zfp_accuracy > 0 && std::isfinite(settings_.zfp_accuracy))) {
    throw InputError("--zfp-accuracy must be positive");
  }
}

namespace {

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

/// Quantized coefficients of one block on support a[0..s) (in order). Without refit each OMP
/// coefficient is rounded; with refit step k solves the trailing (s−k)×(s−k) normal equations
/// G x = Dᵀy with the first k coefficients fixed at their quantized values, and rounds x_0, so
/// later coefficients absorb the rounding error of earlier ones. Returns the squared error of the
/// quantized block (mean error included) and fills q.
double quantize_block(const float* y, float mean_error, const std::int32_t* a, const float* c,
                      int s, const Eigen::MatrixXf& atoms, const Quantizer& cq, bool refit,
                      std::uint32_t* q) {
  if (!refit || s <= 1) {
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

/// The mean bits of a brick whose block means span [lo, hi]: `forced` when ≥ 0, else the fewest
/// bits b (0..12) whose quantization step (hi − lo)/(2^b − 1) is at most `step` (b = 0: the one
/// level is the midpoint, so a span up to `step` suffices), and 12 when step ≤ 0.
std::uint32_t choose_mean_bits(float lo, float hi, double step, int forced) {
  if (forced >= 0) return static_cast<std::uint32_t>(forced);
  if (!(step > 0)) return VR_MEAN_BITS;
  const double span = static_cast<double>(hi) - static_cast<double>(lo);
  for (std::uint32_t b = 0; b < VR_MEAN_BITS; ++b)
    if (span <= step * static_cast<double>(b == 0 ? 1u : (1u << b) - 1u)) return b;
  return VR_MEAN_BITS;
}

/// Quantizes one brick's sparse codes into its payload (brick_decode.h's layout).
/// Step 1: means to b bits over [min, max] of the brick's block means, b the fewest bits whose
/// step is at most options.mean_step (choose_mean_bits). Step 2: coefficients to 6 bits over
/// [min, max] of the brick's coefficients, block by block (quantize_block). Step 3
/// ("quantization inside the pursuit"): while a block's quantized error exceeds m·ε² and it has
/// fewer than Smax atoms, add the atom most correlated with the quantized residual and quantize
/// again; keep it only if the error falls.
std::vector<std::byte> quantize_brick(const float* columns, const float* means,
                                      const dictionary::SparseCodes& codes, std::size_t first_block,
                                      const Eigen::MatrixXf& atoms, const QuantizeOptions& options,
                                      double* squared_error, std::size_t* code_count) {
  float mean_lo = means[0], mean_hi = means[0];
  for (std::uint32_t b = 1; b < VR_BLOCKS_PER_BRICK; ++b) {
    mean_lo = std::min(mean_lo, means[b]);
    mean_hi = std::max(mean_hi, means[b]);
  }
  float coef_lo = std::numeric_limits<float>::infinity(), coef_hi = -coef_lo;
  std::size_t total = 0;
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
    const std::size_t i = first_block + b;
    for (int k = 0; k < codes.count[i]; ++k) {
      coef_lo = std::min(coef_lo, codes.coefficients_of(i)[k]);
      coef_hi = std::max(coef_hi, codes.coefficients_of(i)[k]);
    }
    total += codes.count[i];
  }
  if (total == 0) coef_lo = coef_hi = 0;
  // The 6-bit interval: [min, max] of the coefficients, or narrower when clipping a few extreme
  // coefficients costs less than the coarser step costs all the others (sum of squared rounding
  // and clipping errors over the brick's coefficients, tried for the k smallest and j largest
  // clipped, k, j ∈ {0, 1, 2, 4, 8}).
  if (options.optimize_interval && total > 16) {
    std::vector<float> all;
    all.reserve(total);
    for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
      const std::size_t i = first_block + b;
      all.insert(all.end(), codes.coefficients_of(i), codes.coefficients_of(i) + codes.count[i]);
    }
    std::sort(all.begin(), all.end());
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t k : {0u, 1u, 2u, 4u, 8u})
      for (std::size_t j : {0u, 1u, 2u, 4u, 8u}) {
        if (k + j + 2 > all.size()) continue;
        const Quantizer trial(all[k], all[all.size() - 1 - j], VR_COEF_LEVELS);
        double cost = 0;
        for (float c : all) {
          const double d = static_cast<double>(c) -
                           static_cast<double>(trial.value(trial.quantize(static_cast<double>(c))));
          cost += d * d;
        }
        if (cost < best) {
          best = cost;
          coef_lo = all[k];
          coef_hi = all[all.size() - 1 - j];
        }
      }
  }
  format::KsvdPayloadParts parts;
  parts.mean_bits = choose_mean_bits(mean_lo, mean_hi, options.mean_step, options.mean_bits);
  const float mean_mid = mean_lo + (mean_hi - mean_lo) / 2;
  const Quantizer mq = parts.mean_bits == 0
                           ? Quantizer(mean_mid, mean_mid, 0)
                           : Quantizer(mean_lo, mean_hi, (1u << parts.mean_bits) - 1u);
  const Quantizer cq(coef_lo, coef_hi, VR_COEF_LEVELS);
  std::vector<std::uint16_t>& code_words = parts.codes;
  code_words.reserve(total + 64);
  Eigen::VectorXf residual(VR_BLOCK_LENGTH), correlation;
  for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b) {
    const std::size_t i = first_block + b;
    int s = codes.count[i];
    std::int32_t a[15];
    float c[15];
    std::copy_n(codes.atoms_of(i), s, a);
    std::copy_n(codes.coefficients_of(i), s, c);
    const float* y = columns + std::size_t{b} * VR_BLOCK_LENGTH;
    const std::uint32_t qmean = mq.quantize(static_cast<double>(means[b]));
    const float mean_error = means[b] - mq.value(qmean);
    std::uint32_t q[15];
    double e = quantize_block(y, mean_error, a, c, s, atoms, cq, options.refit, q);
    while (options.target_energy >= 0 && e > options.target_energy && s < options.max_atoms &&
           cq.scale > 0) {
      // The quantized residual, its best new atom, and a fresh quantization with it.
      for (std::uint32_t v = 0; v < VR_BLOCK_LENGTH; ++v) {
        float r = y[v] + mean_error;
        for (int k = 0; k < s; ++k) r -= cq.value(q[k]) * atoms(static_cast<Eigen::Index>(v), a[k]);
        residual(static_cast<Eigen::Index>(v)) = r;
      }
      correlation.noalias() = atoms.transpose() * residual;
      for (int k = 0; k < s; ++k) correlation(a[k]) = 0;
      Eigen::Index best = 0;
      correlation.cwiseAbs().maxCoeff(&best);
      a[s] = static_cast<std::int32_t>(best);
      c[s] = correlation(best);
      std::uint32_t q2[15];
      const double e2 = quantize_block(y, mean_error, a, c, s + 1, atoms, cq, options.refit, q2);
      if (!(e2 < e)) break;
      ++s;
      e = e2;
      std::copy_n(q2, s, q);
    }
    parts.sparsity[b] = static_cast<std::uint32_t>(s);
    parts.mean[b] = qmean;
    for (int k = 0; k < s; ++k)
      code_words.push_back(
          static_cast<std::uint16_t>((static_cast<std::uint32_t>(a[k]) << 6) | q[k]));
    *squared_error += e;
  }
  *code_count += code_words.size();
  parts.dequantization[0] = mq.bias;
  parts.dequantization[1] = mq.scale;
  parts.dequantization[2] = cq.bias;
  parts.dequantization[3] = cq.scale;
  return format::pack_ksvd_payload(parts);
}

std::vector<std::byte> zfp_payload(const float* brick, double accuracy) {
  format::ZfpStream zfp(format::ZfpMode::accuracy(accuracy), brick_size, brick_size, brick_size);
  std::vector<std::byte> buffer(zfp.maximum_size());
  const std::size_t size = zfp.compress(brick, buffer.data(), buffer.size());
  if (size == 0) throw std::runtime_error("zfp_compress failed");
  buffer.resize((size + 3) / 4 * 4);
  // A zfp stream of 4 bytes would read as a constant brick; never happens for 36³ (≥ 729 blocks).
  if (buffer.size() == 4) buffer.resize(8);
  return buffer;
}

}  // namespace

double FrameEncoder::atom_gain_threshold() const {
  if (settings_.codec != format::Codec::ksvd || settings_.fixed_sparsity > 0 ||
      settings_.rule != VariableRateRule::lagrangian)
    return 0;
  return settings_.lagrangian_factor * static_cast<double>(VR_BLOCK_LENGTH) * settings_.tolerance *
         settings_.tolerance;
}

QuantizeOptions FrameEncoder::quantize_options() const {
  QuantizeOptions o;
  o.refit = settings_.refit_quantization;
  o.optimize_interval = settings_.optimize_interval;
  o.max_atoms = settings_.max_atoms;
  o.mean_bits = settings_.mean_bits;
  if (settings_.fixed_sparsity == 0) o.mean_step = settings_.mean_step_factor * settings_.tolerance;
  if (settings_.extend_pursuit && settings_.fixed_sparsity == 0 &&
      settings_.rule == VariableRateRule::tolerance)
    o.target_energy =
        static_cast<double>(VR_BLOCK_LENGTH) * settings_.tolerance * settings_.tolerance;
  return o;
}

std::vector<std::byte> FrameEncoder::encode_brick(std::span<const float> brick) const {
  if (brick.size() != brick_voxels) throw InputError("encode_brick needs 36^3 values");
  const auto [mn, mx] = std::minmax_element(brick.begin(), brick.end());
  if (*mn == *mx) return constant_payload(*mn);
  if (settings_.codec == format::Codec::zfp)
    return zfp_payload(brick.data(), settings_.zfp_accuracy);
  Eigen::MatrixXf columns(VR_BLOCK_LENGTH, VR_BLOCKS_PER_BRICK);
  std::vector<float> means(VR_BLOCKS_PER_BRICK);
  brick_to_blocks(brick.data(), columns.data(), means.data());
  dictionary::SparseCodes codes;
  omp_->encode(columns, codes);
  double error = 0;
  std::size_t code_count = 0;
  return quantize_brick(columns.data(), means.data(), codes, 0, dictionary_->atoms,
                        quantize_options(), &error, &code_count);
}

std::vector<std::byte> FrameEncoder::encode(std::size_t t, const Volume& frame,
                                            FrameStats* stats) const {
  const auto start = Clock::now();
  const Pyramid pyramid = build_pyramid(frame);
  FrameStats st;
  st.seconds_pyramid = seconds_since(start);
  const std::size_t levels = pyramid.geometry.size();
  const auto lo = static_cast<float>(settings_.value_min),
             hi = static_cast<float>(settings_.value_max);
  const bool ksvd = settings_.codec == format::Codec::ksvd;

  // 1. Every cell of every level, breadth-first, Morton order inside a level.
  std::vector<Cell> cells;
  std::vector<std::size_t> level_begin(levels + 1, 0);
  for (std::size_t l = 0; l < levels; ++l) {
    level_begin[l] = cells.size();
    const auto& g = pyramid.geometry[l].grid;
    for (std::uint32_t z = 0; z < g[2]; ++z)
      for (std::uint32_t y = 0; y < g[1]; ++y)
        for (std::uint32_t x = 0; x < g[0]; ++x) {
          Cell c;
          c.level = static_cast<std::uint32_t>(l);
          c.x = x, c.y = y, c.z = z;
          c.morton = format::morton3(x, y, z);
          cells.push_back(std::move(c));
        }
    std::sort(cells.begin() + static_cast<std::ptrdiff_t>(level_begin[l]), cells.end(),
              [](const Cell& a, const Cell& b) { return a.morton < b.morton; });
  }
  level_begin[levels] = cells.size();

  // 2. Bricks in chunks: extract, histogram, constant test; then code the non-constant ones.
  std::vector<float> bricks(chunk_bricks * brick_voxels);
  Eigen::MatrixXf columns;
  std::vector<float> means, weights;
  dictionary::SparseCodes codes;
  // Lagrangian rule: each block's atom gains are weighed by the share of its voxels the decoder
  // reads and by its level's 1/F^(2d) (coded to ε·F^d, d levels above the finest).
  const bool weighted = ksvd && atom_gain_threshold() > 0 &&
                        (settings_.weight_owned_voxels || settings_.level_tolerance_factor != 1);
  const auto level_scale = [&](std::uint32_t level) {  // F^d
    return atom_gain_threshold() > 0
               ? std::pow(settings_.level_tolerance_factor, static_cast<double>(levels - 1 - level))
               : 1.0;
  };
  for (std::size_t begin = 0; begin < cells.size(); begin += chunk_bricks) {
    const std::size_t n = std::min(chunk_bricks, cells.size() - begin);
    auto part = Clock::now();
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t j = 0; j < static_cast<std::ptrdiff_t>(n); ++j) {
      Cell& c = cells[begin + static_cast<std::size_t>(j)];
      float* brick = bricks.data() + static_cast<std::size_t>(j) * brick_voxels;
      extract_brick(pyramid, c.level, c.x, c.y, c.z, {brick, brick_voxels});
      float mn = brick[0], mx = brick[0];
      std::uint64_t hist = 0;
      for (std::uint32_t v = 0; v < brick_voxels; ++v) {
        mn = std::min(mn, brick[v]);
        mx = std::max(mx, brick[v]);
        hist |= std::uint64_t{1} << format::histogram_bin(brick[v], lo, hi);
      }
      c.histogram = hist;
      c.constant = mn == mx;
      c.value = mn;
      if (c.constant)
        c.payload = constant_payload(mn);
      else if (!ksvd)
        c.payload = zfp_payload(brick, settings_.zfp_accuracy);
    }
    if (!ksvd) {
      st.seconds_bricks += seconds_since(part);
      continue;
    }
    std::vector<std::size_t> coded;
    for (std::size_t j = 0; j < n; ++j)
      if (!cells[begin + j].constant) coded.push_back(j);
    if (coded.empty()) continue;
    const auto blocks = static_cast<Eigen::Index>(coded.size() * VR_BLOCKS_PER_BRICK);
    columns.resize(VR_BLOCK_LENGTH, blocks);
    means.resize(static_cast<std::size_t>(blocks));
    weights.resize(weighted ? static_cast<std::size_t>(blocks) : 0);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(coded.size()); ++k) {
      const auto kk = static_cast<std::size_t>(k);
      brick_to_blocks(bricks.data() + coded[kk] * brick_voxels,
                      columns.data() + kk * VR_BLOCKS_PER_BRICK * VR_BLOCK_LENGTH,
                      means.data() + kk * VR_BLOCKS_PER_BRICK);
      if (weighted) {
        const Cell& c = cells[begin + coded[kk]];
        float* w = weights.data() + kk * VR_BLOCKS_PER_BRICK;
        if (settings_.weight_owned_voxels)
          owned_block_weights(c.x, c.y, c.z, pyramid.geometry[c.level].dims, w);
        else
          std::fill(w, w + VR_BLOCKS_PER_BRICK, 1.0f);
        const double scale = level_scale(c.level);
        for (std::uint32_t b = 0; b < VR_BLOCKS_PER_BRICK; ++b)
          w[b] = static_cast<float>(static_cast<double>(w[b]) / (scale * scale));
      }
    }
    st.seconds_bricks += seconds_since(part);
    part = Clock::now();
    omp_->encode(columns, codes, weights);
    st.seconds_omp += seconds_since(part);
    part = Clock::now();
    double quantized_error = 0;
    std::size_t code_count = 0;
    const QuantizeOptions qo = quantize_options();
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : quantized_error, code_count)
    for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(coded.size()); ++k) {
      const auto kk = static_cast<std::size_t>(k);
      Cell& cell = cells[begin + coded[kk]];
      QuantizeOptions brick_qo = qo;  // the means' step follows the level's ε
      brick_qo.mean_step *= level_scale(cell.level);
      cell.payload =
          quantize_brick(columns.data() + kk * VR_BLOCKS_PER_BRICK * VR_BLOCK_LENGTH,
                         means.data() + kk * VR_BLOCKS_PER_BRICK, codes, kk * VR_BLOCKS_PER_BRICK,
                         dictionary_->atoms, brick_qo, &quantized_error, &cell.codes);
      code_count += cell.codes;
    }
    st.codes += code_count;
    st.quantized_squared_error += quantized_error;
    st.seconds_quantize += seconds_since(part);
    for (std::size_t i = 0; i < codes.size(); ++i)
      st.unquantized_squared_error += static_cast<double>(codes.residual_energy[i]);
    st.blocks += static_cast<std::size_t>(blocks);
  }

  // 3. Bottom-up: histograms OR'ed into parents; a subtree is constant when the node and all its
  //    children are constant subtrees of one value. Children of cell (x,y,z) are found by Morton
  //    code: 8·morton + d within the next level.
  std::vector<std::vector<std::size_t>> children(cells.size());
  for (std::size_t l = 0; l + 1 < levels; ++l) {
    std::size_t p = level_begin[l];
    for (std::size_t i = level_begin[l + 1]; i < level_begin[l + 2]; ++i) {
      while (cells[p].morton != cells[i].morton >> 3) ++p;  // both sorted by Morton code
      children[p].push_back(i);
    }
  }
  for (std::size_t i = cells.size(); i-- > 0;) {
    Cell& c = cells[i];
    c.subtree_constant = c.constant;
    for (std::size_t k : children[i]) {
      c.histogram |= cells[k].histogram;
      if (!cells[k].subtree_constant || cells[k].value != c.value) c.subtree_constant = false;
    }
  }

  // 4. Keep the nodes not under an empty node; number them breadth-first; link first children.
  format::FrameContents out;
  out.header.codec = static_cast<std::uint32_t>(settings_.codec);
  out.header.frame_index = static_cast<std::uint32_t>(t);
  out.header.dims[0] = static_cast<std::uint32_t>(frame.dims.x);
  out.header.dims[1] = static_cast<std::uint32_t>(frame.dims.y);
  out.header.dims[2] = static_cast<std::uint32_t>(frame.dims.z);
  out.header.block_size = ksvd ? 6 : 0;
  out.header.atom_count = ksvd ? static_cast<std::uint32_t>(dictionary_->atom_count()) : 0;
  out.header.value_min = lo;
  out.header.value_max = hi;
  out.header.codec_parameter =
      ksvd ? (settings_.fixed_sparsity > 0 ? 0.0 : settings_.tolerance) : settings_.zfp_accuracy;
  out.header.fixed_sparsity = static_cast<std::uint32_t>(settings_.fixed_sparsity);
  std::vector<char> kept(cells.size(), 0);
  if (kept.empty()) throw std::logic_error("a frame has at least one brick");
  kept.front() = 1;
  std::vector<std::uint32_t> index(cells.size(), 0);
  for (std::size_t l = 0; l < levels; ++l) {
    format::LevelEntry e{};
    e.first_node = static_cast<std::uint32_t>(out.nodes.size());
    for (std::size_t i = level_begin[l]; i < level_begin[l + 1]; ++i) {
      if (!kept[i]) continue;
      index[i] = static_cast<std::uint32_t>(out.nodes.size());
      format::Node node{};
      node.brick = index[i];
      node.histogram = cells[i].histogram;
      out.nodes.push_back(node);
      add_to_breakdown(cells[i], pyramid.geometry[l].dims, l + 1 < levels, ksvd, st);
      out.payloads.push_back(std::move(cells[i].payload));
      ++st.bricks;
      if (cells[i].constant) ++st.constant_bricks;
    }
    e.node_count = static_cast<std::uint32_t>(out.nodes.size()) - e.first_node;
    out.levels.push_back(e);
    // Children of kept inner nodes are kept; their first child is the next index in the level
    // below.
    std::uint32_t next = static_cast<std::uint32_t>(out.nodes.size());
    for (std::size_t i = level_begin[l]; i < level_begin[l + 1]; ++i) {
      if (!kept[i]) continue;
      format::NodeType type;
      if (cells[i].subtree_constant)
        type = format::NodeType::empty, ++st.empty_nodes;
      else if (l + 1 == levels)
        type = format::NodeType::leaf;
      else
        type = format::NodeType::inner;
      std::uint32_t first = 0;
      if (type == format::NodeType::inner) {
        first = next;
        for (std::size_t k : children[i]) kept[k] = 1;
        next += static_cast<std::uint32_t>(children[i].size());
      }
      out.nodes[index[i]].child_and_type = first | (static_cast<std::uint32_t>(type) << 30);
    }
  }
  std::vector<std::byte> bytes = format::serialize_frame(out);
  st.bytes = bytes.size();
  st.breakdown.frame_tables = st.bytes - st.breakdown.total();  // what is not a brick payload
  st.seconds = seconds_since(start);
  if (stats) *stats = st;
  return bytes;
}

std::pair<double, double> value_range(const datasets::SeriesReader& series, std::size_t frames,
                                      const Progress& progress) {
  const std::size_t n = frames ? std::min(frames, series.info().frames) : series.info().frames;
  std::vector<float> frame(series.info().dims.voxels());
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (std::size_t t = 0; t < n; ++t) {
    series.read_frame(t, frame);
    const auto [mn, mx] = std::minmax_element(frame.begin(), frame.end());
    lo = std::min(lo, static_cast<double>(*mn));
    hi = std::max(hi, static_cast<double>(*mx));
    progress.report(static_cast<double>(t + 1), static_cast<double>(n), "value range");
  }
  return {lo, hi};
}

namespace {

std::vector<std::byte> read_file_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw format::FormatError(path, "cannot open");
  std::vector<char> chars((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::vector<std::byte> bytes(chars.size());
  if (!chars.empty()) std::memcpy(bytes.data(), chars.data(), chars.size());
  return bytes;
}

/// Manifest bytes are counted in bps; before it exists, estimate them.
double manifest_estimate(std::size_t frames) {
  return 900.0 + 70.0 * static_cast<double>(frames);
}

/// The coding choices recorded in a manifest's provenance, with the values containers written
/// before a field existed used: the pursuit, the mean bits, and the variable-rate rule ("tolerance"
/// when absent) with its parameters.
nlohmann::json coding_choices_of(const format::Manifest& m) {
  nlohmann::json r = nlohmann::json::object();
  if (m.codec != format::Codec::ksvd) return r;
  // Containers written before the field existed all used OMP.
  r["pursuit"] = m.encoder.is_object() && m.encoder.contains("pursuit")
                    ? m.encoder["pursuit"]
                    : nlohmann::json(dictionary::pursuit_name(dictionary::AtomSelection::correlation));
  for (const char* key : {"mean_bits", "mean_step_factor"})
    if (m.encoder.is_object() && m.encoder.contains(key)) r[key] = m.encoder[key];
  if (m.fixed_sparsity != 0) return r;
  const bool has = m.encoder.is_object() && m.encoder.contains("rate_rule");
  r["rate_rule"] = has ? m.encoder["rate_rule"] : nlohmann::json("tolerance");
  for (const char* key : {"lagrangian_factor", "weight_owned_voxels"})
    if (m.encoder.is_object() && m.encoder.contains(key)) r[key] = m.encoder[key];
  // Containers written before the field existed coded every level to ε.
  if (r["rate_rule"] == "lagrangian")
    r["level_tolerance_factor"] = m.encoder.is_object() && m.encoder.contains("level_tolerance_factor")
                                      ? m.encoder["level_tolerance_factor"]
                                      : nlohmann::json(1.0);
  return r;
}

/// The settings that differ between an existing container's manifest and this run's, as
/// "name old (this run: new)" joined by "; " (empty: the same, so --resume may continue it).
std::string settings_difference(const format::Manifest& old, const format::Manifest& now) {
  std::vector<std::string> out;
  const auto differ = [&](const std::string& name, const nlohmann::json& a, const nlohmann::json& b) {
    if (a != b) out.push_back(name + " " + a.dump() + " (this run: " + b.dump() + ")");
  };
  const auto text = [](const auto& v) { return nlohmann::json(v); };
  const auto codec = [](format::Codec c) { return nlohmann::json(c == format::Codec::ksvd ? "ksvd" : "zfp"); };
  differ("dims", text(old.dims), text(now.dims));
  differ("codec", codec(old.codec), codec(now.codec));
  differ("tolerance", text(old.tolerance), text(now.tolerance));
  differ("fixed sparsity", text(old.fixed_sparsity), text(now.fixed_sparsity));
  differ("zfp accuracy", text(old.zfp_accuracy), text(now.zfp_accuracy));
  differ("value range", text(std::vector<double>{old.value_min, old.value_max}),
         text(std::vector<double>{now.value_min, now.value_max}));
  differ("frames", text(old.frames.size()), text(now.frames.size()));
  const auto dictionary = [](const format::Manifest& m) {
    return m.dictionary ? nlohmann::json{{"crc32c", m.dictionary->crc32c}, {"bytes", m.dictionary->bytes}}
                        : nlohmann::json(nullptr);
  };
  differ("dictionary", dictionary(old), dictionary(now));
  // The coding choices recorded in the provenance (pursuit, mean bits, rate rule and its parameters).
  const nlohmann::json a = coding_choices_of(old), b = coding_choices_of(now);
  std::set<std::string> keys;
  for (const auto& [key, value] : a.items()) keys.insert(key);
  for (const auto& [key, value] : b.items()) keys.insert(key);
  for (const auto& key : keys)
    differ(key, a.contains(key) ? a[key] : nlohmann::json(nullptr), b.contains(key) ? b[key] : nlohmann::json(nullptr));
  std::string joined;
  for (const auto& d : out) joined += (joined.empty() ? "" : "; ") + d;
  return joined;
}

}  // namespace

EncodeSummary encode_series(const datasets::SeriesReader& series, const fs::path& out,
                            const EncodeJob& job, const Progress& progress) {
  const auto& info = series.info();
  const std::size_t frames = job.max_frames ? std::min(job.max_frames, info.frames) : info.frames;
  if (frames == 0) throw InputError("the series has no frames");
  CodingSettings coding = job.coding;
  if (coding.value_min == 0 && coding.value_max == 0)
    std::tie(coding.value_min, coding.value_max) = value_range(series, frames);

  format::Manifest m;
  m.program_version = VOLREEL_VERSION;
  m.dims = {static_cast<std::uint32_t>(info.dims.x), static_cast<std::uint32_t>(info.dims.y),
            static_cast<std::uint32_t>(info.dims.z)};
  m.spacing = info.spacing;
  m.variable = info.variable;
  m.source = info.source;
  m.timestamps.assign(info.timestamps.begin(),
                      info.timestamps.begin() +
                          static_cast<std::ptrdiff_t>(std::min(frames, info.timestamps.size())));
  while (m.timestamps.size() < frames)
    m.timestamps.push_back(static_cast<double>(m.timestamps.size()));
  m.levels = static_cast<std::uint32_t>(format::level_geometry(m.dims).size());
  m.codec = coding.codec;
  m.block_size = coding.codec == format::Codec::ksvd ? 6 : 0;
  m.tolerance =
      coding.codec == format::Codec::ksvd && coding.fixed_sparsity == 0 ? coding.tolerance : 0;
  m.fixed_sparsity = static_cast<std::uint32_t>(coding.fixed_sparsity);
  m.zfp_accuracy = coding.codec == format::Codec::zfp ? coding.zfp_accuracy : 0;
  m.value_min = coding.value_min;
  m.value_max = coding.value_max;
  m.frames.assign(frames, std::nullopt);
  m.encoder = job.provenance;
  if (!m.encoder.is_object()) m.encoder = nlohmann::json::object();
  if (coding.codec == format::Codec::ksvd) {
    // How each block chose its atoms and each brick its mean bits: a resumed encode must choose
    // them the same way.
    m.encoder["pursuit"] = dictionary::pursuit_name(coding.selection);
    m.encoder["mean_bits"] =
        coding.mean_bits >= 0 ? nlohmann::json(coding.mean_bits) : nlohmann::json("auto");
    if (coding.mean_bits < 0 && coding.fixed_sparsity == 0)
      m.encoder["mean_step_factor"] = coding.mean_step_factor;
  }
  if (coding.codec == format::Codec::ksvd && coding.fixed_sparsity == 0) {
    // How variable rate spent its atoms: a resumed encode must spend them the same way.
    const bool lagrangian = coding.rule == VariableRateRule::lagrangian;
    m.encoder["rate_rule"] = lagrangian ? "lagrangian" : "tolerance";
    if (lagrangian) {
      m.encoder["lagrangian_factor"] = coding.lagrangian_factor;
      m.encoder["weight_owned_voxels"] = coding.weight_owned_voxels;
      m.encoder["level_tolerance_factor"] = coding.level_tolerance_factor;
    }
  }

  std::optional<dictionary::Dictionary> dict;
  std::vector<std::byte> dict_bytes;
  if (coding.codec == format::Codec::ksvd) {
    if (job.dictionary_file.empty()) throw InputError("the ksvd codec needs a dictionary file");
    dict_bytes = read_file_bytes(job.dictionary_file);
    auto file = format::parse_dictionary_file(dict_bytes, job.dictionary_file);  // validates it
    if (job.half_atoms && !file.half_atoms) {
      file = format::with_half_atoms(std::move(file));
      dict_bytes = format::serialize_dictionary_file(file);
    }
    dict = dictionary::from_file(file);
    m.dictionary = format::ManifestDictionary{"dictionary.bin", dict_bytes.size(),
                                              format::manifest_crc(dict_bytes),
                                              static_cast<std::uint32_t>(dict->atom_count())};
  }
  const FrameEncoder encoder(dict ? &*dict : nullptr, coding);

  // 1. An existing container: resume (same settings) or refuse unless told to overwrite.
  const fs::path manifest_path = out / "manifest.json";
  bool resuming = false;
  if (fs::exists(manifest_path)) {
    if (job.resume) {
      const format::Container old(out, true);
      if (const std::string d = settings_difference(old.manifest(), m); !d.empty())
        throw InputError("'" + out.string() + "' was encoded with other settings: " + d +
                         "; cannot --resume it: give the same options (pursuit: --pursuit, "
                         "level_tolerance_factor: --level-factor, mean_bits: --mean-bits, "
                         "rate_rule: --rate-rule) or --overwrite to start again");
      m.frames = old.manifest().frames;
      resuming = true;
    } else if (!job.overwrite) {
      throw InputError(
          "'" + out.string() +
          "' already holds a container: give --resume to continue it or --overwrite to replace it");
    }
  }
  if (!resuming && fs::exists(out)) {
    std::error_code ec;
    fs::remove_all(out / "frames", ec);
    fs::remove(manifest_path, ec);
    fs::remove(out / "dictionary.bin", ec);
  }
  fs::create_directories(out / "frames");
  // Leftover temporaries of an interrupted run.
  for (const auto& entry : fs::directory_iterator(out / "frames"))
    if (entry.path().filename().string().find(".tmp-") != std::string::npos)
      fs::remove(entry.path());
  if (m.dictionary) {
    bool present = false;
    if (resuming && fs::exists(out / "dictionary.bin")) {
      const auto existing = read_file_bytes(out / "dictionary.bin");
      present = existing == dict_bytes;
    }
    if (!present) format::write_container_file(out, "dictionary.bin", dict_bytes);
  }

  // 2. Which frames are already there and valid: the manifest's CRC, or (written but not yet in
  //    the manifest) a full structural and CRC check.
  EncodeSummary summary;
  summary.frames = frames;
  std::vector<char> done(frames, 0);
  if (resuming) {
    for (std::size_t t = 0; t < frames; ++t) {
      const fs::path path = out / format::frame_file_name(t);
      if (!fs::exists(path)) {
        m.frames[t].reset();
        continue;
      }
      try {
        const format::FrameFile f(path);
        f.view().check_payload_crc();
        const std::uint32_t crc = format::manifest_crc(f.view().bytes());
        const auto& h = f.view().header();
        const bool matches =
            h.frame_index == t && h.codec == static_cast<std::uint32_t>(coding.codec) &&
            (!m.frames[t] ||
             (m.frames[t]->crc32c == crc && m.frames[t]->bytes == f.view().bytes().size()));
        if (matches) {
          m.frames[t] =
              format::ManifestFrame{format::frame_file_name(t), f.view().bytes().size(), crc};
          done[t] = 1;
          ++summary.skipped;
        } else {
          m.frames[t].reset();
        }
      } catch (const format::FormatError&) {
        m.frames[t].reset();
      }
    }
  }
  m.complete = false;
  format::write_manifest(out, m);

  // 3. Encode the rest, one frame in memory at a time.
  Volume frame(info.dims);
  const double voxels = static_cast<double>(info.dims.voxels());
  for (std::size_t t = 0; t < frames; ++t) {
    if (done[t]) continue;
    series.read_frame(t, frame.data);
    FrameStats st;
    const auto start = Clock::now();
    const std::vector<std::byte> bytes = encoder.encode(t, frame, &st);
    summary.seconds += seconds_since(start);
    format::write_container_file(out, format::frame_file_name(t), bytes);
    m.frames[t] = format::ManifestFrame{format::frame_file_name(t), bytes.size(),
                                        format::manifest_crc(bytes)};
    format::write_manifest(out, m);
    ++summary.encoded;
    summary.unquantized_squared_error += st.unquantized_squared_error;
    summary.quantized_squared_error += st.quantized_squared_error;
    summary.seconds_pyramid += st.seconds_pyramid;
    summary.seconds_bricks += st.seconds_bricks;
    summary.seconds_omp += st.seconds_omp;
    summary.seconds_quantize += st.seconds_quantize;
    summary.breakdown += st.breakdown;
    for (std::size_t k = 0; k < st.sparsity_histogram.size(); ++k)
      summary.sparsity_histogram[k] += st.sparsity_histogram[k];
    for (std::size_t k = 0; k < st.mean_bits_histogram.size(); ++k)
      summary.mean_bits_histogram[k] += st.mean_bits_histogram[k];
    char status[64];
    std::snprintf(status, sizeof status, "%.1f MVoxel/s",
                  voxels * static_cast<double>(summary.encoded) / 1e6 / summary.seconds);
    progress.report(static_cast<double>(summary.skipped + summary.encoded),
                    static_cast<double>(frames), status);
  }
  m.complete = true;
  format::write_manifest(out, m);
  const format::Container written(out);
  summary.container_bytes = written.total_bytes();
  summary.bps =
      8.0 * static_cast<double>(summary.container_bytes) / (voxels * static_cast<double>(frames));
  summary.mvoxels_per_s =
      summary.seconds > 0 ? voxels * static_cast<double>(summary.encoded) / 1e6 / summary.seconds
                          : 0;
  return summary;
}

RateSearch search_tolerance(const datasets::SeriesReader& series,
                            const dictionary::Dictionary& dictionary,
                            std::uint64_t dictionary_bytes, CodingSettings settings,
                            double target_bps, std::size_t frames, std::size_t sample_frames,
                            double relative, const Progress& progress) {
  const auto& info = series.info();
  if (frames == 0) frames = info.frames;
  const double voxels = static_cast<double>(info.dims.voxels()) * static_cast<double>(frames);
  const double fixed_bytes = static_cast<double>(dictionary_bytes) + manifest_estimate(frames);
  const double floor_bps = 8 * fixed_bytes / voxels;
  if (!(target_bps > floor_bps))
    throw InputError("--bps " + std::to_string(target_bps) +
                     " is below what the dictionary and manifest alone take (" +
                     std::to_string(floor_bps) +
                     " bps): use a smaller dictionary (volreel train --atoms) or more frames");
  // 1. Sample frames, evenly spaced, in memory.
  std::vector<Volume> samples;
  const std::size_t n = std::min(sample_frames, frames);
  for (std::size_t i = 0; i < n; ++i)
    samples.push_back(series.read_frame(n == 1 ? frames / 2 : i * (frames - 1) / (n - 1)));
  const double range = settings.value_max - settings.value_min;
  settings.fixed_sparsity = 0;
  const auto estimate = [&](double eps) {
    settings.tolerance = eps;
    const FrameEncoder encoder(&dictionary, settings);
    double bytes = 0;
    for (std::size_t i = 0; i < samples.size(); ++i)
      bytes += static_cast<double>(encoder.encode(i, samples[i]).size());
    return 8 *
           (bytes / static_cast<double>(samples.size()) * static_cast<double>(frames) +
            fixed_bytes) /
           voxels;
  };
  // 2. Bracket in log ε (bps falls as ε grows), then bisect geometrically.
  RateSearch r;
  double lo = range * 1e-4, hi = range * 1e-2;
  double bps_lo = estimate(lo), bps_hi = estimate(hi);
  r.iterations = 2;
  while (bps_lo < target_bps && lo > range * 1e-9) lo /= 4, bps_lo = estimate(lo), ++r.iterations;
  while (bps_hi > target_bps && hi < range) hi *= 4, bps_hi = estimate(hi), ++r.iterations;
  r.tolerance = std::abs(bps_lo - target_bps) < std::abs(bps_hi - target_bps) ? lo : hi;
  r.estimated_bps = r.tolerance == lo ? bps_lo : bps_hi;
  for (int i = 0; i < 30 && std::abs(r.estimated_bps - target_bps) > relative * target_bps; ++i) {
    const double mid = std::sqrt(lo * hi);
    const double bps = estimate(mid);
    ++r.iterations;
    r.tolerance = mid;
    r.estimated_bps = bps;
    (bps > target_bps ? lo : hi) = mid;
    progress.report(i + 1, 30,
                    "eps " + std::to_string(mid) + " -> " + std::to_string(bps) + " bps");
  }
  return r;
}

}  // namespace volreel::encoder
