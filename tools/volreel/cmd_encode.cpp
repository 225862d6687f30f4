// cmd_encode.cpp: `volreel encode` — a series -> a NAME.vreel container (encoder/): the options
// as coding settings, the dictionary (given, the container's own on --resume, or trained), ε,
// the encode, and where its bytes and time went.
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "commands.hpp"
#include "encode_report.hpp"
#include "progress.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;

struct EncodeOptions {
  std::string series, dictionary, out,
      codec = "ksvd", rate_rule = "lagrangian",
      pursuit = dictionary::pursuit_name(encoder::CodingSettings{}.selection), mean_bits = "auto",
      coef_bits = "auto", atom_storage = "f16";
  ReaderOptions reader;
  double tolerance = 0, psnr = 0, bps = 0, zfp_accuracy = 0, max_error = 0,
         level_factor = encoder::CodingSettings{}.level_tolerance_factor,
         coef_step_factor = encoder::CodingSettings{}.coef_step_factor;
  int fixed_sparsity = 0, max_atoms = encoder::default_max_atoms, atoms = 0;
  std::size_t max_frames = 0, rate_sample_frames = 3;
  std::uint32_t max_keyframe_gap = encoder::default_max_keyframe_gap;
  bool resume = false, overwrite = false, no_refit = false, extend = false;
  CLI::Option *tolerance_opt = nullptr, *psnr_opt = nullptr, *bps_opt = nullptr, *zfp_opt = nullptr,
              *level_factor_opt = nullptr, *max_error_opt = nullptr, *max_atoms_opt = nullptr,
              *rate_rule_opt = nullptr, *keyframe_gap_opt = nullptr;
};

/// The options' coding settings (the value range and ε not yet set).
encoder::CodingSettings coding_settings(const EncodeOptions& o) {
  encoder::CodingSettings c;
  c.codec = encoder::codec_from_name(o.codec);
  c.max_atoms = o.max_atoms;
  c.fixed_sparsity = o.fixed_sparsity;
  c.rule = encoder::rate_rule_from_name(o.rate_rule);
  if (o.extend && c.fixed_sparsity == 0 && c.rule != encoder::VariableRateRule::tolerance)
    throw InputError("--extend-pursuit needs --rate-rule tolerance");
  if (o.level_factor_opt->count() > 0 &&
      (c.fixed_sparsity > 0 || c.rule != encoder::VariableRateRule::lagrangian))
    throw InputError("--level-factor applies to variable rate with --rate-rule lagrangian only");
  c.selection = dictionary::pursuit_from_name(o.pursuit);
  c.level_tolerance_factor = o.level_factor;
  c.mean_bits = encoder::mean_bits_from_text(o.mean_bits);
  c.coef_bits = encoder::coef_bits_from_text(o.coef_bits);
  c.coef_step_factor = o.coef_step_factor;
  if (o.max_error_opt->count() > 0) {
    // The pointwise bound: the tolerance rule at ε = E/2 (an RMS error never above the largest),
    // then atoms and a finer coefficient step until every value holds (quantize_brick's steps 4
    // and 5).
    if (c.fixed_sparsity > 0)
      throw InputError("--max-error and --fixed-sparsity exclude each other");
    if (o.rate_rule_opt->count() > 0 && c.rule != encoder::VariableRateRule::tolerance)
      throw InputError("--max-error uses --rate-rule tolerance");
    c.rule = encoder::VariableRateRule::tolerance;
    c.max_error = o.max_error;
  }
  c.refit_quantization = !o.no_refit;
  c.extend_pursuit = o.extend;
  return c;
}

encoder::ToleranceRequest tolerance_request(const EncodeOptions& o) {
  encoder::ToleranceRequest r;
  if (o.tolerance_opt->count()) r.tolerance = o.tolerance;
  if (o.max_error_opt->count()) r.tolerance = o.max_error / 2;
  if (o.psnr_opt->count()) r.psnr = o.psnr;
  if (o.bps_opt->count()) r.bps = o.bps;
  r.rate_sample_frames = o.rate_sample_frames;
  return r;
}

