// training_options.cpp: the options `volreel train` and `volreel bench train` share, and their
// progress lines.
#include "training_options.hpp"

#include <cmath>
#include <cstdio>
#include <exception>

#include "progress.hpp"

namespace volreel::cli {

namespace {

/// "16M", "2G", "500k" or a plain count -> voxels (decimal prefixes).
std::uint64_t parse_voxels(const std::string& text) {
  std::size_t used = 0;
  double value = 0;
  try {
    value = std::stod(text, &used);
  } catch (const std::exception&) {
    throw InputError("--coreset '" + text + "' is not a voxel count (e.g. 16M, 500k, 2G)");
  }
  const std::string suffix = text.substr(used);
  double scale = 1;
  if (suffix == "k" || suffix == "K")
    scale = 1e3;
  else if (suffix == "M")
    scale = 1e6;
  else if (suffix == "G")
    scale = 1e9;
  else if (!suffix.empty())
    throw InputError("--coreset '" + text + "': unknown suffix '" + suffix + "' (k, M or G)");
  if (!(value * scale >= 1) || !(value * scale <= 1e15))
    throw InputError("--coreset '" + text + "': expected a count of voxels in 1 .. 1e15");
  return static_cast<std::uint64_t>(value * scale);
}

}  // namespace

std::string mvoxels(double voxels) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3g MVoxel", voxels / 1e6);
  return text;
}

void TrainingCli::add_to(CLI::App& c) {
  c.add_option(
       "SERIES", series,
       "Raw series directory, HDF5 or NetCDF file, raw file or quoted pattern of raw files (see "
       "below)")
      ->required();
  tolerance_option = c.add_option(
      "--tolerance", tolerance,
      "Error tolerance eps: RMS error per value of a block, in data units (a block is done when\n"
      "sqrt(|y - D g|^2 / M^3) <= eps). Overrides --psnr");
  tolerance_option->check(positive());
  c.add_option(
       "--psnr", psnr,
       "Target PSNR in dB: eps = range * 10^(-PSNR/20), range = max - min of the training frames; "
       "PSNR is at\n"
       "least this if every block meets eps (usually higher, since many blocks fall below it)")
      ->check(positive())
      ->capture_default_str();
  c.add_option("--atoms", atoms, "Dictionary size K (1..65536)")
      ->check(CLI::Range(1, 65536))
      ->capture_default_str();
  c.add_option("--block", block,
               "Block size M (blocks of M^3 values; volreel encode codes 6^3 blocks, so its "
               "dictionaries need 6)")
      ->check(CLI::Range(2, 16))
      ->capture_default_str();
  c.add_option("--max-atoms", max_atoms, "Smax: atoms per block at most (1..255, at most M^3)")
      ->check(CLI::Range(1, 255))
      ->capture_default_str();
  c.add_option(
       "--coreset", coreset,
       "Coreset size C in voxels (k, M, G suffixes, decimal): the largest level holds C/M^3 block "
       "draws;\n"
       "frames are chosen until they hold 16*C voxels. Memory for training is about 12 bytes * C")
      ->capture_default_str();
  c.add_option("--levels", levels, "Coreset levels below C: C, C/2, ..., C/2^levels")
      ->check(CLI::Range(0, 30))
      ->capture_default_str();
  c.add_option("--iterations", iterations, "K-SVD iterations per coreset level (Algorithm 1's N)")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  c.add_option("--seed", seed, "Seed for coreset sampling and dictionary initialization")
      ->check(seed_number())
      ->capture_default_str();
  c.add_option("--coarse-tolerance", coarse_tolerance,
               "Tolerance schedule: the first level codes at this many times eps, the next ones "
               "geometrically\n"
               "less, the last at eps (1: eps throughout, as in the paper)")
      ->check(in_range(1, 1e6))
      ->capture_default_str();
  c.add_flag(
      "--no-sparsity-ramp", no_sparsity_ramp,
      "Allow Smax atoms per block from the first iteration (default: iteration t allows t+1)");
  c.add_option("--convergence", convergence,
               "End a level before its N iterations when an iteration lowers the weighted "
               "objective by less than\n"
               "this fraction (0: always N; flat mode tests it in its last stage only). On the "
               "default dataset 0.01\n"
               "trains 2.4x faster than 0 for -0.1 dB and +5% atoms per block at eps")
      ->check(non_negative())
      ->capture_default_str();
  reader.add_to(c);
}

