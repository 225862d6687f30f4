// cmd_train.cpp: `volreel train` — learn a dictionary from a series (MTV-Player §3.1, Algorithm 1:
// coreset hierarchy, batch-OMP, weighted approximate K-SVD) and write it with its provenance.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "commands.hpp"
#include "training_options.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/dictionary.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::cli {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

struct TrainCommandOptions {
  TrainingCli training;
  std::string out;
  bool flat = false, overwrite = false;
};

void run_train(const TrainCommandOptions& o) {
  // The output is checked before the frames are read and the dictionary trained.
  std::error_code ec;
  const auto out_status = std::filesystem::status(o.out, ec);
  if (std::filesystem::is_directory(out_status))
    throw InputError("--out '" + o.out + "' is a directory: expected the dictionary file to write");
  format::detail::check_writable(o.out, "--out");  // a device or FIFO is refused
  if (datasets::input_includes(o.training.series, o.out))
    throw InputError("--out '" + o.out + "' is part of the input '" + o.training.series +
                     "': the dictionary would be written over the data it is trained on; choose "
                     "another --out");
  if (std::filesystem::exists(out_status) && !o.overwrite)
    throw InputError("'" + o.out +
                     "' already exists: give --overwrite to replace it, or choose another --out");
  const auto series = datasets::open_series(o.training.series, o.training.reader.to_open_options());
  const auto& info = series->info();
  std::printf("volreel train: %s, %s x %zu frames, variable '%s'\n", info.source.c_str(),
              to_string(info.dims).c_str(), info.frames, info.variable.c_str());
  const auto co = o.training.coreset_options();
  const auto coreset_start = Clock::now();
  const auto h = build_coresets(*series, co);
  print_coresets(h, info, seconds_since(coreset_start));
  if (const std::string warning = dictionary::too_few_blocks_warning(h, o.training.atoms);
      !warning.empty())
    std::fprintf(stderr, "volreel train: warning: %s\n", warning.c_str());
  const double eps = o.training.tolerance_for(h);
  const double range = h.value_max - h.value_min;
  std::printf(
      "tolerance eps = %.4g (RMS error per value of a block; PSNR >= %.2f dB if every block meets "
      "it)\n",
      eps, dictionary::psnr_for_tolerance(eps, range));
  std::printf("training %s: K = %d atoms of %d^3, Smax = %d, %d iterations %s\n",
              o.flat ? "flat (largest coreset only)" : "hierarchical (Algorithm 1)",
              o.training.atoms, o.training.block, o.training.max_atoms,
              o.flat ? o.training.iterations * (o.training.levels + 1) : o.training.iterations,
              o.flat ? "in all" : "per level");
  const auto to = o.training.training_options(eps, o.flat);
  const auto result = dictionary::train_dictionary(
      h, to, [&](const dictionary::TrainingProgress& p) { print_progress(p, range, true); });
  dictionary::save_dictionary(o.out, result.dictionary,
                              dictionary::training_provenance(co, to, h, result));
  std::printf("trained in %.1f s (%d iterations); wrote %s (%ju bytes)\n", result.seconds,
              result.total_iterations, o.out.c_str(),
              static_cast<std::uintmax_t>(std::filesystem::file_size(o.out)));
}

}  // namespace

void add_train_command(CLI::App& app) {
  auto o = std::make_shared<TrainCommandOptions>();
  CLI::App* train = app.add_subcommand("train",
                                       "Learn a dictionary of M^3 prototype blocks from a series "
                                       "(MTV-Player 3.1, Algorithm 1): pick frames by Halton\n"
                                       "sampling, draw a coreset hierarchy C, C/2, ..., C/2^levels "
                                       "by importance (block energy) in one pass, then refine\n"
                                       "the dictionary by weighted K-SVD (batch-OMP at tolerance "
                                       "eps) from the smallest coreset to the largest.\n"
                                       "Prints a line per level and iteration: RMS error, atoms "
                                       "per block, fraction of blocks meeting eps, time.");
  o->training.add_to(*train);
  train->add_option("--out", o->out, "Dictionary file to write")->required();
  train->add_flag("--overwrite", o->overwrite, "Replace an existing --out file");
  train->add_flag(
      "--flat", o->flat,
      "Train on the largest coreset only (iterations x (levels+1) iterations), for comparison");
  train->callback([o] { run_train(*o); });
}

}  // namespace volreel::cli
