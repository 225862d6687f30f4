// cmd_encode.cpp: `volreel encode` (series -> NAME.vreel container), `volreel info`, `volreel
// verify` and `volreel decode` (a frame at any level -> raw float32, by the CPU reference decoder).
#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/encoder.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/error.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr double default_psnr = 55.0;  ///< when neither the dictionary nor the user says

struct EncodeOptions {
  std::string series, dictionary, out, codec = "ksvd", rate_rule = "lagrangian",
              pursuit = dictionary::pursuit_name(encoder::CodingSettings{}.selection), mean_bits = "auto",
              atom_storage = "f16";
  ReaderOptions reader;
  double tolerance = 0, psnr = 0, bps = 0, zfp_accuracy = 0,
         level_factor = encoder::CodingSettings{}.level_tolerance_factor;
  int fixed_sparsity = 0, max_atoms = 15, atoms = 0;
  std::size_t max_frames = 0, rate_sample_frames = 3;
  bool resume = false, overwrite = false, no_refit = false, no_interval = false, extend = false;
  CLI::Option *tolerance_opt = nullptr, *psnr_opt = nullptr, *bps_opt = nullptr, *zfp_opt = nullptr,
              *level_factor_opt = nullptr;
};

format::DictionaryTraining provenance(const dictionary::CoresetOptions& co,
                                      const dictionary::TrainingOptions& to,
                                      const dictionary::CoresetHierarchy& h,
                                      const dictionary::TrainingResult& r) {
  format::DictionaryTraining t;
  t.tolerance = to.coding.tolerance;
  t.value_min = h.value_min;
  t.value_max = h.value_max;
  t.max_sparsity = static_cast<std::uint32_t>(to.coding.max_atoms);
  t.coreset_voxels = co.coreset_voxels;
  t.coreset_levels = static_cast<std::uint32_t>(co.levels);
  t.iterations = static_cast<std::uint32_t>(r.total_iterations);
  t.seed = to.seed;
  t.training_frames = static_cast<std::uint32_t>(h.frames.size());
  t.rms_error = r.final_stats.rms_error;
  t.mean_sparsity = r.final_stats.mean_sparsity;
  return t;
}

/// Trains a dictionary with volreel train's defaults at ε and writes it to path. atoms > 0: that K.
/// atoms = 0: the dictionary counts in bps, so K is chosen by measured total size — for K = 1024,
/// 512, 256, 128 a dictionary is trained, `sample` frames are encoded at ε, and the K with the
/// smallest estimated container (frames · mean frame size + dictionary file, its atoms stored in
/// binary16 if `half`, as the container will store them) wins.
void train_default_dictionary(const datasets::SeriesReader& series, double eps, int atoms,
                              std::size_t frames, const encoder::CodingSettings& coding,
                              std::size_t sample, bool half, const fs::path& path) {
  dictionary::CoresetOptions co;
  dictionary::CoresetHierarchy h;
  {
    ProgressBar bar("coreset", "frames");
    h = dictionary::build_coreset_hierarchy(series, co, bar.progress());
    bar.finish();
  }
  std::vector<Volume> samples;
  const std::size_t n = std::min(sample, frames);
  for (std::size_t i = 0; i < n && atoms == 0; ++i)
    samples.push_back(series.read_frame(n == 1 ? frames / 2 : i * (frames - 1) / (n - 1)));
  double best_total = std::numeric_limits<double>::infinity();
  for (int k : atoms > 0 ? std::vector<int>{atoms} : std::vector<int>{1024, 512, 256, 128}) {
    dictionary::TrainingOptions to;
    to.atom_count = k;
    to.coding.tolerance = eps;
    const auto start = Clock::now();
    const auto r = dictionary::train_dictionary(h, to);
    const double train_s = std::chrono::duration<double>(Clock::now() - start).count();
    const double dict_bytes =
        static_cast<double>(format::dictionary_file_size(static_cast<std::uint64_t>(k), 216, half));
    double total = dict_bytes;
    if (atoms == 0) {
      auto c = coding;
      c.tolerance = eps;
      c.fixed_sparsity = 0;
      auto stored = r.dictionary;
      if (half)
        stored = dictionary::from_file(
            format::with_half_atoms(dictionary::to_file(r.dictionary, format::DictionaryTraining{})));
      const encoder::FrameEncoder enc(&stored, c);
      double bytes = 0;
      for (std::size_t i = 0; i < samples.size(); ++i)
        bytes += static_cast<double>(enc.encode(i, samples[i]).size());
      total += bytes / static_cast<double>(samples.size()) * static_cast<double>(frames);
      std::printf(
          "  K = %4d: trained in %.1f s; estimated container %.0f bytes (dictionary %.0f)\n", k,
          train_s, total, dict_bytes);
    } else {
      std::printf("  K = %4d: trained in %.1f s\n", k, train_s);
    }
    if (total < best_total) {
      best_total = total;
      dictionary::save_dictionary(path, r.dictionary, provenance(co, to, h, r));
    }
  }
  const auto chosen = format::read_dictionary_file(path);
  std::printf("using the dictionary of K = %u atoms (eps %.4g)\n", chosen.atom_count, eps);
}

