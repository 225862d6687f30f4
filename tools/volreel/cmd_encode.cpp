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
#include "mpi_ranks.hpp"
#include "progress.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/frame_file.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;

struct EncodeOptions {
  std::string series, dictionary, out,
      codec = "ksvd", rate_rule = "lagrangian",
      pursuit = dictionary::pursuit_name(encoder::CodingSettings{}.selection), mean_bits = "auto",
      coef_bits = "auto", atom_storage = "f16", brick_size = "auto";
  ReaderOptions reader;
  double tolerance = 0, psnr = 0, bps = 0, zfp_accuracy = 0, max_error = 0,
         level_factor = encoder::CodingSettings{}.level_tolerance_factor,
         level_detail = encoder::CodingSettings{}.level_detail_ratio,
         coef_step_factor = encoder::CodingSettings{}.coef_step_factor;
  int fixed_sparsity = 0, max_atoms = encoder::default_max_atoms, atoms = 0;
  std::size_t max_frames = 0, rate_sample_frames = 3;
  std::string memory;
  std::uint32_t max_keyframe_gap = encoder::default_max_keyframe_gap;
  bool resume = false, overwrite = false, no_refit = false, extend = false;
  CLI::Option *tolerance_opt = nullptr, *psnr_opt = nullptr, *bps_opt = nullptr, *zfp_opt = nullptr,
              *level_factor_opt = nullptr, *level_detail_opt = nullptr, *max_error_opt = nullptr,
              *max_atoms_opt = nullptr, *rate_rule_opt = nullptr, *keyframe_gap_opt = nullptr;
  const CLI::App* command = nullptr;
};

/// Options of the ksvd codec alone, refused with --codec zfp rather than ignored.
constexpr const char* ksvd_options[] = {
    "--dictionary", "--atoms",          "--tolerance",         "--psnr",
    "--bps",        "--max-error",      "--fixed-sparsity",    "--max-atoms",
    "--rate-rule",  "--level-factor",   "--level-detail",      "--pursuit",
    "--mean-bits",  "--coef-bits",      "--coef-step",         "--atom-storage",
    "--no-refit",   "--extend-pursuit", "--rate-sample-frames"};

