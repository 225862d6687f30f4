// batch_omp.cpp: batch-OMP with progressive Cholesky updates (Rubinstein, Zibulevsky, Elad 2008,
// algorithm 5) with an optional rate-distortion (Lagrangian) stop, and the plain reference OMP.
#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/QR>

#include "volreel/dictionary/omp.hpp"
#include "volreel/format/error.hpp"

namespace volreel::dictionary {

double tolerance_for_psnr(double psnr_db, double value_range) {
  return value_range * std::pow(10.0, -psnr_db / 20.0);
}

double psnr_for_tolerance(double tolerance, double value_range) {
  return 20.0 * std::log10(value_range / tolerance);
}

const char* pursuit_name(AtomSelection selection) {
  return selection == AtomSelection::error ? "ormp" : "omp";
}

AtomSelection pursuit_from_name(const std::string& name) {
  if (name == "ormp") return AtomSelection::error;
  if (name == "omp") return AtomSelection::correlation;
  throw std::invalid_argument("a pursuit is ormp or omp, not '" + name + "'");
}

void SparseCodes::resize(std::size_t blocks, int slots) {
  max_atoms = slots;
  const std::size_t total = blocks * static_cast<std::size_t>(slots);
  count.assign(blocks, 0);
  atom.assign(total, 0);
  coefficient.assign(total, 0.0f);
  residual_energy.assign(blocks, 0.0f);
}

namespace {

void check_options(const SparseCodingOptions& options, Eigen::Index block_length) {
  if (!(options.tolerance >= 0) || !std::isfinite(options.tolerance))
    throw std::invalid_argument("sparse coding tolerance must be a finite value >= 0, not " +
                                format::number_text(options.tolerance));
  if (!(options.min_atom_gain >= 0) || !std::isfinite(options.min_atom_gain))
    throw std::invalid_argument("the minimum atom gain must be a finite value >= 0, not " +
                                format::number_text(options.min_atom_gain));
  if (!(options.max_error >= 0) || !std::isfinite(options.max_error))
    throw std::invalid_argument("the maximum block error must be a finite value >= 0, not " +
                                format::number_text(options.max_error));
  if (options.max_atoms < 1 || options.max_atoms > 255 || options.max_atoms > block_length)
    throw std::invalid_argument("maximum atoms per block must be in 1.." +
                                std::to_string(std::min<Eigen::Index>(255, block_length)) +
                                ", not " + std::to_string(options.max_atoms));
}

/// m·max_error², or +∞ without a bound (max_error = 0).
double bound_energy(const SparseCodingOptions& options, Eigen::Index block_length) {
  return options.max_error > 0
             ? static_cast<double>(block_length) * options.max_error * options.max_error
             : std::numeric_limits<double>::infinity();
}

/// Correlations are updated and searched in chunks of this many values, held in registers.
constexpr Eigen::Index chunk = 64;
using Chunk = Eigen::Matrix<float, chunk, 1>;

typedef float Lanes [[gnu::vector_size(32)]];  // 8 floats: one AVX2 register or two SSE ones
constexpr std::size_t lanes = 8;
/// ORMP's Gram–Schmidt rows are summed this many atoms at a time: 8 vectors, as many independent
/// sums as it takes to keep two vector units busy through their latency.
constexpr Eigen::Index row_chunk = 8 * static_cast<Eigen::Index>(lanes);
/// K rounded up to whole vectors: the length of ORMP's padded arrays.
Eigen::Index padded_atoms(Eigen::Index K) {
  const auto n = static_cast<Eigen::Index>(lanes);
  return (K + n - 1) / n * n;
}

/// Scratch space of one thread, sized once.
struct OmpWorkspace {
  Eigen::VectorXf alpha;  // K: Dᵀr, the residual's correlations
  Eigen::MatrixXf lower;  // S × S: Cholesky factor L of G_II (lower triangle)
  Eigen::VectorXf w, z, gamma, alpha0_support;
  std::vector<int> support;
  std::vector<const float*> columns;  // G's columns of the support
  std::vector<float> chunk_max;       // largest |α| per chunk of α
  /// Orthonormal atoms only: the candidates, best first, as keys (orthonormal_order_key).
  std::vector<std::uint64_t> order;
  // ORMP only:
  // (alpha, projected and gram_row padded with zeros to whole vectors, padded_atoms)
  Eigen::VectorXf projected;  // K: ‖P⊥d_k‖², the atoms' squared norms orthogonal to the support
  Eigen::VectorXf gram_row;  // K: G_{k,:} of the atom being added
  std::vector<float> rows;  // S × K: row j = (L⁻¹ G_{I,:})_j, the support's Gram–Schmidt rows,
                            // by chunks of atoms (row_index), padded