/// Trains the dictionary of an encode given none into `path`, printing each K tried.
void train_dictionary(const datasets::SeriesReader& series, const EncodeOptions& o, double eps,
                      std::size_t frames, const encoder::CodingSettings& coding,
                      const fs::path& path) {
  encoder::DefaultDictionaryOptions d;
  d.tolerance = eps;
  d.atoms = o.atoms;
  d.frames = frames;
  d.sample_frames = o.rate_sample_frames;
  d.half_atoms = o.atom_storage == "f16";
  d.coding = coding;
  dictionary::CoresetHierarchy h;
  {
    ProgressBar bar("coreset", "frames");
    h = dictionary::build_coreset_hierarchy(series, d.coreset, bar.progress());
    bar.finish();
  }
  const auto chosen = encoder::train_default_dictionary(series, h, d, [&](const auto& k) {
    if (d.atoms == 0 && k.atoms == 0)
      std::printf("  the DCT basis alone: estimated container %.0f bytes (dictionary %.0f)\n",
                  k.estimated_bytes, k.dictionary_bytes);
    else if (d.atoms == 0)
      std::printf(
          "  K = %4d: trained in %.1f s; estimated container %.0f bytes (dictionary %.0f)\n",
          k.atoms, k.train_seconds, k.estimated_bytes, k.dictionary_bytes);
    else
      std::printf("  K = %4d: trained in %.1f s\n", k.atoms, k.train_seconds);
  });
  if (chosen.dct_only) {
    format::write_dictionary_file(path, format::dct_dictionary(6, VOLREEL_VERSION));
    std::printf("using the DCT basis alone (eps %.4g)\n", eps);
    return;
  }
  dictionary::save_dictionary(path, chosen.dictionary, chosen.training);
  std::printf("using the dictionary of K = %d atoms (eps %.4g)\n", chosen.dictionary.atom_count(),
              eps);
}

/// What the encoder holds per frame of a stretch with keyframe gaps: the frame and the original
/// voxels of every brick of its octree.
double stretch_bytes_per_frame(const Dims& dims) {
  std::uint64_t bricks = 0;
  for (const auto& g : format::level_geometry({static_cast<std::uint32_t>(dims.x),
                                               static_cast<std::uint32_t>(dims.y),
                                               static_cast<std::uint32_t>(dims.z)}))
    bricks += std::uint64_t{g.grid[0]} * g.grid[1] * g.grid[2];
  return 4.0 * (static_cast<double>(dims.voxels()) +
                static_cast<double>(bricks) * static_cast<double>(format::brick_voxels));
}

/// The keyframe gap to encode with: the option's, or without one the default, lowered so that the
/// G + 1 frames of a stretch take at most half the machine's memory (said when it is lowered).
std::uint32_t keyframe_gap(const EncodeOptions& o, const Dims& dims) {
  if (o.keyframe_gap_opt->count() > 0) return o.max_keyframe_gap;
  // --bps's rate search codes whole sample frames: the size it finds is the size written only
  // when every frame stores every brick.
  if (o.bps_opt->count() > 0) return 1;
  const double memory =
      static_cast<double>(::sysconf(_SC_PHYS_PAGES)) * static_cast<double>(::sysconf(_SC_PAGESIZE));
  const double per_frame = stretch_bytes_per_frame(dims);
  std::uint32_t gap = o.max_keyframe_gap;
  while (gap > 1 && memory > 0 && (gap + 1) * per_frame > memory / 2) --gap;
  if (gap < o.max_keyframe_gap)
    std::printf("keyframe gap %u (not %u): %u frames of %.0f MB each fit in half the memory\n", gap,
                o.max_keyframe_gap, gap + 1, per_frame / 1e6);
  return gap;
}