/// The options' coding settings (the value range and ε not yet set).
encoder::CodingSettings coding_settings(const EncodeOptions& o) {
  encoder::CodingSettings c;
  c.codec = encoder::codec_from_name(o.codec);
  if (c.codec == format::Codec::zfp) {
    for (const char* name : ksvd_options)
      if (o.command->count(name) > 0)
        throw InputError(std::string(name) +
                         " applies to the ksvd codec: --codec zfp codes every brick to one "
                         "absolute accuracy, --zfp-accuracy E (default range*1e-3)");
  } else if (o.zfp_opt->count() > 0) {
    throw InputError("--zfp-accuracy applies to --codec zfp only");
  }
  c.max_atoms = o.max_atoms;
  c.fixed_sparsity = o.fixed_sparsity;
  if (c.fixed_sparsity > 0) {
    // Fixed rate takes S atoms a block whatever the error: a target or a variable-rate setting
    // beside it would be ignored.
    for (const char* name : {"--tolerance", "--psnr", "--bps", "--max-error", "--max-atoms",
                             "--rate-rule", "--coef-step", "--level-factor", "--level-detail",
                             "--rate-sample-frames", "--extend-pursuit"})
      if (o.command->count(name) > 0)
        throw InputError(std::string(name) +
                         " applies to variable rate: --fixed-sparsity S codes every block with S "
                         "atoms whatever its error (leave out one of the two)");
  }
  c.rule = encoder::rate_rule_from_name(o.rate_rule);
  if (o.extend && c.fixed_sparsity == 0 && c.rule != encoder::VariableRateRule::tolerance)
    throw InputError("--extend-pursuit needs --rate-rule tolerance");
  if (o.level_factor_opt->count() > 0 &&
      (c.fixed_sparsity > 0 || c.rule != encoder::VariableRateRule::lagrangian))
    throw InputError("--level-factor applies to variable rate with --rate-rule lagrangian only");
  if (o.level_detail_opt->count() > 0 &&
      (c.fixed_sparsity > 0 || c.rule != encoder::VariableRateRule::lagrangian))
    throw InputError("--level-detail applies to variable rate with --rate-rule lagrangian only");
  c.selection = dictionary::pursuit_from_name(o.pursuit);
  c.level_tolerance_factor = o.level_factor;
  c.level_detail_ratio = o.level_detail;
  c.mean_bits = encoder::mean_bits_from_text(o.mean_bits);
  c.coef_bits = encoder::coef_bits_from_text(o.coef_bits);
  c.coef_step_factor = o.coef_step_factor;
  c.brick_size = encoder::brick_size_from_text(o.brick_size);
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

/// The request of `volreel encode` with these options (the same on every MPI rank).
encoder::EncodeRequest encode_request(const EncodeOptions& o, std::size_t frames) {
  encoder::EncodeRequest r;
  r.coding = coding_settings(o);
  r.tolerance = tolerance_request(o);
  if (o.zfp_opt->count()) r.zfp_accuracy = o.zfp_accuracy;
  r.dictionary = o.dictionary;
  r.atoms = o.atoms;
  r.half_atoms = o.atom_storage == "f16";
  r.resume = o.resume;
  r.overwrite = o.overwrite;
  r.max_frames = frames;
  if (o.keyframe_gap_opt->count() > 0) r.max_keyframe_gap = o.max_keyframe_gap;
  if (!o.memory.empty()) {
    try {
      r.memory = format::detail::parse_byte_size(o.memory, "--memory");
    } catch (const std::invalid_argument& e) {
      throw InputError(e.what());
    }
    if (r.memory == 0) throw InputError("--memory " + o.memory + ": expected more than 0 bytes");
  }
  r.provenance = {
      {"program", "volreel " VOLREEL_VERSION}, {"series", o.series}, {"coef_bits", o.coef_bits}};
  return r;
}

void run_encode(const EncodeOptions& o) {
  // The options checked together before any input is read: a mistake there is one on the command
  // line (exit status 2), not an error of the run.
  try {
    encoder::check_request(encode_request(o, 0));
  } catch (const InputError& e) {
    throw CLI::ValidationError(e.what());
  }
  // Under mpirun every rank runs this with the same options; rank 0 alone prints.
  const encoder::Ranks* ranks = mpi_ranks();
  const auto series = datasets::open_series(o.series, o.reader.to_open_options());
  const auto& info = series->info();
  const std::size_t frames = o.max_frames ? std::min(o.max_frames, info.frames) : info.frames;
  if (ranks && !ranks->root()) {
    encoder::EncodeRequest r = encode_request(o, frames);
    r.ranks = ranks;
    encoder::encode(*series, o.out, r);
    const std::uint64_t rss = peak_resident_bytes();
    ranks->gather({&rss, 1});
    return;
  }
  std::printf("volreel encode: %s, %s x %zu frames, variable '%s'\n", info.source.c_str(),
              to_string(info.dims).c_str(), frames, info.variable.c_str());
  if (ranks)
    std::printf(
        "%d MPI processes, each coding a share of the frames (frames coded piecewise are shared "
        "brick by brick when there are fewer keyframe stretches than processes)\n",
        ranks->size());
  encoder::EncodeRequest r = encode_request(o, frames);
  r.ranks = ranks;
  encoder::EncodeEvents events;
  events.message = [](const std::string& line) { std::printf("%s\n", line.c_str()); };
  std::optional<ProgressBar> bar;
  events.stage = [&](const std::string& stage, const std::string& unit) {
    return bar.emplace(stage, unit).progress();
  };
  events.stage_done = [&] {
    if (bar) bar->finish();
    bar.reset();
  };
  events.candidate = [&](const encoder::DictionaryCandidate& k) {
    if (k.past_minimum)
      std::printf(
          "  K = %4d: not trained: the estimate rose with each of the last %d sizes (smallest so "
          "far %.0f bytes)\n",
          k.atoms, encoder::max_rising_estimates, k.best_bytes);
    else if (k.skipped)
      std::printf(
          "  K = %4d: not trained: its dictionary alone (%.0f bytes) is at least the smallest "
          "container estimated so far (%.0f bytes)\n",
          k.atoms, k.dictionary_bytes, k.best_bytes);
    else if (o.atoms == 0 && k.atoms == 0)
      std::printf("  the DCT basis alone: estimated container %.0f bytes (dictionary %.0f)\n",
                  k.estimated_bytes, k.dictionary_bytes);
    else if (o.atoms == 0)
      std::printf(
          "  K = %4d: trained in %.1f s; estimated container %.0f bytes (dictionary %.0f)\n",
          k.atoms, k.train_seconds, k.estimated_bytes, k.dictionary_bytes);
    else
      std::printf("  K = %4d: trained in %.1f s\n", k.atoms, k.train_seconds);
  };
  events.tolerance_chosen = [&](const encoder::ToleranceChoice& eps,
                                const encoder::CodingSettings& c, std::uint32_t atoms) {
    print_tolerance_choice(eps, c, o.bps, encoder::tolerance_range(c.value_min, c.value_max),
                           atoms);
  };
  // One process: Ctrl-C or SIGTERM stops at the next progress update, between frames, so that
  // the frames written so far stay complete for --resume (under mpirun the ranks would not stop
  // together: the signal ends them at once, and --resume removes what they left half-written).
  std::optional<StopOnSignal> stop;
  if (!ranks) stop.emplace();
  const bool out_existed = std::filesystem::exists(o.out);
  const std::filesystem::path next = encoder::replacement_folder(o.out);
  const bool replacing = encoder::replaces_container(o.out, o.overwrite, o.resume);
  const encoder::EncodeSummary s = [&] {
    try {
      return encoder::encode(*series, o.out, r, events);
    } catch (const Interrupted&) {
      if (bar) bar.reset();
      // Stopped before its first frame (while the value range or the dictionary was found): a
      // container this run made holds nothing to continue, and goes.
      std::error_code ec;
      const std::filesystem::path where = replacing ? next : std::filesystem::path(o.out);
      std::size_t written = 0;
      try {
        const format::Container kept(where, true);
        for (const auto& frame : kept.manifest().frames) written += frame.has_value();
      } catch (const std::exception&) {  // no manifest yet
      }
      if (written == 0 && replacing) std::filesystem::remove_all(next, ec);
      if (written == 0 && !out_existed) std::filesystem::remove_all(o.out, ec);
      const std::string old =
          replacing ? "; " + o.out + " still holds the container it would replace" : "";
      if (written == 0)
        std::fprintf(stderr, "\nvolreel encode: interrupted before its first frame was written%s\n",
                     old.c_str());
      else
        std::fprintf(stderr,
                     "\nvolreel encode: interrupted: the %zu frames written to %s are kept%s; the "
                     "same command with --resume%s continues it\n",
                     written, where.c_str(), old.c_str(),
                     o.overwrite ? " instead of --overwrite" : "");
      throw;
    }
  }();
  stop.reset();
  const bool missed = print_encode_summary(s, s.coding, o.out, r.tolerance.psnr.value_or(0),
                                           r.tolerance.bps.value_or(0));
  const std::uint64_t rss = peak_resident_bytes();
  const std::vector<std::uint64_t> each =
      ranks ? ranks->gather({&rss, 1}) : std::vector<std::uint64_t>{rss};
  std::string line = ranks ? "peak resident memory per rank:" : "peak resident memory:";
  for (const std::uint64_t b : each) line += " " + std::to_string((b + (1u << 19)) >> 20) + " MiB";
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
  if (missed)
    throw TargetMissed("the container " + o.out +
                       " is complete and valid, but misses its target (the warning above): exit "
                       "status " +
                       std::to_string(target_missed_status));
}

}  // namespace