/// Where the frame files' bytes went, and the atoms per block (ksvd).
void print_breakdown(const encoder::EncodeSummary& s) {
  const encoder::ByteBreakdown& b = s.breakdown;
  const double total = static_cast<double>(b.total());
  if (!(total > 0)) return;
  const auto share = [&](double bytes) { return 100.0 * bytes / total; };
  std::printf("frame bytes (%zu frames encoded): ", s.encoded);
  const std::pair<const char*, std::size_t> parts[] = {
      {"frame tables", b.frame_tables},   {"constant bricks", b.constant_bricks},
      {"brick headers", b.brick_headers}, {"block means+counts", b.block_entries},
      {"codes", b.codes},                 {"alignment", b.alignment},
      {"zfp streams", b.zfp_streams}};
  bool first = true;
  for (const auto& [name, bytes] : parts) {
    if (bytes == 0) continue;
    std::printf("%s%s %.1f%%", first ? "" : ", ", name, share(static_cast<double>(bytes)));
    first = false;
  }
  std::printf("; coarse levels %.1f%%, aprons and padding about %.1f%% (of all frame bytes)\n",
              share(static_cast<double>(b.coarse_levels)), share(b.aprons_and_padding));
  if (b.codes > 0) {
    std::printf("codes of the finest level's own voxels (interior, inside the volume): %.1f%% of the frame bytes",
                share(b.finest_owned_codes));
    // In bps when this run wrote every frame (the container's bytes are then all accounted for).
    if (s.skipped == 0 && s.container_bytes > 0)
      std::printf(", %.4f bps", s.bps * b.finest_owned_codes / static_cast<double>(s.container_bytes));
    std::printf("\n");
  }
  std::size_t blocks = 0, codes = 0;
  for (std::size_t k = 0; k < s.sparsity_histogram.size(); ++k)
    blocks += s.sparsity_histogram[k], codes += k * s.sparsity_histogram[k];
  if (blocks == 0) return;
  std::printf("atoms per block: mean %.2f; blocks with 0..15 atoms (%%):",
              static_cast<double>(codes) / static_cast<double>(blocks));
  for (std::size_t count : s.sparsity_histogram)
    std::printf(" %.1f", 100.0 * static_cast<double>(count) / static_cast<double>(blocks));
  std::size_t bricks = 0, bits = 0;
  for (std::size_t k = 0; k < s.mean_bits_histogram.size(); ++k)
    bricks += s.mean_bits_histogram[k], bits += k * s.mean_bits_histogram[k];
  std::printf("\nmean bits per brick: mean %.2f; bricks with 0..12 bits (%%):",
              static_cast<double>(bits) / static_cast<double>(std::max<std::size_t>(bricks, 1)));
  for (std::size_t count : s.mean_bits_histogram)
    std::printf(" %.1f", 100.0 * static_cast<double>(count) /
                             static_cast<double>(std::max<std::size_t>(bricks, 1)));
  std::printf("\n");
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
  auto& c = job.coding;
  if (o.codec == "ksvd")
    c.codec = format::Codec::ksvd;
  else if (o.codec == "zfp")
    c.codec = format::Codec::zfp;
  else
    throw InputError("--codec must be ksvd or zfp, not '" + o.codec + "'");
  c.max_atoms = o.max_atoms;
  c.fixed_sparsity = o.fixed_sparsity;
  if (o.rate_rule == "lagrangian")
    c.rule = encoder::VariableRateRule::lagrangian;
  else if (o.rate_rule == "tolerance")
    c.rule = encoder::VariableRateRule::tolerance;
  else
    throw InputError("--rate-rule must be lagrangian or tolerance, not '" + o.rate_rule + "'");
  if (o.extend && c.fixed_sparsity == 0 && c.rule != encoder::VariableRateRule::tolerance)
    throw InputError("--extend-pursuit needs --rate-rule tolerance");
  if (o.level_factor_opt->count() > 0 &&
      (c.fixed_sparsity > 0 || c.rule != encoder::VariableRateRule::lagrangian))
    throw InputError("--level-factor applies to variable rate with --rate-rule lagrangian only");
  c.selection = dictionary::pursuit_from_name(o.pursuit);
  c.level_tolerance_factor = o.level_factor;
  job.half_atoms = o.atom_storage == "f16";
  if (o.mean_bits == "auto") {
    c.mean_bits = -1;
  } else {
    char* end = nullptr;
    const long bits = std::strtol(o.mean_bits.c_str(), &end, 10);
    if (o.mean_bits.empty() || *end != '\0' || bits < 0 || bits > 12)
      throw InputError("--mean-bits must be auto or a whole number 0..12, not '" + o.mean_bits + "'");
    c.mean_bits = static_cast<int>(bits);
  }
  c.refit_quantization = !o.no_refit;
  c.extend_pursuit = o.extend;
  c.optimize_interval = !o.no_interval;
  {
    ProgressBar bar("value range", "frames");
    std::tie(c.value_min, c.value_max) = encoder::value_range(*series, frames, bar.progress());
    bar.finish();
  }
  const double range = c.value_max - c.value_min;
  std::printf("value range [%.6g, %.6g]\n", c.value_min, c.value_max);

  if (c.codec == format::Codec::zfp) {
    c.zfp_accuracy = o.zfp_opt->count() ? o.zfp_accuracy : range * 1e-3;
    std::printf("codec zfp, fixed accuracy %.4g per brick\n", c.zfp_accuracy);
  } else {
    // The dictionary: given, the container's own (resume), or trained here.
    fs::path dict_path = o.dictionary;
    fs::path trained;
    if (dict_path.empty() && o.resume && fs::exists(fs::path(o.out) / "dictionary.bin"))
      dict_path = fs::path(o.out) / "dictionary.bin";
    double eps_hint =
        o.tolerance_opt->count()
            ? o.tolerance
            : dictionary::tolerance_for_psnr(o.psnr_opt->count() ? o.psnr : default_psnr, range);
    if (dict_path.empty()) {
      trained =
          fs::temp_directory_path() / ("volreel-dictionary-" + std::to_string(::getpid()) + ".bin");
      std::printf(
          "no --dictionary given: training one with volreel train's defaults at eps %.4g, %s\n",
          eps_hint,
          o.atoms ? ("K = " + std::to_string(o.atoms)).c_str()
                  : "K chosen by the total size it gives (--atoms to fix it)");
      train_default_dictionary(*series, eps_hint, o.atoms, frames, c, o.rate_sample_frames,
                               o.atom_storage == "f16",
                               trained);
      dict_path = trained;
    }
    // A copy, so that the container's own dictionary.bin can be used to resume.
    const fs::path copy = fs::temp_directory_path() /
                          ("volreel-dictionary-copy-" + std::to_string(::getpid()) + ".bin");
    fs::copy_file(dict_path, copy, fs::copy_options::overwrite_existing);
    if (!trained.empty()) fs::remove(trained);
    job.dictionary_file = copy;
    auto file = format::read_dictionary_file(copy);
    if (job.half_atoms && !file.half_atoms) {
      // Stored as the container will store it, so that --bps measures what the encode writes.
      file = format::with_half_atoms(std::move(file));
      format::write_dictionary_file(copy, file);
    }
    // ε: --tolerance, --psnr, --bps, else the dictionary's training ε, else PSNR 55 dB.
    if (c.fixed_sparsity > 0) {
      std::printf("fixed rate: %d atoms per block\n", c.fixed_sparsity);
    } else if (o.tolerance_opt->count()) {
      c.tolerance = o.tolerance;
    } else if (o.psnr_opt->count()) {
      c.tolerance = dictionary::tolerance_for_psnr(o.psnr, range);
    } else if (o.bps_opt->count()) {
      const auto dict = dictionary::from_file(file);
      c.tolerance = range * 1e-3;
      ProgressBar bar("rate control", "steps");
      const auto r = encoder::search_tolerance(*series, dict, fs::file_size(copy), c, o.bps, frames,
                                               o.rate_sample_frames, 0.03, bar.progress());
      bar.finish();
      c.tolerance = r.tolerance;
      std::printf(
          "rate control: eps %.4g gives an estimated %.4f bps (target %.4f) after %d trial encodes "
          "of %zu frames\n",
          r.tolerance, r.estimated_bps, o.bps, r.iterations,
          std::min(o.rate_sample_frames, frames));
    } else if (file.training.tolerance > 0) {
      c.tolerance = file.training.tolerance;
      std::printf("tolerance from the dictionary's training: ");
    } else {
      c.tolerance = dictionary::tolerance_for_psnr(default_psnr, range);
    }
    if (c.fixed_sparsity == 0 && c.rule == encoder::VariableRateRule::tolerance)
      std::printf(
          "tolerance eps %.4g, eps rule (PSNR >= %.2f dB before quantization if every block meets "
          "it), K = %u\n",
          c.tolerance, dictionary::psnr_for_tolerance(c.tolerance, range), file.atom_count);
    else if (c.fixed_sparsity == 0)
      std::printf(
          "tolerance eps %.4g, Lagrangian rule: a block keeps an atom if it lowers its squared "
          "error by >= %.3g (%g*216*eps^2; nominal PSNR %.2f dB), K = %u\n",
          c.tolerance, c.lagrangian_factor * 216 * c.tolerance * c.tolerance, c.lagrangian_factor,
          dictionary::psnr_for_tolerance(c.tolerance, range), file.atom_count);
  }
  job.provenance = {
      {"program", "volreel " VOLREEL_VERSION},      {"series", o.series},
      {"refit_quantization", c.refit_quantization}, {"extend_pursuit", c.extend_pursuit},
      {"optimize_interval", c.optimize_interval},   {"max_atoms", c.max_atoms}};
  // encode_series adds the variable-rate rule and its parameters.
  encoder::EncodeSummary s;
  {
    ProgressBar bar("encoding", "frames");
    s = encoder::encode_series(*series, o.out, job, bar.progress());
    bar.finish();
  }
  if (!job.dictionary_file.empty()) fs::remove(job.dictionary_file);
  std::printf(
      "encoding time: pyramid %.2f s, brick extraction + histograms %.2f s, batch-OMP %.2f s, "
      "quantization %.2f s, "
      "other (reading excluded) %.2f s\n",
      s.seconds_pyramid, s.seconds_bricks, s.seconds_omp, s.seconds_quantize,
      s.seconds - s.seconds_pyramid - s.seconds_bricks - s.seconds_omp - s.seconds_quantize);
  if (s.unquantized_squared_error > 0)
    std::printf(
        "quantization: %.3f dB lost against the unquantized sparse approximation (squared error "
        "over all coded blocks, "
        "every level; refit %s, optimized interval %s, pursuit extension %s)\n",
        10 * std::log10(s.quantized_squared_error / s.unquantized_squared_error),
        c.refit_quantization ? "on" : "off", c.optimize_interval ? "on" : "off",
        c.extend_pursuit && c.fixed_sparsity == 0 &&
                c.rule == encoder::VariableRateRule::tolerance
            ? "on"
            : "off");
  print_breakdown(s);
  std::printf(
      "wrote %s: %zu frames (%zu encoded, %zu already there), %ju bytes, %.4f bps; encoding %.1f "
      "s, %.2f MVoxel/s on %d threads\n",
      o.out.c_str(), s.frames, s.encoded, s.skipped, static_cast<std::uintmax_t>(s.container_bytes),
      s.bps, s.seconds, s.mvoxels_per_s, omp_get_max_threads());
}

