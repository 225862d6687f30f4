// dictionary_test_data.hpp: synthetic volumes for the dictionary tests, made with our own PRNG.
#pragma once

#include <cmath>
#include <numbers>
#include <vector>

#include <Eigen/Core>

#include "volreel/datasets/prng.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/dictionary/blocks.hpp"
#include "volreel/dictionary/dictionary.hpp"

namespace volreel::test {

/// K random zero-mean unit atoms of 216 values (seeded: the same everywhere).
inline dictionary::Dictionary random_dictionary(int atoms, std::uint64_t seed) {
  dictionary::Dictionary d;
  d.block_size = 6;
  d.atoms.resize(216, atoms);
  SplitMix64 rng(seed);
  for (int k = 0; k < atoms; ++k)
    for (int v = 0; v < 216; ++v) d.atoms(v, k) = static_cast<float>(rng.normal());
  dictionary::normalize_atoms(d.atoms);
  return d;
}

/// K atoms that pay on `v`: blocks of 6³ of the volume itself, taken at spread-out places (the
/// volume at least 6 a side), zero-mean and unit-norm.
inline dictionary::Dictionary exemplar_dictionary(const Volume& v, int atoms) {
  dictionary::Dictionary d;
  d.block_size = 6;
  d.atoms.resize(216, atoms);
  const std::int64_t nx = v.dims.x / 6, ny = v.dims.y / 6, nz = v.dims.z / 6;
  for (int k = 0; k < atoms; ++k) {
    const std::int64_t x0 = 6 * (k % nx), y0 = 6 * (k / nx % ny), z0 = 6 * (k % nz);
    for (std::int64_t z = 0; z < 6; ++z)
      for (std::int64_t y = 0; y < 6; ++y)
        for (std::int64_t x = 0; x < 6; ++x)
          d.atoms(static_cast<Eigen::Index>(x + 6 * y + 36 * z), k) = v.at(x0 + x, y0 + y, z0 + z);
  }
  dictionary::normalize_atoms(d.atoms);
  return d;
}

/// A smooth multi-scale field (a few random plane waves) with some noise; no two frames alike.
inline Volume wavy_volume(Dims dims, std::uint64_t seed) {
  SplitMix64 rng(seed);
  struct Wave {
    double kx, ky, kz, phase, amplitude;
  };
  std::vector<Wave> waves;
  for (int w = 0; w < 12; ++w) {
    const double scale = 0.05 + 0.5 * rng.uniform();
    waves.push_back({scale * rng.normal(), scale * rng.normal(), scale * rng.normal(),
                     2 * std::numbers::pi * rng.uniform(), 1.0 / (1.0 + 4 * scale)});
  }
  Volume v(dims);
  for (std::int64_t k = 0; k < dims.z; ++k)
    for (std::int64_t j = 0; j < dims.y; ++j)
      for (std::int64_t i = 0; i < dims.x; ++i) {
        double value = 0.02 * rng.normal();
        for (const Wave& w : waves)
          value +=
              w.amplitude * std::sin(w.kx * static_cast<double>(i) + w.ky * static_cast<double>(j) +
                                     w.kz * static_cast<double>(k) + w.phase);
        v.at(i, j, k) = static_cast<float>(value);
      }
  return v;
}

/// K random zero-mean unit-norm atoms of m values.
inline Eigen::MatrixXf planted_atoms(Eigen::Index m, Eigen::Index K, std::uint64_t seed) {
  SplitMix64 rng(seed);
  Eigen::MatrixXf D(m, K);
  for (Eigen::Index i = 0; i < D.size(); ++i) D.data()[i] = static_cast<float>(rng.normal());
  dictionary::normalize_atoms(D);
  return D;
}

/// A volume whose every M³ block is mean + Σ (sparsity atoms of D) · coefficient + noise.
inline Volume planted_volume(Dims dims, int block_size, const Eigen::MatrixXf& atoms, int sparsity,
                             double noise, std::uint64_t seed) {
  SplitMix64 rng(seed);
  const dictionary::BlockGrid grid(dims, block_size);
  Volume v(dims);
  Eigen::VectorXf block(atoms.rows());
  for (std::size_t b = 0; b < grid.block_count(); ++b) {
    block.setZero();
    for (int s = 0; s < sparsity; ++s) {
      const auto k = static_cast<Eigen::Index>(rng.below(static_cast<std::uint64_t>(atoms.cols())));
      block +=
          static_cast<float>((rng.uniform() < 0.5 ? -1 : 1) * rng.uniform(1.0, 3.0)) * atoms.col(k);
    }
    for (Eigen::Index i = 0; i < block.size(); ++i)
      block[i] += static_cast<float>(noise * rng.normal());
    grid.store(v.data, b, static_cast<float>(rng.uniform(-5, 5)), block.data());
  }
  return v;
}

}  // namespace volreel::test
