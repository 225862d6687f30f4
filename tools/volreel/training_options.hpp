// training_options.hpp: the options `volreel train` and `volreel bench train` share — the series,
// ε or a PSNR, K, M, Smax, the coreset hierarchy and the training schedules — and what both print
// while they train.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/dictionary/training.hpp"

namespace volreel::cli {

/// Options shared by `train` and `bench train`.
struct TrainingCli {
  std::string series;
  ReaderOptions reader;
  double tolerance = 0;
  double psnr = dictionary::default_training_psnr;
  int atoms = 1024;
  int block = 6;
  int max_atoms = dictionary::default_max_atoms;
  std::string coreset = "16M";
  int levels = 6;
  int iterations = 8;
  std::uint64_t seed = 1;
  double coarse_tolerance = 2;
  bool no_sparsity_ramp = false;
  double convergence = 0.01;
  CLI::Option* tolerance_option = nullptr;

  void add_to(CLI::App& c);
  dictionary::CoresetOptions coreset_options() const;
  dictionary::TrainingOptions training_options(double eps, bool flat) const;
  /// ε: --tolerance, else --psnr over the training frames' value range.
  double tolerance_for(const dictionary::CoresetHierarchy& h) const;
};

/// "12.3 MVoxel".
std::string mvoxels(double voxels);
/// The coreset hierarchy of the series, with a progress bar.
dictionary::CoresetHierarchy build_coresets(const datasets::SeriesReader& series,
                                            const dictionary::CoresetOptions& o);
/// The frames and levels of a hierarchy drawn in `seconds`.
void print_coresets(const dictionary::CoresetHierarchy& h, const datasets::SeriesInfo& info,
                    double seconds);
/// A line per iteration (every_iteration) or per level, and the final evaluation.
void print_progress(const dictionary::TrainingProgress& p, double range, bool every_iteration);

}  // namespace volreel::cli
