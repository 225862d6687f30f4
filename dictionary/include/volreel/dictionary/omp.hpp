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
#include <string>
#include <vector>

#include <Eigen/Core>

namespace volreel::dictionary {

/// Maximum atoms per block in volreel's format (4-bit sparsity field).
inline constexpr int default_max_atoms = 15;

/// Which atom a pursuit step adds (the stopping rules are the same for both):
///   correlation — OMP: the atom most correlated with the residual, argmax |d_kᵀr|;
///   error — ORMP, order-recursive matching pursuit (Cotter, Adler, Rao, Kreutz-Delgado 1999,
///     "Forward sequential algorithms for best basis selection"; also "optimized OMP",
///     Rebollo-Neira & Lowe 2002): the atom whose addition lowers ‖r‖² most, argmax (d_kᵀr)² /
///     ‖P⊥d_k‖², with P⊥ the projection orthogonal to the atoms already chosen. It costs the same
///     O(K·s) per step here (the projected norms are updated with the Gram–Schmidt rows of the
///     support) and, at a given ε, needs fewer atoms (docs/benchmarks.md). An atom mostly inside
///     the span of the support is scored as if the fraction ormp_projected_floor of its energy were
///     outside it: such atoms take large, cancelling coefficients, which a coarse quantizer codes
///     poorly.
enum class AtomSelection { correlation, error };

/// The names volreel uses for a selection (command lines, manifests): "omp" and "ormp".
const char* pursuit_name(AtomSelection selection);
/// The inverse; throws std::invalid_argument on another name.
AtomSelection pursuit_from_name(const std::string& name);

/// ORMP's score is (d_kᵀr)² / max(‖P⊥d_k‖², floor·‖d_k‖²), in (0, 1]: near 0 it is exact ORMP, 1
/// is OMP (for atoms of equal norm). Of the floors measured from near 0 to 1, 0.3 gives the most
/// PSNR at the same size and loses the least to 6-bit quantization (docs/benchmarks.md).
inline constexpr double ormp_projected_floor = 0.3;

/// When the pursuit of a block stops: at the first of these that holds.
///   1. ‖r‖² ≤ m·ε² (the tolerance; ε = 0: never);
///   2. s = Smax;
///   3. rate-distortion stop (min_atom_gain > 0): the next atom would lower ‖r‖² by less than
///      min_atom_gain, unless ‖r‖² > m·max_error² (max_error > 0: a hard bound on the block's RMS
///      error that overrides the gain test; 0: no bound).
/// Rule 3 is the Lagrangian rule of rate-distortion optimisation (Shoham & Gersho 1988; Ortega &
/// Ramchandran 1998, "Rate-distortion methods for image and video compression", §III): with a
/// constant cost per atom (a 16-bit code), keeping every atom whose gain exceeds λ·bits gives every
/// block the same slope −ΔE/Δbits, which minimises the total squared error for the total number of
/// codes, where rule 1 equalises the error per block instead. The gain of atom k is computed
/// before it is added: the residual is orthogonal to the support, so ΔE = (d_kᵀr)² / ‖P⊥d_k‖²,
/// with ‖P⊥d_k‖² the new Cholesky pivot G_kk − wᵀw. min_atom_gain = 0 is plain OMP (rules 1–2).

struct SparseCodingOptions {
  double tolerance = 0;               ///< ε ≥ 0, RMS error per value of a block (see above)
  int max_atoms = default_max_atoms;  ///< Smax ≥ 1: a block uses at most this many atoms
  double min_atom_gain = 0;           ///< ≥ 0, data units² (squared error of the block): rule 3
  double max_error = 0;               ///< ≥ 0, RMS error per value: rule 3's bound (0: none)
  AtomSelection selection = AtomSelection::correlation;  ///< OMP or ORMP
};

/// ε for a PSNR target: ε = range · 10^(−psnr/20), so that PSNR ≥ psnr if every block meets ε.
double tolerance_for_psnr(double psnr_db, double value_range);
/// The inverse: 20·log10(range/ε).
double psnr_for_tolerance(double tolerance, double value_range);

/// The PSNR targets (dB) that set ε where neither ε nor a PSNR is given; they differ, one per job.
/// Training (volreel train): at this ε nearly every block meets ε within Smax atoms.
inline constexpr double default_training_psnr = 50.0;
/// Encoding (volreel encode): the container's quality where neither the options nor the
/// dictionary (the ε it was trained at, which volreel train records) give ε.
inline constexpr double default_encoding_psnr = 55.0;

/// Sparse codes of n blocks, with max_atoms slots per block (slots past count(i) are unused).
struct SparseCodes {
  int max_atoms = 0;
  std::vector<std::uint8_t> count;  ///< atoms used by block i
  std::vector<std::int32_t> atom;   ///< n × max_atoms atom indices, in the order OMP chose them
  std::vector<float> coefficient;   ///< n × max_atoms coefficients
  /// ‖y − Dγ‖₂² of block i: computed from y and the code where the pursuit stopped at the
  /// tolerance, else (another stop, or the last continuation's) the pursuit's running estimate
  /// (BatchOmp::encode)
  std::vector<float> residual_energy;