void run_encode(const EncodeOptions& o) {
  const auto series = datasets::open_series(o.series, o.reader.to_open_options());
  const auto& info = series->info();
  const std::size_t frames = o.max_frames ? std::min(o.max_frames, info.frames) : info.frames;
  std::printf("volreel encode: %s, %s x %zu frames, variable '%s'\n", info.source.c_str(),
              to_string(info.dims).c_str(), frames, info.variable.c_str());
  encoder::EncodeJob job;
  job.resume = o.resume;
  job.overwrite = o.overwrite;
  job.max_frames = frames;
  job.coding = coding_settings(o);
  job.half_atoms = o.atom_storage == "f16";
  if (o.psnr_opt->count() > 0) job.psnr_target = o.psnr;
  job.max_keyframe_gap = keyframe_gap(o, info.dims);
  auto& c = job.coding;
  {
    ProgressBar bar("value range", "frames");
    std::tie(c.value_min, c.value_max) = encoder::value_range(*series, frames, bar.progress());
    bar.finish();
  }
  encoder::check_value_range(c.value_min, c.value_max, series->info().source);
  const double range = encoder::tolerance_range(c.value_min, c.value_max);
  std::printf("value range [%.6g, %.6g]%s\n", c.value_min, c.value_max,
              c.value_max > c.value_min ? "" : " (constant: every brick is stored as the value)");

  if (c.codec == format::Codec::zfp) {
    c.zfp_accuracy = o.zfp_opt->count() ? o.zfp_accuracy : range * 1e-3;
    std::printf("codec zfp, fixed accuracy %.4g per brick\n", c.zfp_accuracy);
  } else {
    // The dictionary: given, the container's own (resume), or trained here.
    const encoder::ToleranceRequest request = tolerance_request(o);
    fs::path dict_path = o.dictionary;
    fs::path trained;
    if (dict_path.empty() && o.resume && fs::exists(fs::path(o.out) / "dictionary.bin"))
      dict_path = fs::path(o.out) / "dictionary.bin";
    if (dict_path.empty() && !(c.value_max > c.value_min)) dict_path = "dct";  // nothing to learn
    if (dict_path.empty()) {
      const double eps = encoder::tolerance_to_train_at(request, range);
      trained =
          fs::temp_directory_path() / ("volreel-dictionary-" + std::to_string(::getpid()) + ".bin");
      std::printf(
          "no --dictionary given: training one with volreel train's defaults at eps %.4g, %s\n",
          eps,
          o.atoms ? ("K = " + std::to_string(o.atoms)).c_str()
                  : "K chosen by the total size it gives (--atoms to fix it)");
      train_dictionary(*series, o, eps, frames, c, trained);
      dict_path = trained;
    }
    // A copy, so that the container's own dictionary.bin can be used to resume.
    const fs::path copy = fs::temp_directory_path() /
                          ("volreel-dictionary-copy-" + std::to_string(::getpid()) + ".bin");
    if (dict_path == "dct")
      format::write_dictionary_file(copy, format::dct_dictionary(6, VOLREEL_VERSION));
    else
      fs::copy_file(dict_path, copy, fs::copy_options::overwrite_existing);
    if (!trained.empty()) fs::remove(trained);
    job.dictionary_file = copy;
    auto file = format::read_dictionary_file(copy);
    if ((job.half_atoms && !file.half_atoms) || !file.dct_atoms) {
      // Stored as the container will store it, so that --bps measures what the encode writes.
      file = format::container_dictionary(std::move(file), job.half_atoms);
      format::write_dictionary_file(copy, file);
    }
    std::optional<ProgressBar> bar;
    if (request.bps && c.fixed_sparsity == 0) bar.emplace("rate control", "steps");
    const auto eps = encoder::choose_tolerance(*series, file, fs::file_size(copy), c, frames,
                                               request, bar ? bar->progress() : Progress{});
    if (bar) bar->finish();
    c.tolerance = eps.tolerance;
    print_tolerance_choice(eps, c, o.bps, std::min(o.rate_sample_frames, frames), range,
                           file.atom_count);
  }
  job.provenance = {{"program", "volreel " VOLREEL_VERSION},
                    {"series", o.series},
                    {"refit_quantization", c.refit_quantization},
                    {"extend_pursuit", c.extend_pursuit},
                    {"max_atoms", c.max_atoms},
                    {"coef_bits", o.coef_bits},
                    {"coef_step_factor", c.coef_step_factor},
                    {"max_error", c.max_error}};
  // encode_series adds the variable-rate rule and its parameters.
  encoder::EncodeSummary s;
  {
    ProgressBar bar("encoding", "frames");
    s = encoder::encode_series(*series, o.out, job, bar.progress());
    bar.finish();
  }
  if (!job.dictionary_file.empty()) fs::remove(job.dictionary_file);
  print_encode_summary(s, c, o.out, job.psnr_target);
}

}  // namespace