void run_info(const std::string& dir, bool json) {
  const format::Container c(dir, true);
  const auto& m = c.manifest();
  const double voxels = static_cast<double>(m.dims[0]) * m.dims[1] * m.dims[2];
  std::size_t written = 0;
  for (const auto& f : m.frames) written += f ? 1u : 0u;
  const std::uint64_t bytes = c.total_bytes();
  const double bps = 8.0 * static_cast<double>(bytes) /
                     (voxels * static_cast<double>(std::max<std::size_t>(written, 1)));
  nlohmann::json levels = nlohmann::json::array();
  if (written > 0 && m.frames[0]) {
    const auto f = c.open_frame(0);
    for (std::uint32_t l = 0; l < f.view().level_count(); ++l) {
      const auto& e = f.view().level(l);
      levels.push_back({{"level", l},
                        {"dims", e.dims},
                        {"grid", e.grid},
                        {"nodes", e.node_count},
                        {"payload_bytes", f.view().payload_end_for_depth(l + 1) -
                                              f.view().payload_end_for_depth(l)}});
    }
  }
  if (json) {
    nlohmann::json j = format::manifest_to_json(m);
    j["total_bytes"] = bytes;
    j["bps"] = bps;
    j["frames_written"] = written;
    j["frame0_levels"] = levels;
    std::cout << j.dump(2) << '\n';
    return;
  }
  std::printf("%s: volreel container, format version %u, written by volreel %s%s\n", dir.c_str(),
              m.format_version, m.program_version.c_str(),
              m.complete ? "" : " (INCOMPLETE: resume with volreel encode --resume)");
  std::printf("volume   %ux%ux%u, spacing %g %g %g, variable '%s', %zu frames (%zu written)\n",
              m.dims[0], m.dims[1], m.dims[2], m.spacing[0], m.spacing[1], m.spacing[2],
              m.variable.c_str(), m.frames.size(), written);
  std::printf("octree   %u levels, bricks of %u^3 (%u interior + %u apron)\n", m.levels,
              m.brick_size, m.brick_size - 2 * m.brick_apron, m.brick_apron);
  if (m.codec == format::Codec::ksvd) {
    std::printf("codec    ksvd (sparse coding, blocks of %u^3), ", m.block_size);
    if (m.fixed_sparsity)
      std::printf("fixed rate S = %u\n", m.fixed_sparsity);
    else
      std::printf("variable rate, eps = %.6g\n", m.tolerance);
    std::printf("dictionary %s: %u atoms, %ju bytes\n", m.dictionary->file.c_str(),
                m.dictionary->atom_count, static_cast<std::uintmax_t>(m.dictionary->bytes));
  } else {
    std::printf("codec    zfp fixed accuracy %.6g\n", m.zfp_accuracy);
  }
  std::printf("values   [%.6g, %.6g]\n", m.value_min, m.value_max);
  std::printf("size     %ju bytes, %.4f bps (all files, over the %zu frames written)\n",
              static_cast<std::uintmax_t>(bytes), bps, written);
  for (const auto& l : levels)
    std::printf("frame 0 level %d: %s voxels, %d nodes, %ju payload bytes\n", l["level"].get<int>(),
                l["dims"].dump().c_str(), l["nodes"].get<int>(),
                static_cast<std::uintmax_t>(l["payload_bytes"].get<std::uint64_t>()));
}