  void resize(std::size_t blocks, int slots);
  std::size_t size() const { return count.size(); }
  const std::int32_t* atoms_of(std::size_t i) const {
    return atom.data() + i * static_cast<std::size_t>(max_atoms);
  }
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
  /// on bad options (ε, min_atom_gain or max_error < 0 or not finite, Smax < 1 or > 255 or > m).
  BatchOmp(const Eigen::MatrixXf& atoms, SparseCodingOptions options);

  /// Codes every column of `blocks` (m × n, zero-mean). codes is resized to n. gain_weights: empty,
  /// or n values ≥ 0, the importance of each block's error in the rate-distortion stop: block i
  /// stops before an atom whose gain × gain_weights[i] is below min_atom_gain (0: no atoms, unless
  /// the max_error bound asks for them). A block whose pursuit stops at the tolerance is checked
  /// against its computed residual and continued while it misses it (docs/design.md, "Pursuit").
  /// Throws std::invalid_argument on a size mismatch.
  void encode(const Eigen::Ref<const Eigen::MatrixXf>& blocks, SparseCodes& codes,
              const std::vector<float>& gain_weights = {}) const;

  const SparseCodingOptions& options() const { return options_; }
  const Eigen::MatrixXf& atoms() const { return atoms_; }
  /// True when the atoms are orthonormal (every Gram entry within orthonormal_tolerance of the
  /// identity's, as for the DCT basis): a pursuit then takes the atoms in order of |α⁰| and needs
  /// no Gram–Schmidt.
  bool orthonormal() const { return orthonormal_; }

  /// The largest |G_ij − δ_ij| of atoms that BatchOmp codes as an orthonormal basis.
  static constexpr float orthonormal_tolerance = 1e-5f;

 private:
  Eigen::MatrixXf atoms_;
  bool orthonormal_ = false;
  Eigen::MatrixXf gram_;           ///< K × K
  Eigen::VectorXf gram_diagonal_;  ///< G_kk = ‖d_k‖²: ORMP's projected norms before any atom
  Eigen::VectorXf floored_diagonal_;  ///< ormp_projected_floor·G_kk
  SparseCodingOptions options_;
  double target_energy_;  ///< m·ε²
  double bound_energy_;   ///< m·max_error² (+∞ without a bound)
};

/// One block's code from the reference OMP.
struct ReferenceCode {
  std::vector<int> atoms;  ///< in the order chosen
  std::vector<double> coefficients;
  double residual_energy = 0;  ///< ‖y − Dγ‖₂², computed from the residual itself
  double min_selection_margin =
      0;  ///< smallest relative gap, over the steps, between the best and the second-best score
};

/// Plain OMP (or ORMP) in double precision: at each step correlate the explicit residual with
/// every atom (ORMP: divide the squared correlations by the atoms' squared norms orthogonal to the
/// support, from a QR of the support), add the best, re-solve least squares on the support by QR.
/// Slow; the yardstick for tests. Same stopping rules as BatchOmp (‖r‖² ≤ m·ε², Smax atoms, or an
/// atom's gain below min_atom_gain, measured here as the drop of the explicit ‖r‖²; such an atom
/// is not kept). min_selection_margin compares the scores (|correlation| or gain).
ReferenceCode reference_omp(const Eigen::MatrixXf& atoms, const Eigen::VectorXf& block,
                            SparseCodingOptions options);

/// y ≈ Dγ for block i of codes, written into out (m values).
void reconstruct_block(const Eigen::MatrixXf& atoms, const SparseCodes& codes, std::size_t i,
                       float* out);

}  // namespace volreel::dictionary