  OmpWorkspace(Eigen::Index atoms, int slots, bool ormp)
      : alpha(Eigen::VectorXf::Zero(ormp ? padded_atoms(atoms) : atoms)),
        lower(slots, slots),
        w(slots),
        z(slots),
        gamma(slots),
        alpha0_support(slots),
        support(static_cast<std::size_t>(slots)),
        columns(static_cast<std::size_t>(slots)),
        chunk_max(static_cast<std::size_t>(atoms / chunk + 1)),
        projected(Eigen::VectorXf::Zero(ormp ? padded_atoms(atoms) : 0)),
        gram_row(Eigen::VectorXf::Zero(ormp ? padded_atoms(atoms) : 0)),
        rows(ormp ? static_cast<std::size_t>(padded_atoms(atoms)) * static_cast<std::size_t>(slots)
                  : 0) {}
};

/// The hot loop of batch-OMP (Σ_s s·K multiply-adds per block), fused with the search for the next
/// atom: α = α⁰ − Σ_j γ_j·G_{:,I_j} (s = 0: α = α⁰), then α_I = 0, and returns argmax_k |α_k|
/// (the first on ties). Each chunk of α is accumulated over all support columns before it is
/// stored, and its largest |α| is kept, so that the search scans a single chunk.
Eigen::Index update_correlations(float* alpha, const float* alpha0, const float* const* columns,
                                 const float* gamma, const int* support, int s, Eigen::Index K,
                                 float* chunk_max) {
  const Eigen::Index full = K / chunk;
  for (Eigen::Index c = 0; c < full; ++c) {
    const Eigen::Index at = c * chunk;
    Chunk acc = Eigen::Map<const Chunk>(alpha0 + at);
    for (int j = 0; j < s; ++j)
      acc.noalias() -= gamma[j] * Eigen::Map<const Chunk>(columns[j] + at);
    Eigen::Map<Chunk>(alpha + at) = acc;
    chunk_max[c] = acc.cwiseAbs().maxCoeff();
  }
  const Eigen::Index chunks = full + (K > full * chunk ? 1 : 0);
  if (chunks > full) {  // the tail, shorter than a chunk
    float m = 0;
    for (Eigen::Index i = full * chunk; i < K; ++i) {
      float a = alpha0[i];
      for (int j = 0; j < s; ++j) a -= gamma[j] * columns[j][i];
      alpha[i] = a;
      m = std::max(m, std::abs(a));
    }
    chunk_max[full] = m;
  }
  // Chosen atoms are orthogonal to the residual: zero their α (rounding leaves it tiny, not 0)
  // and refresh the maxima of their chunks.
  for (int j = 0; j < s; ++j) alpha[support[j]] = 0;
  for (int j = 0; j < s; ++j) {
    const Eigen::Index c = support[j] / chunk;
    const Eigen::Index n = std::min(chunk, K - c * chunk);
    chunk_max[c] = Eigen::Map<const Eigen::VectorXf>(alpha + c * chunk, n).cwiseAbs().maxCoeff();
  }
  Eigen::Index best_chunk = 0;
  for (Eigen::Index c = 1; c < chunks; ++c)
    if (chunk_max[c] > chunk_max[best_chunk]) best_chunk = c;
  const float best = chunk_max[best_chunk];
  const Eigen::Index end = std::min(K, (best_chunk + 1) * chunk);
  for (Eigen::Index i = best_chunk * chunk; i < end; ++i)
    if (std::abs(alpha[i]) == best) return i;
  return best_chunk * chunk;
}

/// The stopping rules of a pursuit in energies (see SparseCodingOptions).
struct StopRule {
  double target = 0;    ///< m·ε²: stop once ‖r‖² ≤ target
  int max_atoms = 1;    ///< Smax
  double min_gain = 0;  ///< stop before an atom that lowers ‖r‖² by less (0: off)
  double bound = 0;     ///< ... unless ‖r‖² > bound (m·max_error², +∞ without a bound)
};

/// Error-constrained OMP-Cholesky for one block, from α⁰ = Dᵀy and ‖y‖² (RZE08, algorithm 5),
/// with the rate-distortion stop. Writes the support, coefficients and ‖r‖²; returns the number
/// of atoms.
int code_one_block(const float* alpha0, double energy, const Eigen::MatrixXf& gram,
                   const StopRule& rule, OmpWorkspace& ws, std::int32_t* atoms_out,
                   float* coefficients_out, float* residual_out) {
  const int max_atoms = rule.max_atoms;
  const double target = rule.target;
  const Eigen::Index K = gram.rows();
  float* alpha = ws.alpha.data();
  auto& L = ws.lower;
  double residual = energy;
  int s = 0;
  // 1. The atom most correlated with the residual, k = argmax |α|, starting from α = α⁰.
  Eigen::Index k = 0;
  if (residual > target)
    k = update_correlations(alpha, alpha0, ws.columns.data(), ws.gamma.data(), ws.support.data(), 0,
                            K, ws.chunk_max.data());
  while (residual > target && s < max_atoms) {
    if (!(std::abs(alpha[k]) > 0)) break;  // the residual is orthogonal to every atom

    // 2. Progressive Cholesky: L ← [L 0; wᵀ sqrt(G_kk − wᵀw)] with L w = G_{I,k}.
    const float* g_k = gram.col(k).data();
    float pivot = g_k[k];
    if (s > 0) {
      float ww = 0;
      for (int r = 0; r < s; ++r) {
        float v = g_k[ws.support[static_cast<std::size_t>(r)]];
        for (int c = 0; c < r; ++c) v -= L(r, c) * ws.w[c];
        ws.w[r] = v / L(r, r);
        ww += ws.w[r] * ws.w[r];
      }
      pivot = g_k[k] - ww;
      if (!(pivot > 1e-5f)) break;  // atom k is (numerically) in the span of the support
    }
    // 2b. Rate-distortion stop: atom k would lower ‖r‖² by (d_kᵀr)² / ‖P⊥d_k‖² = α_k² / pivot.
    if (rule.min_gain > 0 && residual <= rule.bound) {
      const double gain = static_cast<double>(alpha[k]) * static_cast<double>(alpha[k]) /
                          static_cast<double>(pivot);
      if (gain < rule.min_gain) break;
    }
    for (int c = 0; c < s; ++c) L(s, c) = ws.w[c];
    L(s, s) = std::sqrt(pivot);
    ws.support[static_cast<std::size_t>(s)] = static_cast<int>(k);
    ws.alpha0_support[s] = alpha0[k];
    ++s;

    // 3. γ_I = (L Lᵀ)⁻¹ α⁰_I by forward and back substitution.
    for (int r = 0; r < s; ++r) {
      float v = ws.alpha0_support[r];
      for (int c = 0; c < r; ++c) v -= L(r, c) * ws.z[c];
      ws.z[r] = v / L(r, r);
    }
    for (int r = s - 1; r >= 0; --r) {
      float v = ws.z[r];
      for (int c = r + 1; c < s; ++c) v -= L(c, r) * ws.gamma[c];
      ws.gamma[r] = v / L(r, r);
    }

    // 4. α = α⁰ − G_I γ_I (β = G_I γ_I), and ‖r‖² = ‖y‖² − γ_Iᵀ α⁰_I (RZE08's ε_n − δ_n + δ_{n−1}
    //    telescoped: δ_n = γ_Iᵀ β_I = γ_Iᵀ α⁰_I because G_II γ_I = α⁰_I).
    //    α is only needed (with step 1 for the next round, k = argmax |α|) if there is one.
    double delta = 0;
    for (int j = 0; j < s; ++j)
      delta += static_cast<double>(ws.gamma[j]) * static_cast<double>(ws.alpha0_support[j]);
    residual = std::max(energy - delta, 0.0);
    ws.columns[static_cast<std::size_t>(s - 1)] = g_k;
    if (residual > target && s < max_atoms)
      k = update_correlations(alpha, alpha0, ws.columns.data(), ws.gamma.data(), ws.support.data(),
                              s, K, ws.chunk_max.data());
  }
  for (int j = 0; j < s; ++j) {
    atoms_out[j] = ws.support[static_cast<std::size_t>(j)];
    coefficients_out[j] = ws.gamma[j];
  }
  *residual_out = static_cast<float>(residual);
  return s;
}

/// The smallest Cholesky pivot (‖P⊥d_k‖²) an atom may have to join the support.
constexpr float min_pivot = 1e-5f;
static_assert(ormp_projected_floor > 0 && ormp_projected_floor <= 1);

/// argmax_k α_k² / max(‖P⊥d_k‖², f·‖d_k‖²), the ORMP score (f = ormp_projected_floor; floored
/// holds f·G_kk), the first on ties, searched like update_correlations: the scores of each chunk
/// are computed vectorized and their maximum kept, then only the best chunk is scanned.
Eigen::Index ormp_best(const float* alpha, const float* projected, const float* floored,
                       Eigen::Index K, float* chunk_max) {
  using Array = Eigen::Array<float, Eigen::Dynamic, 1>;
  using Scores = Eigen::Array<float, Eigen::Dynamic, 1, Eigen::ColMajor, chunk, 1>;  // no heap
  const auto scores = [&](Eigen::Index at, Eigen::Index n) -> Scores {
    const auto a = Eigen::Map<const Array>(alpha + at, n);
    return a * a /
           Eigen::Map<const Array>(projected + at, n).max(Eigen::Map<const Array>(floored + at, n));
  };
  const Eigen::Index chunks = (K + chunk - 1) / chunk;
  Eigen::Index best_chunk = 0;
  for (Eigen::Index c = 0; c < chunks; ++c) {
    chunk_max[c] = scores(c * chunk, std::min(chunk, K - c * chunk)).maxCoeff();
    if (chunk_max[c] > chunk_max[best_chunk]) best_chunk = c;
  }
  const Eigen::Index at = best_chunk * chunk, n = std::min(chunk, K - at);
  const Scores best = scores(at, n);
  for (Eigen::Index i = 0; i < n; ++i)
    if (best[i] == chunk_max[best_chunk]) return at + i;
  return at;
}

/// The support's Gram–Schmidt rows, S × K (K padded to whole vectors), stored by chunks of
/// row_chunk atoms (the last one narrower): a chunk holds, row after row, its values of each row,
/// so that its sums over the rows read one contiguous stretch.
std::size_t row_index(int j, Eigen::Index atom, int slots, Eigen::Index padded) {
  const Eigen::Index start = atom / row_chunk * row_chunk;
  const Eigen::Index width = std::min(row_chunk, padded - start);
  return static_cast<std::size_t>(start * slots + j * width + (atom - start));
}

/// One chunk of `V` vectors of ORMP's step 3 (gram_schmidt_row): V independent sums.
template <std::size_t V>
void gram_schmidt_chunk(float* __restrict rows, const float* __restrict g_k,
                        const float* __restrict l, int s, float inverse_root, float z,
                        float* __restrict alpha, float* __restrict projected) {
  // Vectors go through memcpy, not through functions (a 32-byte vector argument changes the ABI
  // of a build without AVX).
  Lanes sum[V] = {};
  const float* r = rows;
  for (int j = 0; j < s; ++j, r += V * lanes)
    for (std::size_t v = 0; v < V; ++v) {
      Lanes row;
      std::memcpy(&row, r + v * lanes, sizeof row);
      sum[v] += l[j] * row;
    }
  float* q = rows + static_cast<std::size_t>(s) * V * lanes;
  for (std::size_t v = 0; v < V; ++v) {
    const std::size_t i = v * lanes;
    Lanes g, a, p;
    std::memcpy(&g, g_k + i, sizeof g);
    std::memcpy(&a, alpha + i, sizeof a);
    std::memcpy(&p, projected + i, sizeof p);
    const Lanes value = (g - sum[v]) * inverse_root;
    a -= z * value;
    p -= value * value;
    std::memcpy(q + i, &value, sizeof value);
    std::memcpy(alpha + i, &a, sizeof a);
    std::memcpy(projected + i, &p, sizeof p);
  }
}

/// ORMP's step 3: row s, q = (G_{k,:} − Σ_j L_kj q_j)/√p over the earlier rows, then α ← α − z·q
/// and ‖P⊥d‖² ← ‖P⊥d‖² − q², a chunk at a time while its sums are in registers. g_k, α and
/// ‖P⊥d‖² are padded with zeros to whole vectors, which the padding keeps.
void gram_schmidt_row(float* rows, int slots, const float* g_k, const float* l, int s,
                      float inverse_root, float z, float* alpha, float* projected,
                      Eigen::Index padded) {
  constexpr std::size_t most = static_cast<std::size_t>(row_chunk) / lanes;
  for (Eigen::Index at = 0; at < padded; at += row_chunk) {
    const auto vectors = static_cast<std::size_t>(std::min(row_chunk, padded - at)) / lanes;
    // gram_schmidt_chunk<vectors> (1..most), called directly so that it inlines.
    [&]<std::size_t... V>(std::index_sequence<V...>) {
      static_cast<void>(((vectors == V + 1 ? (gram_schmidt_chunk<V + 1>(rows + at * slots, g_k + at,
                                                                        l, s, inverse_root, z,
                                                                        alpha + at, projected + at),
                                              true)
                                           : false) ||
                         ...));
    }
    (std::make_index_sequence<most>{});
  }
}

/// ORMP for one block (see AtomSelection), from α⁰ = Dᵀy and ‖y‖², with the same stopping rules and
/// outputs as code_one_block. Gram–Schmidt in the coefficient domain: adding atom k with pivot
/// p = ‖P⊥d_k‖² gives the row q = (G_{k,:} − Σ_j L_kj q_j)/√p (L_kj = q_j[k], the new row of the
/// Cholesky factor of G_II), the residual's new correlations α ← α − z·q with z = α_k/√p (the
/// residual's coordinate on the new orthonormal direction, so ‖r‖² falls by z²), and the projected
/// norms ‖P⊥d‖² ← ‖P⊥d‖² − q². The coefficients solve Lᵀγ = z at the end.
int code_one_block_ormp(const float* alpha0, double energy, const Eigen::MatrixXf& gram,
                        const float* gram_diagonal, const float* floored, const StopRule& rule,
                        OmpWorkspace& ws, std::int32_t* atoms_out, float* coefficients_out,
                        float* residual_out) {
  const Eigen::Index K = gram.rows();
  const auto slots = static_cast<int>(ws.lower.rows());  // S, the rows' chunk length
  const Eigen::Index padded = padded_atoms(K);
  float* alpha = ws.alpha.data();
  float* projected = ws.projected.data();
  auto& L = ws.lower;
  std::copy(alpha0, alpha0 + K, alpha);
  std::copy(gram_diagonal, gram_diagonal + K, projected);
  double residual = energy;
  int s = 0;
  while (residual > rule.target && s < rule.max_atoms) {
    // 1. The atom that lowers ‖r‖² most (the first on ties; chosen atoms have α = 0).
    const Eigen::Index k = ormp_best(alpha, projected, floored, K, ws.chunk_max.data());
    const float pivot = projected[k];
    if (!(std::abs(alpha[k]) > 0) || !(pivot > min_pivot)) break;
    const float root = std::sqrt(pivot);
    const float z = alpha[k] / root;
    // 2. Rate-distortion stop: atom k would lower ‖r‖² by z².
    if (rule.min_gain > 0 && residual <= rule.bound &&
        static_cast<double>(z) * static_cast<double>(z) < rule.min_gain)
      break;
    // 3. The Cholesky row and the Gram–Schmidt row of atom k; α and ‖P⊥d‖² updated.
    float* g_k = ws.gram_row.data();  // padded with zeros
    std::copy_n(gram.col(k).data(), K, g_k);
    float* l = ws.w.data();  // row s of L, contiguous
    for (int c = 0; c < s; ++c) l[c] = L(s, c) = ws.rows[row_index(c, k, slots, padded)];
    L(s, s) = root;
    gram_schmidt_row(ws.rows.data(), slots, g_k, l, s, 1.0f / root, z, alpha, projected, padded);
    ws.support[static_cast<std::size_t>(s)] = static_cast<int>(k);
    ws.z[s] = z;
    ++s;
    for (int j = 0; j < s; ++j)
      alpha[ws.support[static_cast<std::size_t>(j)]] = 0,
      projected[ws.support[static_cast<std::size_t>(j)]] = 0;
    residual = std::max(residual - static_cast<double>(z) * static_cast<double>(z), 0.0);
  }
  // 4. γ from Lᵀγ = z (back substitution).
  for (int r = s - 1; r >= 0; --r) {
    float v = ws.z[r];
    for (int c = r + 1; c < s; ++c) v -= L(c, r) * ws.gamma[c];
    ws.gamma[r] = v / L(r, r);
  }
  for (int j = 0; j < s; ++j) {
    atoms_out[j] = ws.support[static_cast<std::size_t>(j)];
    coefficients_out[j] = ws.gamma[j];
  }
  *residual_out = static_cast<float>(residual);
  return s;
}

/// OMP and ORMP for one block when the atoms are orthonormal (G = I), with the same stopping rules
/// and outputs as code_one_block: both then take the atom of largest |α_k| (the first on ties),
/// whose coefficient is α_k and whose gain is α_k², and leave the other correlations as they were.
/// So the atoms are taken in order of |α⁰| without updating anything: under a gain stop only the
/// atoms whose gain reaches it are candidates, sorted once.
int code_one_block_orthonormal(const float* alpha0, double energy, Eigen::Index K,
                               const StopRule& rule, OmpWorkspace& ws, std::int32_t* atoms_out,
                               float* coefficients_out, float* residual_out) {
  // An atom below the gain stop can be taken only while the residual is above the bound (the stop
  // then does not apply) and the target; a gain stop of 0 stops nothing.
  const bool gain_stops = rule.min_gain > 0 && energy <= rule.bound;
  std::vector<std::uint64_t>& order = ws.order;
  order.clear();
  for (Eigen::Index k = 0; k < K; ++k) {
    const double a = static_cast<double>(alpha0[k]);
    // |α| > 0 also leaves out a NaN, which would break the sort's ordering.
    if (std::abs(a) > 0 && (!gain_stops || a * a >= rule.min_gain)) {
      // The bits of a positive float order as the float does: |α| in the high word, the index
      // complemented in the low one, so that a descending sort puts the first index first on ties
      // (and compares integers instead of loading α twice a comparison).
      const std::uint32_t magnitude = std::bit_cast<std::uint32_t>(std::abs(alpha0[k]));
      order.push_back((std::uint64_t{magnitude} << 32) | ~static_cast<std::uint32_t>(k));
    }
  }
  std::sort(order.begin(), order.end(), std::greater<>());
  double residual = energy;
  int s = 0;
  for (const std::uint64_t key : order) {
    const int k = static_cast<int>(~static_cast<std::uint32_t>(key));
    if (!(residual > rule.target) || s >= rule.max_atoms) break;
    const double z = static_cast<double>(alpha0[k]);
    if (rule.min_gain > 0 && residual <= rule.bound && z * z < rule.min_gain) break;
    atoms_out[s] = k;
    coefficients_out[s] = alpha0[k];
    ++s;
    residual = std::max(residual - z * z, 0.0);
  }
  *residual_out = static_cast<float>(residual);
  return s;
}

/// Buffers of refine_on_residual, one set per thread.
struct ResidualWorkspace {
  Eigen::VectorXd residual;    // m: y − Dγ
  Eigen::VectorXf residual_f;  // m: the same in float, for Dᵀr
  Eigen::VectorXf alpha0;      // K: Dᵀr
  std::vector<std::int32_t> atoms;
  std::vector<float> coefficients;
  ResidualWorkspace(Eigen::Index m, Eigen::Index K, int slots)
      : residual(m),
        residual_f(m),
        alpha0(K),
        atoms(static_cast<std::size_t>(slots)),
        coefficients(static_cast<std::size_t>(slots)) {}
};

/// The most continuations refine_on_residual runs for one block.
constexpr int max_continuations = 4;

/// A pursuit tracks ‖r‖² as ‖y‖² less the gains it computed, in float arithmetic, whose rounding
/// grows with ‖y‖² and with the atoms taken. On a smooth block, whose energy is some 10⁵ times
/// m·ε² and more at small ε, that estimate reaches the target while the residual is still well
/// above it: blocks stopped tens of atoms early, and the PSNR of smooth fields levelled off near
/// 80 dB whatever ε asked. So when a pursuit stops because its estimate met the target, the
/// residual is computed from y and the code (in double), and while it misses the target a new
/// pursuit codes it (α⁰ = Dᵀr), with the same rules and the atoms left; its atoms join the code,
/// and the coefficients of an atom taken twice add up (the quantizer refits blocks of up to
/// max_refit_atoms atoms by least squares on the support; larger ones keep these sums). Returns the
/// number of atoms; `*residual` is the computed ‖r‖² when the last pass stopped at the target.
template <class Pursuit>
int refine_on_residual(const float* y, const Eigen::MatrixXf& atoms, const StopRule& rule,
                       int count, Pursuit&& pursue, ResidualWorkspace& rw, std::int32_t* atom_out,
                       float* coefficient_out, float* residual) {
  const Eigen::Index m = atoms.rows();
  for (int pass = 0; pass < max_continuations; ++pass) {
    if (count >= rule.max_atoms || !(static_cast<double>(*residual) <= rule.target)) break;
    for (Eigen::Index v = 0; v < m; ++v) rw.residual[v] = static_cast<double>(y[v]);
    for (int j = 0; j < count; ++j) {
      const float* d = atoms.col(atom_out[j]).data();
      const double c = static_cast<double>(coefficient_out[j]);
      for (Eigen::Index v = 0; v < m; ++v) rw.residual[v] -= c * static_cast<double>(d[v]);
    }
    const double energy = rw.residual.squaredNorm();
    *residual = static_cast<float>(energy);
    if (energy <= rule.target) break;
    rw.residual_f = rw.residual.cast<float>();
    rw.alpha0.noalias() = atoms.transpose() * rw.residual_f;
    StopRule rest = rule;
    rest.max_atoms = rule.max_atoms - count;
    float rest_residual = 0;
    const int added = pursue(rw.alpha0.data(), energy, rest, rw.atoms.data(),
                             rw.coefficients.data(), &rest_residual);
    if (added == 0) break;
    for (int j = 0; j < added; ++j) {
      const std::int32_t a = rw.atoms[static_cast<std::size_t>(j)];
      const float c = rw.coefficients[static_cast<std::size_t>(j)];
      const auto at = std::find(atom_out, atom_out + count, a) - atom_out;
      if (at < count)
        coefficient_out[at] += c;
      else
        atom_out[count] = a, coefficient_out[count] = c, ++count;
    }
    *residual = rest_residual;
  }
  return count;
}

}  // namespace

BatchOmp::BatchOmp(const Eigen::MatrixXf& atoms, SparseCodingOptions options)
    : atoms_(atoms), options_(options) {
  check_options(options, atoms.rows());
  if (atoms.cols() < 1) throw std::invalid_argument("a dictionary needs at least one atom");
  gram_.noalias() = atoms_.transpose() * atoms_;
  gram_diagonal_ = gram_.diagonal();
  orthonormal_ =
      atoms.cols() <= atoms.rows() &&
      (gram_ - Eigen::MatrixXf::Identity(gram_.rows(), gram_.cols())).cwiseAbs().maxCoeff() <=
          orthonormal_tolerance;
  // At least the smallest pivot: a zero atom (α = 0, ‖P⊥d‖² = 0) then scores 0, not 0/0.
  floored_diagonal_ =
      (gram_diagonal_ * static_cast<float>(ormp_projected_floor)).cwiseMax(min_pivot);
  target_energy_ = static_cast<double>(atoms.rows()) * options.tolerance * options.tolerance;
  bound_energy_ = bound_energy(options, atoms.rows());
}

void BatchOmp::encode(const Eigen::Ref<const Eigen::MatrixXf>& blocks, SparseCodes& codes,
                      const std::vector<float>& gain_weights) const {
  if (blocks.rows() != atoms_.rows())
    throw std::invalid_argument("blocks have " + std::to_string(blocks.rows()) + " values, atoms " +
                                std::to_string(atoms_.rows()));
  if (!gain_weights.empty() && gain_weights.size() != static_cast<std::size_t>(blocks.cols()))
    throw std::invalid_argument(std::to_string(gain_weights.size()) + " gain weights for " +
                                std::to_string(blocks.cols()) + " blocks");
  const auto n = static_cast<std::size_t>(blocks.cols());
  const int S = options_.max_atoms;
  codes.resize(n, S);
  const StopRule rule{target_energy_, S, options_.min_atom_gain, bound_energy_};
  // Batches of columns: one GEMM Dᵀ·Y per batch gives every α⁰ of the batch.
  constexpr Eigen::Index batch = 256;
  const auto batches = static_cast<std::int64_t>((blocks.cols() + batch - 1) / batch);
#pragma omp parallel
  {
    Eigen::MatrixXf correlations(atoms_.cols(), batch);
    const bool ormp = options_.selection == AtomSelection::error;
    OmpWorkspace ws(atoms_.cols(), S, ormp && !orthonormal_);
    if (orthonormal_) ws.order.reserve(static_cast<std::size_t>(atoms_.cols()));
    ResidualWorkspace rw(atoms_.rows(), atoms_.cols(), S);
#pragma omp for schedule(dynamic, 1)
    for (std::int64_t b = 0; b < batches; ++b) {
      const Eigen::Index first = b * batch;
      const Eigen::Index cols = std::min(batch, blocks.cols() - first);
      correlations.leftCols(cols).noalias() = atoms_.transpose() * blocks.middleCols(first, cols);
      for (Eigen::Index j = 0; j < cols; ++j) {
        const auto i = static_cast<std::size_t>(first + j);
        // ‖y‖² in float, vectorized (sixteen partial sums: the error is of the order of that in
        // α⁰).
        const auto energy = static_cast<double>(blocks.col(first + j).squaredNorm());
        const std::size_t slot = i * static_cast<std::size_t>(S);
        StopRule block_rule = rule;
        if (!gain_weights.empty() && rule.min_gain > 0)  // gain·w < min_gain ⇔ gain < min_gain / w
          block_rule.min_gain = gain_weights[i] > 0
                                    ? rule.min_gain / static_cast<double>(gain_weights[i])
                                    : std::numeric_limits<double>::infinity();
        const auto pursue = [&](const float* alpha0, double e, const StopRule& r,
                                std::int32_t* atom_out, float* coefficient_out, float* residual) {
          if (orthonormal_)
            return code_one_block_orthonormal(alpha0, e, atoms_.cols(), r, ws, atom_out,
                                              coefficient_out, residual);
          return ormp
                     ? code_one_block_ormp(alpha0, e, gram_, gram_diagonal_.data(),
                                           floored_diagonal_.data(), r, ws, atom_out,
                                           coefficient_out, residual)
                     : code_one_block(alpha0, e, gram_, r, ws, atom_out, coefficient_out, residual);
        };
        const int count =
            pursue(correlations.col(j).data(), energy, block_rule, codes.atom.data() + slot,
                   codes.coefficient.data() + slot, codes.residual_energy.data() + i);
        codes.count[i] = static_cast<std::uint8_t>(
            refine_on_residual(blocks.col(first + j).data(), atoms_, block_rule, count, pursue, rw,
                               codes.atom.data() + slot, codes.coefficient.data() + slot,
                               codes.residual_energy.data() + i));
      }
    }
  }
}

ReferenceCode reference_omp(const Eigen::MatrixXf& atoms, const Eigen::VectorXf& block,
                            SparseCodingOptions options) {
  check_options(options, atoms.rows());
  const Eigen::MatrixXd D = atoms.cast<double>();
  const Eigen::VectorXd y = block.cast<double>();
  const double target = static_cast<double>(atoms.rows()) * options.tolerance * options.tolerance;
  const double bound = bound_energy(options, atoms.rows());
  ReferenceCode code;
  code.min_selection_margin = std::numeric_limits<double>::infinity();
  Eigen::VectorXd r = y;
  Eigen::VectorXd gamma;
  while (r.squaredNorm() > target && static_cast<int>(code.atoms.size()) < options.max_atoms) {
    // 1. Correlate the explicit residual with every atom not yet chosen (ORMP: the gain of each,
    //    the squared correlation over the atom's squared norm orthogonal to the support).
    Eigen::VectorXd c = (D.transpose() * r).cwiseAbs();
    if (options.selection == AtomSelection::error) {
      Eigen::MatrixXd projected = D;
      if (!code.atoms.empty()) {
        Eigen::MatrixXd DI(D.rows(), static_cast<Eigen::Index>(code.atoms.size()));
        for (std::size_t j = 0; j < code.atoms.size(); ++j)
          DI.col(static_cast<Eigen::Index>(j)) = D.col(code.atoms[j]);
        projected -=
            DI * DI.householderQr().solve(D);  // the part of each atom in the support's span
      }
      const Eigen::VectorXd norms = D.colwise().squaredNorm().transpose();
      c = c.cwiseProduct(c).cwiseQuotient(projected.colwise()
                                              .squaredNorm()
                                              .transpose()
                                              .cwiseMax(ormp_projected_floor * norms)
                                              .cwiseMax(1e-12));
    }
    for (int k : code.atoms) c[k] = -1;
    Eigen::Index k = 0;
    const double best = c.maxCoeff(&k);
    if (!(best > 0)) break;
    c[k] = -1;
    const double second = c.size() > 1 ? c.maxCoeff() : 0.0;
    code.atoms.push_back(static_cast<int>(k));
    // 2. Least squares on the support, from scratch.
    Eigen::MatrixXd DI(D.rows(), static_cast<Eigen::Index>(code.atoms.size()));
    for (std::size_t j = 0; j < code.atoms.size(); ++j)
      DI.col(static_cast<Eigen::Index>(j)) = D.col(code.atoms[j]);
    const Eigen::VectorXd trial = DI.colPivHouseholderQr().solve(y);
    const Eigen::VectorXd trial_r = y - DI * trial;
    // 3. Rate-distortion stop: the atom is not kept if it lowers ‖r‖² by less than min_atom_gain.
    if (options.min_atom_gain > 0 && r.squaredNorm() <= bound &&
        r.squaredNorm() - trial_r.squaredNorm() < options.min_atom_gain) {
      code.atoms.pop_back();
      break;
    }
    code.min_selection_margin = std::min(code.min_selection_margin, (best - second) / best);
    gamma = trial;
    r = trial_r;
  }
  code.coefficients.assign(gamma.data(), gamma.data() + gamma.size());
  code.residual_energy = r.squaredNorm();
  return code;
}

void reconstruct_block(const Eigen::MatrixXf& atoms, const SparseCodes& codes, std::size_t i,
                       float* out) {
  Eigen::Map<Eigen::VectorXf> result(out, atoms.rows());
  result.setZero();
  const std::int32_t* a = codes.atoms_of(i);
  const float* c = codes.coefficients_of(i);
  for (int j = 0; j < codes.count[i]; ++j) result.noalias() += c[j] * atoms.col(a[j]);
}

}  // namespace volreel::dictionary