void add_encode_command(CLI::App& app) {
  auto o = std::make_shared<EncodeOptions>();
  CLI::App* cmd = app.add_subcommand(
      "encode",
      "Encode a series into a NAME.vreel container (MTV-Player 3.2): per frame an octree of bricks "
      "(34^3 + 1-voxel apron,\ncoarser levels averaging 2x2x2), each brick's 6^3 blocks "
      "sparse-coded against the dictionary (variable rate: each block\nkeeps the atoms that lower "
      "its squared error by at least 0.25*216*eps^2, the rate-distortion optimal\nallocation; or, "
      "--rate-rule tolerance, atoms until its RMS error <= eps; fixed rate: S atoms) and\n"
      "quantized, or each brick coded by zfp (--codec zfp).");
  cmd->add_option(
         "SERIES", o->series,
         "Raw series directory, HDF5 file, raw file or quoted pattern of raw files (see below)")
      ->required();
  cmd->add_option("--out", o->out, "The container directory to write, e.g. turb.vreel")->required();
  cmd->add_option("--dictionary", o->dictionary,
                  "Dictionary from volreel train, or 'dct' for the DCT basis alone (no learned "
                  "atoms: nothing to\ntrain or store; for series too small to pay for a "
                  "dictionary). Default: train one with volreel train's defaults");
  cmd->add_option("--atoms", o->atoms,
                  "Without --dictionary: K of the dictionary trained here (default 0: try 1024, "
                  "512, 256, 128 and the DCT\nbasis alone, and keep the one that gives the "
                  "smallest container, dictionary included)");
  o->tolerance_opt = cmd->add_option(
      "--tolerance", o->tolerance,
      "eps, data units: an atom is kept if it lowers its block's squared error by at least\n"
      "0.25*216*eps^2 (--rate-rule tolerance: the RMS error per value of every block)");
  o->psnr_opt = cmd->add_option(
      "--psnr", o->psnr,
      "Target PSNR in dB: eps = range * 10^(-PSNR/20) to start with; a frame whose finest level "
      "falls short\n(measured after encoding) is coded again at a smaller eps, so that every "
      "frame, and the sequence, reaches it");
  o->bps_opt = cmd->add_option(
      "--bps", o->bps,
      "Search eps so that the whole container takes this many bits per voxel (within 5%)");
  o->max_error_opt = cmd->add_option(
      "--max-error", o->max_error,
      "Pointwise bound E, data units: every decoded value of the finest level within E of the "
      "original\n(blocks take atoms, bricks a finer coefficient step, until it holds; volreel "
      "compare --max-error checks it)");
  o->max_error_opt->check(CLI::PositiveNumber);
  o->tolerance_opt->excludes(o->psnr_opt)->excludes(o->bps_opt)->excludes(o->max_error_opt);
  o->psnr_opt->excludes(o->bps_opt)->excludes(o->max_error_opt);
  o->bps_opt->excludes(o->max_error_opt);
  cmd->add_option("--fixed-sparsity", o->fixed_sparsity,
                  "Fixed rate: S atoms per block (1..216) instead of a tolerance");
  o->max_atoms_opt = cmd->add_option("--max-atoms", o->max_atoms, "Smax for variable rate (1..216)")
                         ->capture_default_str();
  o->rate_rule_opt =
      cmd->add_option(
             "--rate-rule", o->rate_rule,
             "Variable rate: lagrangian (equal distortion-per-bit slope in every block: the "
             "least squared error\n"
             "for the size; blocks of aprons and padding weigh by the voxels the decoder "
             "reads from them) or\n"
             "tolerance (every block's RMS error <= eps: equal error per block)")
          ->capture_default_str();
  o->level_factor_opt = cmd->add_option("--level-factor", o->level_factor,
                                        "Lagrangian rule: code each coarser level to F times the "
                                        "eps of the level below (F^d, d levels above\nthe finest: "
                                        "coarse levels are drawn only where they are small on "
                                        "screen, and differ from the data\nby more than eps "
                                        "already); 1 codes every level to eps");
  o->level_factor_opt->check(CLI::Range(1.0, 16.0))->capture_default_str();
  cmd->add_option("--pursuit", o->pursuit,
                  "Which atom each pursuit step adds: ormp (the one that lowers the block's "
                  "squared error most: fewer atoms\nfor the same error) or omp (the one most "
                  "correlated with the residual, as in the paper; --extend-pursuit\nalways adds "
                  "that one)")
      ->check(CLI::IsMember({"ormp", "omp"}))
      ->capture_default_str();
  cmd->add_option("--mean-bits", o->mean_bits,
                  "Bits of each brick's quantized block means: auto (variable rate: per brick the "
                  "fewest bits, 0..12,\n"
                  "whose step is at most eps/2; fixed rate: 12) or 0..12 for every brick")
      ->capture_default_str();
  cmd->add_option("--coef-bits", o->coef_bits,
                  "Magnitude bits of each brick's quantized coefficients: auto (variable rate: "
                  "the step is --coef-step\ntimes eps; fixed rate: the brick's largest "
                  "coefficient / 128) or 1..16 (the step is the brick's largest\ncoefficient / "
                  "2^N)")
      ->capture_default_str();
  cmd->add_option("--coef-step", o->coef_step_factor,
                  "Variable rate: the coefficient quantization step as a multiple of eps")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_option("--atom-storage", o->atom_storage,
                  "How the container stores the dictionary's atoms: f16 (IEEE half: half the "
                  "bytes; the frames are coded\n"
                  "against the rounded atoms) or f32 (a dictionary stored in f16 stays f16)")
      ->check(CLI::IsMember({"f16", "f32"}))
      ->capture_default_str();
  cmd->add_option("--codec", o->codec, "ksvd (sparse coding) or zfp (fixed accuracy per brick)")
      ->capture_default_str();
  o->zfp_opt = cmd->add_option("--zfp-accuracy", o->zfp_accuracy,
                               "zfp absolute error tolerance (default range*1e-3)");
  cmd->add_option("--max-frames", o->max_frames, "Encode only the first N frames (0: all)");
  o->keyframe_gap_opt =
      cmd->add_option("--max-keyframe-gap", o->max_keyframe_gap,
                      "The most time steps between two stored bricks of a node: a node stores no "
                      "brick at the steps\n"
                      "between where interpolating its neighbouring keyframes meets the error "
                      "rule. 1: every step\n"
                      "stores every brick. Memory: G + 1 frames. With --bps the default is 1 (the "
                      "rate search codes\n"
                      "whole frames); without the option it is lowered where G + 1 frames would "
                      "take more than\n"
                      "half the memory")
          ->check(CLI::Range(1, 65535))
          ->capture_default_str();
  cmd->add_option("--rate-sample-frames", o->rate_sample_frames, "--bps: frames encoded per trial")
      ->capture_default_str();
  cmd->add_flag("--resume", o->resume,
                "Continue an interrupted encode: keep frames already written and valid");
  cmd->add_flag("--overwrite", o->overwrite, "Replace an existing container");
  cmd->add_flag("--no-refit", o->no_refit,
                "Quantize coefficients independently (no least-squares refit; for comparison)");
  cmd->add_flag("--extend-pursuit", o->extend,
                "--rate-rule tolerance: add atoms to blocks whose quantized error exceeds eps "
                "(quantization inside the\n"
                "pursuit): meets eps after quantization, at more bytes and half the speed");
  o->reader.add_to(*cmd);
  cmd->callback([o] { run_encode(*o); });
}

}  // namespace volreel::cli