void run_verify(const std::string& dir) {
  ProgressBar bar("verifying", "frames");
  const auto problems = format::verify_container(
      dir,
      [](std::size_t done, std::size_t total, void* user) {
        static_cast<ProgressBar*>(user)->update(
            {static_cast<double>(done), static_cast<double>(total), {}});
      },
      &bar);
  bar.finish();
  for (const auto& p : problems) std::fprintf(stderr, "%s\n", p.c_str());
  if (!problems.empty())
    throw InputError(dir + ": " + std::to_string(problems.size()) + " problem(s) found");
  std::printf("%s: OK (manifest, dictionary, every frame's CRC-32C, index and brick payloads)\n",
              dir.c_str());
}

struct DecodeOptions {
  std::string dir, out;
  std::size_t frame = 0;
  int level = -1;
  int repeat = 1;
};

void run_decode(const DecodeOptions& o) {
  const format::Container c(o.dir);
  const auto f = c.open_frame(o.frame);
  const std::uint32_t levels = f.view().level_count();
  const std::uint32_t level = o.level < 0 ? levels - 1 : static_cast<std::uint32_t>(o.level);
  if (level >= levels)
    throw InputError("--level " + std::to_string(o.level) + ": the frame has levels 0.." +
                     std::to_string(levels - 1));
  format::LevelVolume v;
  const auto& e = f.view().level(level);
  v.dims = {e.dims[0], e.dims[1], e.dims[2]};
  v.data.resize(std::size_t{e.dims[0]} * e.dims[1] * e.dims[2]);
  // Timed: decoding into the allocated volume, the best of --repeat runs.
  double seconds = 1e30;
  for (int r = 0; r < std::max(1, o.repeat); ++r) {
    const auto start = Clock::now();
    format::decode_level(f.view(), level, c.atoms(), v.data);
    seconds = std::min(seconds, std::chrono::duration<double>(Clock::now() - start).count());
  }
  std::ofstream out(o.out, std::ios::binary);
  out.write(reinterpret_cast<const char*>(v.data.data()),
            static_cast<std::streamsize>(v.data.size() * sizeof(float)));
  if (!out) throw InputError("cannot write '" + o.out + "'");
  std::printf(
      "wrote %s: frame %zu level %u, %ux%ux%u float32 (x fastest); decoded in %.4f s (%.1f "
      "MVoxel/s of output; best of %d, %d threads)\n",
      o.out.c_str(), o.frame, level, v.dims[0], v.dims[1], v.dims[2], seconds,
      static_cast<double>(v.data.size()) / 1e6 / seconds, std::max(1, o.repeat),
      omp_get_max_threads());
}

}  // namespace

