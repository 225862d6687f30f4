// ksvd.cpp: one iteration of weighted approximate K-SVD (RZE08 "Approximate K-SVD" with weights;
// the steps are numbered as in ksvd.hpp).
#include "volreel/dictionary/ksvd.hpp"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

namespace volreel::dictionary {

namespace {

void check_inputs(const Eigen::MatrixXf& atoms, const Eigen::MatrixXf& samples,
                  std::span<const float> weights) {
  if (samples.rows() != atoms.rows())
    throw std::invalid_argument("samples have " + std::to_string(samples.rows()) +
                                " values, atoms " + std::to_string(atoms.rows()));
  if (weights.size() != static_cast<std::size_t>(samples.cols()))
    throw std::invalid_argument(std::to_string(weights.size()) + " weights for " +
                                std::to_string(samples.cols()) + " samples");
}

/// (A residual counts as meeting ε up to float rounding of the stored residual: 1e-6 relative.)
CodingStats stats_of(const SparseCodes& codes, std::span<const float> weights, double target) {
  CodingStats s;
  for (std::size_t i = 0; i < codes.size(); ++i) {
    const double w = static_cast<double>(weights[i]);
    s.objective += w * static_cast<double>(codes.residual_energy[i]);
    s.weighted_atoms += w * codes.count[i];
    if (static_cast<double>(codes.residual_energy[i]) > target * (1 + 1e-6)) s.weighted_unmet += w;
    s.weight_sum += w;
  }
  return s;
}

double target_energy(const Eigen::MatrixXf& atoms, const SparseCodingOptions& coding) {
  return static_cast<double>(atoms.rows()) * coding.tolerance * coding.tolerance;
}

}  // namespace

CodingStats measure_coding(const Eigen::MatrixXf& atoms, const Eigen::MatrixXf& samples,
                           std::span<const float> weights, const SparseCodingOptions& coding) {
  check_inputs(atoms, samples, weights);
  SparseCodes codes;
  BatchOmp(atoms, coding).encode(samples, codes);
  return stats_of(codes, weights, target_energy(atoms, coding));
}

KsvdIterationStats ksvd_iteration(Eigen::MatrixXf& atoms, const Eigen::MatrixXf& samples,
                                  std::span<const float> weights, const KsvdOptions& options,
                                  SplitMix64& rng) {
  check_inputs(atoms, samples, weights);
  const Eigen::Index m = atoms.rows();
  const Eigen::Index K = atoms.cols();
  const Eigen::Index n = samples.cols();
  KsvdIterationStats stats;

  // 1. Sparse coding.
  SparseCodes codes;
  BatchOmp(atoms, options.coding).encode(samples, codes);
  stats.coded = stats_of(codes, weights, target_energy(atoms, options.coding));

  // Residuals R = Y − DΓ, kept up to date through step 2.
  Eigen::MatrixXf residual(m, n);
#pragma omp parallel for schedule(static)
  for (Eigen::Index i = 0; i < n; ++i) {
    auto r = residual.col(i);
    r = samples.col(i);
    const auto ui = static_cast<std::size_t>(i);
    const std::int32_t* a = codes.atoms_of(ui);
    const float* c = codes.coefficients_of(ui);
    for (int j = 0; j < codes.count[ui]; ++j) r.noalias() -= c[j] * atoms.col(a[j]);
  }

  // Who uses which atom: for atom k, entries [start[k], start[k+1]) of `users` are the coefficient
  // slots (i·Smax + j) that hold k.
  const auto S = static_cast<std::size_t>(codes.max_atoms);
  std::vector<std::size_t> start(static_cast<std::size_t>(K) + 1, 0);
  for (std::size_t i = 0; i < codes.size(); ++i)
    for (std::size_t j = 0; j < codes.count[i]; ++j)
      ++start[static_cast<std::size_t>(codes.atom[i * S + j]) + 1];
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<std::size_t> users(start.back());
  {
    std::vector<std::size_t> fill(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < codes.size(); ++i)
      for (std::size_t j = 0; j < codes.count[i]; ++j)
        users[fill[static_cast<std::size_t>(codes.atom[i * S + j])]++] = i * S + j;
  }
  std::size_t most_users = 0;
  for (Eigen::Index k = 0; k < K; ++k)
    most_users = std::max(
        most_users, start[static_cast<std::size_t>(k) + 1] - start[static_cast<std::size_t>(k)]);

  // 2. Atom updates in a random order (Fisher–Yates with our PRNG).
  std::vector<Eigen::Index> order(static_cast<std::size_t>(K));
  std::iota(order.begin(), order.end(), Eigen::Index{0});
  for (std::size_t i = order.size(); i > 1; --i) std::swap(order[i - 1], order[rng.below(i)]);
  Eigen::MatrixXf E(m, static_cast<Eigen::Index>(most_users));
  Eigen::VectorXf g(static_cast<Eigen::Index>(most_users)),
      wg(static_cast<Eigen::Index>(most_users));
  Eigen::VectorXf d(m);
  std::vector<bool> used(static_cast<std::size_t>(K), false);
  for (const Eigen::Index k : order) {
    const std::size_t first = start[static_cast<std::size_t>(k)];
    const auto count = static_cast<Eigen::Index>(start[static_cast<std::size_t>(k) + 1] - first);
    if (count == 0) continue;
    used[static_cast<std::size_t>(k)] = true;
    auto Ek = E.leftCols(count);
    // 2a. E = residuals of the users with atom k's contribution added back; g = their coefficients.
    for (Eigen::Index j = 0; j < count; ++j) {
      const std::size_t slot = users[first + static_cast<std::size_t>(j)];
      const auto i = static_cast<Eigen::Index>(slot / S);
      g[j] = codes.coefficient[slot];
      wg[j] = g[j] * weights[static_cast<std::size_t>(i)];
      Ek.col(j) = residual.col(i) + g[j] * atoms.col(k);
    }
    // 2b. d = E W g, zero-mean (it already is, up to rounding), unit norm.
    d.noalias() = Ek * wg.head(count);
    d.array() -= d.mean();
    const float norm = d.norm();
    if (!(norm > 1e-30f))
      continue;  // users' weighted contribution vanishes: keep the atom as it is
    d /= norm;
    // 2c. g = Eᵀd; residuals become E − d gᵀ.
    g.head(count).noalias() = Ek.transpose() * d;
    for (Eigen::Index j = 0; j < count; ++j) {
      const std::size_t slot = users[first + static_cast<std::size_t>(j)];
      const auto i = static_cast<Eigen::Index>(slot / S);
      codes.coefficient[slot] = g[j];
      residual.col(i) = Ek.col(j) - g[j] * d;
    }
    atoms.col(k) = d;
  }
  std::vector<double> weighted_error(static_cast<std::size_t>(n));
  for (Eigen::Index i = 0; i < n; ++i) {
    weighted_error[static_cast<std::size_t>(i)] =
        static_cast<double>(weights[static_cast<std::size_t>(i)]) *
        static_cast<double>(residual.col(i).squaredNorm());
    stats.objective_updated += weighted_error[static_cast<std::size_t>(i)];
  }
  for (bool u : used) stats.unused_atoms += u ? 0 : 1;
  if (!options.replace_atoms) return stats;

  // 3. Replace unused atoms and near-duplicates by the worst represented samples (largest w‖r‖²).
  const Eigen::MatrixXf gram = atoms.transpose() * atoms;
  std::vector<bool> replace(static_cast<std::size_t>(K), false);
  for (Eigen::Index k = 0; k < K; ++k) {
    if (!used[static_cast<std::size_t>(k)]) {
      replace[static_cast<std::size_t>(k)] = true;
      continue;
    }
    for (Eigen::Index i = 0; i < k; ++i)
      if (!replace[static_cast<std::size_t>(i)] &&
          static_cast<double>(std::abs(gram(i, k))) > options.duplicate_threshold) {
        replace[static_cast<std::size_t>(k)] = true;
        break;
      }
  }
  std::vector<std::size_t> worst(static_cast<std::size_t>(n));
  std::iota(worst.begin(), worst.end(), std::size_t{0});
  const auto wanted = static_cast<std::size_t>(std::count(replace.begin(), replace.end(), true));
  const std::size_t take = std::min(wanted, worst.size());
  std::partial_sort(worst.begin(), worst.begin() + static_cast<std::ptrdiff_t>(take), worst.end(),
                    [&](std::size_t a, std::size_t b) {
                      return weighted_error[a] != weighted_error[b]
                                 ? weighted_error[a] > weighted_error[b]
                                 : a < b;
                    });
  std::size_t next = 0;
  for (Eigen::Index k = 0; k < K && next < take; ++k) {
    if (!replace[static_cast<std::size_t>(k)]) continue;
    const std::size_t i = worst[next];
    if (!(weighted_error[i] > 0)) break;  // every remaining sample is represented exactly
    ++next;
    d = samples.col(static_cast<Eigen::Index>(i));
    d.array() -= d.mean();
    const float norm = d.norm();
    if (!(norm > 1e-30f)) continue;
    atoms.col(k) = d / norm;
    ++stats.replaced_atoms;
  }
  return stats;
}

}  // namespace volreel::dictionary
