// metrics.cpp: PSNR, RMSE and maximum error between an original and a decoded array, accumulated
// over any number of frames (definitions in metrics.hpp).
#include "volreel/psnr/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <utility>
#include <vector>

namespace volreel::psnr {
namespace {

/// Values per block of the error sums: each block is summed on its own and the block sums are
/// added in order, so the result is accurate for huge arrays and independent of the thread count.
constexpr std::size_t kBlock = 4096;

struct BlockSums {
  double sum_squared = 0, max_abs = 0;
  double min = std::numeric_limits<double>::infinity();
  double max = -std::numeric_limits<double>::infinity();
  bool finite = true;
};

BlockSums sum_block(const float* original, const float* decoded, std::size_t n) {
  BlockSums sums;
  float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
  bool finite = true;
  for (std::size_t i = 0; i < n; ++i) {
    const float a = original[i], b = decoded[i];
    finite = finite && std::isfinite(a) && std::isfinite(b);
    lo = std::min(lo, a);
    hi = std::max(hi, a);
    const double error = static_cast<double>(a) - static_cast<double>(b);
    sums.sum_squared += error * error;
    sums.max_abs = std::max(sums.max_abs, std::abs(error));
  }
  sums.min = static_cast<double>(lo);
  sums.max = static_cast<double>(hi);
  sums.finite = finite;
  return sums;
}

[[noreturn]] void throw_non_finite(std::span<const float> original,
                                   std::span<const float> decoded) {
  for (std::size_t i = 0; i < original.size(); ++i) {
    for (const auto& [name, values] :
         {std::pair{"original", original}, std::pair{"decoded", decoded}}) {
      if (!std::isfinite(values[i])) {
        throw InputError(std::string("error metrics: the ") + name + " value at index " +
                         std::to_string(i) + " (in order, x fastest) is " +
                         (std::isnan(values[i]) ? "NaN" : "infinite") +
                         "; metrics need finite values");
      }
    }
  }
  throw InputError("error metrics: non-finite value");  // unreachable: a block reported one
}

/// 10·log10(range² / mse) with the edge cases of metrics.hpp: +inf when mse = 0 (whatever the
/// range), −inf when the original is constant but the decoded data differ.
double psnr_from(double range, double mse) {
  if (mse == 0) return std::numeric_limits<double>::infinity();
  if (range == 0) return -std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(range * range / mse);
}

}  // namespace

void ErrorAccumulator::add(std::span<const float> original, std::span<const float> decoded) {
  if (original.size() != decoded.size()) {
    throw InputError("error metrics: original has " + std::to_string(original.size()) +
                     " values but decoded has " + std::to_string(decoded.size()));
  }
  if (original.empty()) return;

  // 1. Sum each block of kBlock values in parallel.
  const std::size_t blocks = (original.size() + kBlock - 1) / kBlock;
  std::vector<BlockSums> sums(blocks);
  const auto block_count = static_cast<std::int64_t>(blocks);
#pragma omp parallel for schedule(static) if (blocks > 16)
  for (std::int64_t b = 0; b < block_count; ++b) {
    const std::size_t begin = static_cast<std::size_t>(b) * kBlock;
    const std::size_t n = std::min(kBlock, original.size() - begin);
    sums[static_cast<std::size_t>(b)] =
        sum_block(original.data() + begin, decoded.data() + begin, n);
  }

  // 2. Combine the blocks in order (deterministic), then fold into the running totals.
  BlockSums total;
  for (const BlockSums& s : sums) {
    total.finite = total.finite && s.finite;
    total.sum_squared += s.sum_squared;
    total.max_abs = std::max(total.max_abs, s.max_abs);
    total.min = std::min(total.min, s.min);
    total.max = std::max(total.max, s.max);
  }
  if (!total.finite) throw_non_finite(original, decoded);

  min_ = count_ == 0 ? total.min : std::min(min_, total.min);
  max_ = count_ == 0 ? total.max : std::max(max_, total.max);
  count_ += original.size();
  sum_squared_ += total.sum_squared;
  max_abs_ = std::max(max_abs_, total.max_abs);
}

ErrorStats ErrorAccumulator::result() const {
  ErrorStats stats;
  stats.count = count_;
  stats.mse = count_ == 0 ? 0.0 : sum_squared_ / static_cast<double>(count_);
  stats.rmse = std::sqrt(stats.mse);
  stats.max_abs_error = max_abs_;
  return against_range(stats, min_, max_);
}

ErrorStats against_range(ErrorStats stats, double min, double max) {
  stats.original_min = min;
  stats.original_max = max;
  stats.psnr = psnr_from(stats.range(), stats.mse);
  // zfp's 20·log10(range / (2·RMSE)) = 10·log10(range² / MSE) − 20·log10(2), same edge cases.
  stats.psnr_zfp = std::isfinite(stats.psnr) ? 20.0 * std::log10(stats.range() / (2.0 * stats.rmse))
                                             : stats.psnr;
  return stats;
}

ErrorStats compare(std::span<const float> original, std::span<const float> decoded) {
  ErrorAccumulator accumulator;
  accumulator.add(original, decoded);
  return accumulator.result();
}

}  // namespace volreel::psnr
