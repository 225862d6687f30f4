// prng.cpp: the non-inline parts of volreel's PRNG.
#include "volreel/datasets/prng.hpp"

#include <cmath>
#include <numbers>

namespace volreel {

double SplitMix64::normal() noexcept {
  // Box–Muller; 1 - u keeps the logarithm's argument in (0, 1].
  const double u1 = 1.0 - uniform();
  const double u2 = uniform();
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
}

}  // namespace volreel