dictionary::CoresetOptions TrainingCli::coreset_options() const {
  // Checked before the frames are read (coreset_options comes first).
  if (max_atoms > block * block * block)
    throw InputError("--max-atoms " + std::to_string(max_atoms) + ": blocks of " +
                     std::to_string(block) + "^3 have " + std::to_string(block * block * block) +
                     " values, so at most " + std::to_string(block * block * block) +
                     " atoms a block");
  dictionary::CoresetOptions o;
  o.block_size = block;
  o.coreset_voxels = parse_voxels(coreset);
  o.levels = levels;
  o.seed = seed;
  return o;
}

dictionary::TrainingOptions TrainingCli::training_options(double eps, bool flat) const {
  dictionary::TrainingOptions o;
  o.atom_count = atoms;
  o.coding = {.tolerance = eps, .max_atoms = max_atoms};
  o.iterations = iterations;
  o.flat = flat;
  o.seed = seed;
  o.coarse_tolerance_factor = coarse_tolerance;
  o.sparsity_ramp = !no_sparsity_ramp;
  o.convergence = convergence;
  return o;
}

double TrainingCli::tolerance_for(const dictionary::CoresetHierarchy& h) const {
  const bool given = tolerance_option && tolerance_option->count() > 0;
  return dictionary::training_tolerance(given ? std::optional<double>(tolerance) : std::nullopt,
                                        psnr, h);
}

dictionary::CoresetHierarchy build_coresets(const datasets::SeriesReader& series,
                                            const dictionary::CoresetOptions& o) {
  ProgressBar bar("coreset", "frames");
  auto h = dictionary::build_coreset_hierarchy(series, o, bar.progress());
  bar.finish();
  return h;
}

void print_coresets(const dictionary::CoresetHierarchy& h, const datasets::SeriesInfo& info,
                    double seconds) {
  const double m = std::pow(h.block_size, 3);
  std::printf("coreset: %zu frames by Halton sampling (", h.frames.size());
  for (std::size_t i = 0; i < h.frames.size(); ++i) {
    if (i == 8) {
      std::printf(", ...");
      break;
    }
    std::printf("%s%zu", i ? ", " : "", h.frames[i]);
  }
  std::printf(") = %s in %.0f blocks of %d^3, drawn in %.1f s; value range [%.6g, %.6g]\n",
              mvoxels(static_cast<double>(h.frames.size() * info.dims.voxels())).c_str(),
              h.population_blocks, h.block_size, seconds, h.value_min, h.value_max);
  std::printf("levels (draws -> distinct blocks):");
  for (const auto& c : h.levels)
    std::printf(" %zu->%ld", c.draws, static_cast<long>(c.blocks.cols()));
  std::printf("  (largest = %s)\n", mvoxels(static_cast<double>(h.largest().draws) * m).c_str());
}

void print_progress(const dictionary::TrainingProgress& p, double range, bool every_iteration) {
  if (!every_iteration && !p.final && p.iteration != p.iterations) return;
  if (p.final)
    std::printf("final     ");
  else
    std::printf("level %d/%d iteration %2d/%d ", p.level, p.levels, p.iteration, p.iterations);
  std::printf(
      "[%6zu blocks, eps %.3g, Smax %2d]  RMS %.4g (PSNR %.2f dB)  atoms/block %.3f  met eps "
      "%.2f%%  replaced %4d  %7.1f s\n",
      p.samples, p.tolerance, p.max_atoms, p.rms_error, 20 * std::log10(range / p.rms_error),
      p.mean_sparsity, 100 * p.fraction_met, p.replaced_atoms, p.elapsed_seconds);
  std::fflush(stdout);
}

}  // namespace volreel::cli