void add_encode_command(CLI::App& app) {
  auto o = std::make_shared<EncodeOptions>();
  CLI::App* cmd = app.add_subcommand("encode",
                                     "Encode a series into a NAME.vreel container (MTV-Player "
                                     "3.2): per frame an octree of bricks (34^3 + 1-voxel apron,\n"
                                     "coarser levels averaging 2x2x2), each brick's 6^3 blocks "
                                     "sparse-coded against the dictionary (variable rate: each block\n"
                                     "keeps the atoms that lower its squared error by at least "
                                     "0.25*216*eps^2, the rate-distortion optimal\n"
                                     "allocation; or, --rate-rule tolerance, atoms until its RMS "
                                     "error <= eps; fixed rate: S atoms) and\n"
                                     "quantized, or each brick coded by zfp (--codec zfp).");
  cmd->add_option("SERIES", o->series, "Raw series directory, HDF5 file or raw file")->required();
  cmd->add_option("--out", o->out, "The container directory to write, e.g. turb.vreel")->required();
  cmd->add_option("--dictionary", o->dictionary,
                  "Dictionary from volreel train (default: train one with its defaults)");
  cmd->add_option("--atoms", o->atoms,
                  "Without --dictionary: K of the dictionary trained here (default 0: try 1024, "
                  "512, 256, 128 and keep the K\n"
                  "that gives the smallest container, dictionary included)");
  o->tolerance_opt = cmd->add_option(
      "--tolerance", o->tolerance,
      "eps, data units: an atom is kept if it lowers its block's squared error by at least\n"
      "0.25*216*eps^2 (--rate-rule tolerance: the RMS error per value of every block)");
  o->psnr_opt = cmd->add_option("--psnr", o->psnr, "eps = range * 10^(-PSNR/20)");
  o->bps_opt = cmd->add_option(
      "--bps", o->bps,
      "Search eps so that the whole container takes this many bits per voxel (within 5%)");
  o->tolerance_opt->excludes(o->psnr_opt)->excludes(o->bps_opt);
  o->psnr_opt->excludes(o->bps_opt);
  cmd->add_option("--fixed-sparsity", o->fixed_sparsity,
                  "Fixed rate: S atoms per block (1..15) instead of a tolerance");
  cmd->add_option("--max-atoms", o->max_atoms, "Smax for variable rate (1..15)")
      ->capture_default_str();
  cmd->add_option("--rate-rule", o->rate_rule,
                  "Variable rate: lagrangian (equal distortion-per-bit slope in every block: the "
                  "least squared error\n"
                  "for the size; blocks of aprons and padding weigh by the voxels the decoder "
                  "reads from them) or\n"
                  "tolerance (every block's RMS error <= eps: equal error per block)")
      ->capture_default_str();
  o->level_factor_opt = cmd->add_option("--level-factor", o->level_factor,
                  "Lagrangian rule: code each coarser level to F times the eps of the level below "
                  "(F^d, d levels above\n"
                  "the finest: coarse levels are drawn only where they are small on screen, and "
                  "differ from the data\n"
                  "by more than eps already); 1 codes every level to eps")
      ->check(CLI::Range(1.0, 16.0))
      ->capture_default_str();
  cmd->add_option("--pursuit", o->pursuit,
                  "Which atom each pursuit step adds: ormp (the one that lowers the block's squared "
                  "error most: fewer atoms\n"
                  "for the same error) or omp (the one most correlated with the residual, as in "
                  "the paper; --extend-pursuit\n"
                  "always adds that one)")
      ->check(CLI::IsMember({"ormp", "omp"}))
      ->capture_default_str();
  cmd->add_option("--mean-bits", o->mean_bits,
                  "Bits of each brick's quantized block means: auto (variable rate: per brick the "
                  "fewest bits, 0..12,\n"
                  "whose step is at most eps/2; fixed rate: 12) or 0..12 for every brick")
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
  cmd->add_option("--rate-sample-frames", o->rate_sample_frames, "--bps: frames encoded per trial")
      ->capture_default_str();
  cmd->add_flag("--resume", o->resume,
                "Continue an interrupted encode: keep frames already written and valid");
  cmd->add_flag("--overwrite", o->overwrite, "Replace an existing container");
  cmd->add_flag("--no-refit", o->no_refit,
                "Quantize coefficients independently (no least-squares refit; for comparison)");
  cmd->add_flag("--no-interval", o->no_interval,
                "Quantize coefficients over [min, max] of each brick (for comparison)");
  cmd->add_flag("--extend-pursuit", o->extend,
                "--rate-rule tolerance: add atoms to blocks whose quantized error exceeds eps "
                "(quantization inside the\n"
                "pursuit): meets eps after quantization, at more bytes and half the speed");
  o->reader.add_to(*cmd);
  cmd->callback([o] { run_encode(*o); });

  auto info_dir = std::make_shared<std::string>();
  auto info_json = std::make_shared<bool>(false);
  CLI::App* info = app.add_subcommand(
      "info", "Describe a NAME.vreel container: volume, codec, levels, sizes and bps");
  info->add_option("CONTAINER", *info_dir, "NAME.vreel directory")->required();
  info->add_flag("--json", *info_json, "Print JSON (the manifest plus totals)");
  info->callback([info_dir, info_json] { run_info(*info_dir, *info_json); });

  auto verify_dir = std::make_shared<std::string>();
  CLI::App* verify = app.add_subcommand(
      "verify", "Check every CRC and structure of a NAME.vreel container, and decode every brick");
  verify->add_option("CONTAINER", *verify_dir, "NAME.vreel directory")->required();
  verify->callback([verify_dir] { run_verify(*verify_dir); });

  auto d = std::make_shared<DecodeOptions>();
  CLI::App* decode = app.add_subcommand(
      "decode",
      "Decode one frame at one level with the CPU reference decoder into a raw float32 file");
  decode->add_option("CONTAINER", d->dir, "NAME.vreel directory")->required();
  decode->add_option("--frame", d->frame, "Time step")->capture_default_str();
  decode->add_option("--level", d->level,
                     "Octree level: 0 = root (one brick) ... levels-1 = full resolution (default)");
  decode->add_option("--out", d->out, "Output .f32 file")->required();
  decode
      ->add_option("--repeat", d->repeat,
                   "Decode this many times and report the fastest (a benchmark)")
      ->capture_default_str();
  decode->callback([d] { run_decode(*d); });
}

}  // namespace volreel::cli
