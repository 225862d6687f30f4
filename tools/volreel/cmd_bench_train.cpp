// cmd_bench_train.cpp: `volreel bench train` — compares hierarchical training (Algorithm 1) with
// flat and plain K-SVD at the same ε on the same coreset, codes held-out frames with each
// dictionary, and measures batch-OMP throughput on all threads and on one.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "training_options.hpp"
#include "volreel/dictionary/blocks.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/omp.hpp"
#include "volreel/dictionary/training.hpp"

namespace volreel::cli {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct BenchTrainOptions {
  TrainingCli training;
  int eval_frames = 4;
  std::vector<int> flat_iterations;
  std::vector<int> plain_iterations;
  bool no_plain = false;
};

struct Evaluation {
  double psnr = 0, rmse = 0;
  double atoms_per_block = 0, fraction_met = 0;
  double blocks = 0, voxels = 0;
  double omp_seconds = 0, extract_seconds = 0;
};

/// Sparse-codes every block of the given frames (unquantized) and compares the reconstruction with
/// the original: PSNR over all of them (range = max − min of the originals), atoms per block, and
/// the time batch-OMP took.
Evaluation evaluate(const datasets::SeriesReader& series, const std::vector<std::size_t>& frames,
                    const dictionary::Dictionary& d,
                    const dictionary::SparseCodingOptions& coding) {
  const auto& info = series.info();
  const dictionary::BlockGrid grid(info.dims, d.block_size);
  const dictionary::BatchOmp omp(d.atoms, coding);
  const double target =
      static_cast<double>(grid.block_length()) * coding.tolerance * coding.tolerance;
  Evaluation e;
  double squared_error = 0, atoms = 0, met = 0;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  Eigen::MatrixXf blocks;
  std::vector<float> means;
  dictionary::SparseCodes codes;
  Volume reconstruction(info.dims);
  std::vector<float> approx(static_cast<std::size_t>(grid.block_length()));
  for (std::size_t t : frames) {
    const Volume original = series.read_frame(t);
    auto start = Clock::now();
    dictionary::extract_blocks(grid, original.data, blocks, means);
    e.extract_seconds += seconds_since(start);
    start = Clock::now();
    omp.encode(blocks, codes);
    e.omp_seconds += seconds_since(start);
    for (std::size_t b = 0; b < codes.size(); ++b) {
      atoms += codes.count[b];
      met += static_cast<double>(codes.residual_energy[b]) <= target * (1 + 1e-6) ? 1 : 0;
      dictionary::reconstruct_block(d.atoms, codes, b, approx.data());
      grid.store(reconstruction.data, b, means[b], approx.data());
    }
    for (std::size_t i = 0; i < original.data.size(); ++i) {
      const double x = original.data[i];
      const double diff = x - static_cast<double>(reconstruction.data[i]);
      squared_error += diff * diff;
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    e.blocks += static_cast<double>(codes.size());
    e.voxels += static_cast<double>(info.dims.voxels());
  }
  e.rmse = std::sqrt(squared_error / e.voxels);
  e.psnr = 20 * std::log10((hi - lo) / e.rmse);
  e.atoms_per_block = atoms / e.blocks;
  e.fraction_met = met / e.blocks;
  return e;
}

void run_bench_train(const BenchTrainOptions& o) {
  const auto series = datasets::open_series(o.training.series, o.training.reader.to_open_options());
  const auto& info = series->info();
  if (info.frames < 2)
    throw InputError(o.training.series + ": " + std::to_string(info.frames) +
                     " frame; bench train needs at least 2 (one to train on, one to evaluate)");
  if (static_cast<std::size_t>(o.eval_frames) >= info.frames)
    throw InputError("--eval-frames " + std::to_string(o.eval_frames) +
                     " holds out every frame of " + std::to_string(info.frames) +
                     ", leaving none to train on: give --eval-frames " +
                     std::to_string(info.frames - 1) + " or fewer");
  std::printf("volreel bench train\nmachine: %s\ninput:   %s, %s, %zu frames, variable '%s'\n",
              describe_machine().c_str(), info.source.c_str(), to_string(info.dims).c_str(),
              info.frames, info.variable.c_str());

  // 1. Which frames train and which evaluate: the Halton choice for C, and evenly spaced frames
  //    among the rest (if C takes every frame, the evaluation frames are held out first).
  auto co = o.training.coreset_options();
  std::vector<std::size_t> all(info.frames);
  std::iota(all.begin(), all.end(), std::size_t{0});
  const auto chosen = dictionary::halton_frames(
      all, info.dims.voxels(), co.frame_factor * static_cast<double>(co.coreset_voxels));
  std::vector<std::size_t> rest;
  for (std::size_t t : all)
    if (std::find(chosen.begin(), chosen.end(), t) == chosen.end()) rest.push_back(t);
  if (rest.empty()) {
    rest = all;
    std::printf("note: C = %s needs every frame; holding %d frames out of training anyway\n",
                mvoxels(static_cast<double>(co.coreset_voxels)).c_str(), o.eval_frames);
  }
  std::vector<std::size_t> eval;
  const auto wanted = std::min(rest.size(), static_cast<std::size_t>(std::max(1, o.eval_frames)));
  for (std::size_t i = 0; i < wanted; ++i)
    eval.push_back(rest[(2 * i + 1) * rest.size() / (2 * wanted)]);
  for (std::size_t t : all)
    if (std::find(eval.begin(), eval.end(), t) == eval.end()) co.candidate_frames.push_back(t);
  if (co.candidate_frames.empty())
    throw InputError("the series needs at least 2 frames: one to train, one to evaluate");

  const auto coreset_start = Clock::now();
  const auto h = build_coresets(*series, co);
  print_coresets(h, info, seconds_since(coreset_start));
  std::printf("evaluation frames (not used for training):");
  for (std::size_t t : eval) std::printf(" %zu", t);
  std::printf("\n");
  const double eps = o.training.tolerance_for(h);
  const double range = h.value_max - h.value_min;
  std::printf(
      "tolerance eps = %.4g (RMS per value of a block; PSNR >= %.2f dB if every block meets it); K "
      "= %d, M = %d, Smax = %d\n\n",
      eps, dictionary::psnr_for_tolerance(eps, range), o.training.atoms, o.training.block,
      o.training.max_atoms);

  // 2. Train hierarchically, then flat with the same number of iterations and with more, all at
  //    the same ε on the same coreset.
  //    "plain": without volreel's tolerance and sparsity schedules, i.e. K-SVD at ε on one coreset
  //    as in the non-hierarchical training the paper compares with.
  struct Run {
    std::string name;
    bool flat;
    int flat_iterations;
    bool plain;
    dictionary::TrainingResult result;
    Evaluation eval;
  };
  const int same_count = o.training.iterations * (o.training.levels + 1);
  std::vector<Run> runs{{"hierarchical", false, 0, false, {}, {}}};
  std::vector<int> flat_counts = o.flat_iterations;
  if (flat_counts.empty()) flat_counts = {same_count};
  for (int n : flat_counts) runs.push_back({"flat " + std::to_string(n), true, n, false, {}, {}});
  std::vector<int> plain_counts = o.plain_iterations;
  if (plain_counts.empty()) plain_counts = {same_count, 2 * same_count};
  if (!o.no_plain)
    for (int n : plain_counts)
      runs.push_back({"plain " + std::to_string(n), true, n, true, {}, {}});
  for (Run& r : runs) {
    auto options = o.training.training_options(eps, r.flat);
    options.flat_iterations = r.flat_iterations;
    if (r.plain) {
      options.coarse_tolerance_factor = 1;
      options.sparsity_ramp = false;
    }
    if (r.flat)
      std::printf("training flat: %d iterations on the largest coreset%s\n", r.flat_iterations,
                  r.plain ? ", at eps and Smax throughout (no schedules)" : "");
    else
      std::printf("training hierarchical: %d iterations on each of %d levels\n",
                  o.training.iterations, o.training.levels + 1);
    r.result = dictionary::train_dictionary(h, options, [&](const dictionary::TrainingProgress& p) {
      print_progress(p, range, false);
    });
  }

  // 3. Held-out frames: sparsity and PSNR of the unquantized sparse approximation, with all
  // threads.
  for (Run& r : runs) {
    ProgressBar bar("evaluating " + r.name, "frames");
    r.eval = evaluate(*series, eval, r.result.dictionary,
                      {.tolerance = eps, .max_atoms = o.training.max_atoms});
    bar.finish();
  }

  // 4. Batch-OMP throughput on one thread (all threads: from step 3).
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const Evaluation single = evaluate(*series, eval, runs[0].result.dictionary,
                                     {.tolerance = eps, .max_atoms = o.training.max_atoms});
  omp_set_num_threads(threads);

  std::printf("\n%-13s %10s %10s %12s %12s %10s %10s\n", "training", "time (s)", "iters",
              "train RMS", "eval PSNR", "atoms/blk", "met eps");
  for (const Run& r : runs)
    std::printf("%-13s %10.1f %10d %12.4g %9.2f dB %10.3f %9.2f%%\n", r.name.c_str(),
                r.result.seconds, r.result.total_iterations, r.result.final_stats.rms_error,
                r.eval.psnr, r.eval.atoms_per_block, 100 * r.eval.fraction_met);
  std::printf("\n");
  for (std::size_t i = 1; i < runs.size(); ++i)
    std::printf(
        "hierarchical vs %-10s: %5.2fx faster, PSNR %+.2f dB, atoms/block %+.3f (targets: >= 4x, "
        "|dPSNR| <= 0.2 dB)\n",
        runs[i].name.c_str(), runs[i].result.seconds / runs[0].result.seconds,
        runs[0].eval.psnr - runs[i].eval.psnr,
        runs[0].eval.atoms_per_block - runs[i].eval.atoms_per_block);
  const auto& e = runs[0].eval;
  std::printf(
      "batch-OMP (hierarchical dictionary, %.3f atoms/block, K = %d, Smax = %d), %.0f blocks of "
      "%d^3 from %zu frames:\n",
      e.atoms_per_block, o.training.atoms, o.training.max_atoms, e.blocks, o.training.block,
      eval.size());
  std::printf(
      "  %2d threads: %9.0f blocks/s  %7.2f MVoxel/s  (with block extraction: %.2f MVoxel/s)\n",
      threads, e.blocks / e.omp_seconds, e.voxels / e.omp_seconds / 1e6,
      e.voxels / (e.omp_seconds + e.extract_seconds) / 1e6);
  std::printf(
      "  %2d thread:  %9.0f blocks/s  %7.2f MVoxel/s  (with block extraction: %.2f MVoxel/s)\n", 1,
      single.blocks / single.omp_seconds, single.voxels / single.omp_seconds / 1e6,
      single.voxels / (single.omp_seconds + single.extract_seconds) / 1e6);
}

}  // namespace

void add_bench_train_command(CLI::App& bench) {
  auto o = std::make_shared<BenchTrainOptions>();
  CLI::App* cmd =
      bench.add_subcommand("train",
                           "Dictionary training benchmark: trains hierarchically (Algorithm 1), "
                           "flat (the largest coreset only, the same\n"
                           "number of iterations) and plain (flat without volreel's tolerance and "
                           "sparsity schedules, i.e. K-SVD at eps as in\n"
                           "the paper's baseline; the same number of iterations and twice that), "
                           "all at the same eps on the same coreset, then\n"
                           "codes frames held out of training with each dictionary\n"
                           "(unquantized) and prints training time, PSNR, atoms per block, blocks "
                           "meeting eps, and batch-OMP throughput in\n"
                           "blocks/s and MVoxel/s on all threads and on one.");
  o->training.add_to(*cmd);
  cmd->add_option("--eval-frames", o->eval_frames,
                  "Frames held out of training and coded for PSNR and speed")
      ->check(CLI::Range(1, 1 << 20))
      ->capture_default_str();
  cmd->add_option("--flat-iterations", o->flat_iterations,
                  "Iteration counts of the flat runs to compare with (default: the hierarchical "
                  "run's count,\n"
                  "iterations x (levels+1))")
      ->check(in_range(1, 1e6));
  cmd->add_option("--plain-iterations", o->plain_iterations,
                  "Iteration counts of the plain flat runs (default: the hierarchical run's count "
                  "and twice that)")
      ->check(in_range(1, 1e6));
  cmd->add_flag("--no-plain", o->no_plain,
                "Skip the flat run without tolerance and sparsity schedules (plain K-SVD at eps, "
                "as in the paper's baseline)");
  cmd->callback([o] { run_bench_train(*o); });
}

}  // namespace volreel::cli
