// omp.hpp: sparse coding of blocks against a dictionary by Orthogonal Matching Pursuit —
// batch-OMP with progressive Cholesky updates and error-based stopping (Rubinstein, Zibulevsky,
// Elad 2008, "Efficient implementation of the K-SVD algorithm using batch orthogonal matching
// pursuit", algorithm 5 "OMP-Cholesky, error-constrained"), and a plain reference OMP for tests.
//
// The tolerance ε, used everywhere in volreel (training, encoding, the dictionary file):
//   ε is the RMS error per value of a block, in data units. A block y (m = M³ zero-mean values)
//   is coded when ‖y − Dγ‖₂² ≤ m·ε², i.e. sqrt(‖y − Dγ‖₂² / m) ≤ ε. (The paper's equation 2
//   bounds ‖y − Dγ‖₂² by ε² directly; dividing by m makes ε independent of the block size and
//   directly comparable to an RMSE.) The block mean is coded separately, so the zero-mean
//   residual is the block's whole residual. If every block meets ε, the volume's RMSE ≤ ε and
//   its PSNR ≥ 20·log10(range/ε); since many blocks fall well below ε the PSNR is usually higher.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace volreel::dictionary {

/// Maximum atoms per block in volreel's format (4-bit sparsity field).
inline constexpr int default_max_atoms = 15;

struct SparseCodingOptions {
  double tolerance = 0;                 ///< ε ≥ 0, RMS error per value of a block (see above)
  int max_atoms = default_max_atoms;    ///< Smax ≥ 1: a block uses at most this many atoms
};

/// ε for a PSNR target: ε = range · 10^(−psnr/20), so that PSNR ≥ psnr if every block meets ε.
double tolerance_for_psnr(double psnr_db, double value_range);
/// The inverse: 20·log10(range/ε).
double psnr_for_tolerance(double tolerance, double value_range);

/// Sparse codes of n blocks, with max_atoms slots per block (slots past count(i) are unused).
struct SparseCodes {
  int max_atoms = 0;
  std::vector<std::uint8_t> count;        ///< atoms used by block i
  std::vector<std::int32_t> atom;         ///< n × max_atoms atom indices, in the order OMP chose them
  std::vector<float> coefficient;         ///< n × max_atoms coefficients
  std::vector<float> residual_energy;     ///< ‖y − Dγ‖₂² of block i (from OMP's update formula)

  void resize(std::size_t blocks, int slots);
  std::size_t size() const { return count.size(); }
  const std::int32_t* atoms_of(std::size_t i) const { return atom.data() + i * static_cast<std::size_t>(max_atoms); }
  const float* coefficients_of(std::size_t i) const {
    return coefficient.data() + i * static_cast<std::size_t>(max_atoms);
  }
};

/// Batch-OMP against a fixed dictionary. Construction precomputes the Gram matrix G = DᵀD; encode()
/// computes Dᵀy for a batch of blocks with one matrix product, then runs OMP per block using only
/// G, Dᵀy and ‖y‖², in parallel (OpenMP) over batches. Results do not depend on the thread count.
class BatchOmp {
 public:
  /// atoms: m × K, unit-norm columns (zero-mean for volreel's blocks). Throws std::invalid_argument
  /// on bad options (ε < 0 or not finite, Smax < 1 or > 255 or > m).
  BatchOmp(const Eigen::MatrixXf& atoms, SparseCodingOptions options);

  /// Codes every column of `blocks` (m × n, zero-mean). codes is resized to n.
  void encode(const Eigen::Ref<const Eigen::MatrixXf>& blocks, SparseCodes& codes) const;

  const SparseCodingOptions& options() const { return options_; }
  const Eigen::MatrixXf& atoms() const { return atoms_; }

 private:
  Eigen::MatrixXf atoms_;
  Eigen::MatrixXf gram_;   ///< K × K
  SparseCodingOptions options_;
  double target_energy_;   ///< m·ε²
};

/// One block's code from the reference OMP.
struct ReferenceCode {
  std::vector<int> atoms;             ///< in the order chosen
  std::vector<double> coefficients;
  double residual_energy = 0;         ///< ‖y − Dγ‖₂², computed from the residual itself
  double min_selection_margin = 0;    ///< smallest gap, over the steps, between the best and the second-best |correlation|
};

/// Plain OMP in double precision: at each step correlate the explicit residual with every atom,
/// add the best, re-solve least squares on the support by QR. Slow; the yardstick for tests.
/// Same stopping rule as BatchOmp (‖r‖² ≤ m·ε², or Smax atoms).
ReferenceCode reference_omp(const Eigen::MatrixXf& atoms, const Eigen::VectorXf& block, SparseCodingOptions options);

/// y ≈ Dγ for block i of codes, written into out (m values).
void reconstruct_block(const Eigen::MatrixXf& atoms, const SparseCodes& codes, std::size_t i, float* out);

}  // namespace volreel::dictionary