void add_encode_command(CLI::App& app) {
  auto o = std::make_shared<EncodeOptions>();
  CLI::App* cmd = app.add_subcommand(
      "encode",
      "Encode a series into a NAME.vreel container (MTV-Player 3.2): per frame an octree of bricks "
      "(B^3 stored voxels:\n(B-2)^3 interior + 1-voxel apron, coarser levels averaging 2x2x2), "
      "each brick's 6^3 blocks "
      "sparse-coded against the dictionary (variable rate: each block\nkeeps the atoms that lower "
      "its squared error by at least 0.25*216*eps^2, the rate-distortion optimal\nallocation; or, "
      "--rate-rule tolerance, atoms until its RMS error <= eps; fixed rate: S atoms) and\n"
      "quantized, or each brick coded by zfp (--codec zfp).\nUnder mpirun -n N the ranks share "
      "the frames and write the same container as one process;\nframes coded piecewise "
      "(--memory) are shared brick by brick when there are fewer keyframe stretches\nthan "
      "ranks.\nExit status: 0; 3 when the container is written and valid but misses --psnr, "
      "--bps (by more than\n5 %) or --max-error (a warning says by how much); any other non-zero "
      "status is an error (130:\ninterrupted), after which nothing half-written is left.");
  cmd->add_option(
         "SERIES", o->series,
         "Raw series directory, HDF5 or NetCDF file, raw file or quoted pattern of raw files (see "
         "below)")
      ->required();
  cmd->add_option("--out", o->out, "The container directory to write, e.g. turb.vreel")->required();
  CLI::Option* dictionary_opt = cmd->add_option(
      "--dictionary", o->dictionary,
      "Dictionary from volreel train, or 'dct' for the DCT basis alone (no learned "
      "atoms: nothing to\ntrain or store; for series too small to pay for a "
      "dictionary). Default: train one, at the tolerance below (without one: that of\n55 dB PSNR), "
      "with volreel train's other defaults");
  cmd->add_option("--atoms", o->atoms,
                  "Without --dictionary: K of the dictionary trained here (default 0: try the "
                  "DCT basis alone and 128, 256,\n512 and 1024 atoms, and keep the one that gives "
                  "the smallest container, dictionary included;\na K whose dictionary alone is "
                  "at least the smallest container estimated so far is not trained, nor\nthe sizes "
                  "after two in a row whose estimate rose)")
      ->check(in_range(0, 65536))
      ->excludes(dictionary_opt);
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
  o->max_error_opt->check(positive());
  o->tolerance_opt->check(positive());
  o->psnr_opt->check(positive());
  o->bps_opt->check(positive());
  o->tolerance_opt->excludes(o->psnr_opt)->excludes(o->bps_opt)->excludes(o->max_error_opt);
  o->psnr_opt->excludes(o->bps_opt)->excludes(o->max_error_opt);
  o->bps_opt->excludes(o->max_error_opt);
  cmd->add_option("--fixed-sparsity", o->fixed_sparsity,
                  "Fixed rate: S atoms per block (1..216) instead of a tolerance")
      ->check(CLI::Range(1, 216));
  o->max_atoms_opt = cmd->add_option("--max-atoms", o->max_atoms, "Smax for variable rate (1..216)")
                         ->check(CLI::Range(1, 216))
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
  o->level_factor_opt->check(in_range(1, 16))->capture_default_str();
  o->level_detail_opt = cmd->add_option(
      "--level-detail", o->level_detail,
      "Lagrangian rule: also code a brick above the finest level to R times what its "
      "downsampling lost\n(delta, the RMS difference between the data and the brick's voxels) "
      "where that is coarser than\neps*F^d: at small eps coarse levels then leave their bits to "
      "the finest, and their drawing\nstays within sqrt(1 + R^2)*delta of the data; 0: eps*F^d "
      "alone");
  o->level_detail_opt->check(in_range(0, 4))->capture_default_str();
  cmd->add_option("--pursuit", o->pursuit,
                  "Which atom each pursuit step adds: ormp (the one that lowers the block's "
                  "squared error most: fewer atoms\nfor the same error) or omp (the one most "
                  "correlated with the residual, as in the paper; --extend-pursuit\nalways adds "
                  "that one)")
      ->check(CLI::IsMember({"ormp", "omp"}))
      ->capture_default_str();
  cmd->add_option("--mean-bits", o->mean_bits,
                  "Bits of each brick's quantized block means: auto (variable rate: per brick the "
                  "fewest bits, 0..15,\n"
                  "whose step is at most eps/2; fixed rate: 12) or 0..15 for every brick")
      ->capture_default_str();
  cmd->add_option("--coef-bits", o->coef_bits,
                  "Magnitude bits of each brick's quantized coefficients: auto (variable rate: "
                  "the step is --coef-step\ntimes eps; fixed rate: the brick's largest "
                  "coefficient / 128) or 1..16 (the step is the brick's largest\ncoefficient / "
                  "2^N)")
      ->capture_default_str();
  cmd->add_option("--coef-step", o->coef_step_factor,
                  "Variable rate: the coefficient quantization step as a multiple of eps")
      ->check(positive())
      ->capture_default_str();
  cmd->add_option("--atom-storage", o->atom_storage,
                  "How the container stores the dictionary's atoms: f16 (IEEE half: half the "
                  "bytes; the frames are coded\n"
                  "against the rounded atoms) or f32 (a dictionary stored in f16 stays f16)")
      ->check(CLI::IsMember({"f16", "f32"}))
      ->capture_default_str();
  cmd->add_option(
         "--brick-size", o->brick_size,
         "B, stored voxels per brick axis: a multiple of 6 in 12..66, or auto: the size "
         "whose bricks, over\nall levels, store the fewest 6^3 blocks (with voxels of the "
         "volume or just past it; 66,\ninterior 64, for power-of-two sizes from 64 up; the "
         "smaller of near ties)")
      ->capture_default_str();
  cmd->add_option("--codec", o->codec, "ksvd (sparse coding) or zfp (fixed accuracy per brick)")
      ->capture_default_str();
  o->zfp_opt = cmd->add_option("--zfp-accuracy", o->zfp_accuracy,
                               "zfp absolute error tolerance (default range*1e-3)");
  o->zfp_opt->check(positive());
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
                      "--memory")
          ->check(CLI::Range(1, 65535))
          ->capture_default_str();
  cmd->add_option("--memory", o->memory,
                  "The memory the encode may hold for frames, e.g. 2G, 512M (default: half the "
                  "machine's, or of its\ncontainer's limit where lower). Frames that do\n"
                  "not fit whole (twice their float32 size) are read and coded piecewise, a row "
                  "of bricks at a time,\n"
                  "with keyframe gap 1 and a dictionary given; smaller frames lower the default "
                  "keyframe gap to fit,\nand frames of a few bricks are coded side by side, "
                  "as many ahead of their keyframe stretch as fit");
  cmd->add_option("--rate-sample-frames", o->rate_sample_frames,
                  "--bps: frames encoded per trial, evenly spaced; the eps found is checked on as "
                  "many others\n(twice at most) and searched again where they disagree")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 20))
      ->capture_default_str();
  CLI::Option* resume_opt =
      cmd->add_flag("--resume", o->resume,
                    "Continue an interrupted encode (or an interrupted --overwrite of a\n"
                    "container): keep frames already written and valid");
  cmd->add_flag("--overwrite", o->overwrite,
                "Replace an existing container: the new one is written beside it (in\n"
                "OUT/.volreel-new) and takes its place once complete, so a failed or\n"
                "interrupted run leaves the old one whole (room for both is needed)")
      ->excludes(resume_opt);
  cmd->add_flag(
      "--no-refit", o->no_refit,
      "Quantize coefficients independently (no least-squares refit; for comparison; with the DCT "
      "basis alone, whose atoms are orthonormal, the refit changes nothing)");
  cmd->add_flag("--extend-pursuit", o->extend,
                "--rate-rule tolerance: add atoms to blocks whose quantized error exceeds eps "
                "(quantization inside the\n"
                "pursuit): meets eps after quantization, at more bytes and half the speed");
  o->reader.add_to(*cmd);
  o->reader.add_spacing_to(*cmd);
  o->command = cmd;
  cmd->callback([o] { run_encode(*o); });
}

}  // namespace volreel::cli
