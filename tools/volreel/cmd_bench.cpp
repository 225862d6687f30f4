// cmd_bench.cpp: `volreel bench ...` — benchmark programs that print measured figures.
//   bench rd SERIES   rate-distortion of every codec (zfp fixed accuracy and fixed rate so far)
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include "commands.hpp"
#include "container_series.hpp"
#include "progress.hpp"
#include "volreel/encoder/encode.hpp"
#include "volreel/encoder/series_encoder.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/psnr/rate_distortion.hpp"
#include "volreel_codecs.hpp"

namespace volreel::cli {

namespace {

struct RdCommandOptions {
  std::string series;
  std::string out = "rd";
  ReaderOptions reader;
  psnr::RdOptions rd;
  bool no_plot = false;
  std::string dictionary;            ///< volreel's codecs need one; without it only zfp runs
  std::string atom_storage = "f16";  ///< how the dictionary counts: as encode stores it
  /// Octave steps, half-octave steps where turbulence at 128³ lands in 0.3–0.6 bps (the equal-bps
  /// rows).
  std::vector<double> tolerances = {std::ldexp(1.0, -6),  std::ldexp(1.0, -7), std::exp2(-7.5),
                                    std::ldexp(1.0, -8),  std::exp2(-8.5),     std::ldexp(1.0, -9),
                                    std::ldexp(1.0, -10), std::ldexp(1.0, -11)};
  std::vector<int> sparsities = {1, 2, 3, 4, 5, 6, 7, 8};
  std::vector<double> lagrangian_factors = {encoder::CodingSettings{}.lagrangian_factor};
  bool tolerance_rule = false;  ///< also variable rate with the ε rule
  std::string pursuit = dictionary::pursuit_name(encoder::CodingSettings{}.selection);
  double level_factor = encoder::CodingSettings{}.level_tolerance_factor;
  double level_detail = encoder::CodingSettings{}.level_detail_ratio;
  double coef_step = encoder::CodingSettings{}.coef_step_factor;
  std::string brick_size = "auto";
  std::vector<double> zfp_bricks;  ///< zfp inside the container, accuracy / range (default none)
  /// Also variable rate through a container with sparse keyframes, one curve per gap.
  std::vector<std::uint32_t> keyframe_gaps;
  /// Rows of the equal-bps table: the span MTV-Player's Table 1 reports (0.3 to 0.6 bps).
  std::vector<double> at_bps = {0.30, 0.35, 0.40, 0.45, 0.50, 0.55, 0.60};
};

/// volreel variable rate with sparse keyframes: each tolerance encoded into a container as
/// OUT/keyframes.vreel, where --keyframe-gaps writes its containers (and removes them after):
/// refused unless nothing is there or a volreel container is (a run stopped before its end),
/// checked before any measurement.
std::filesystem::path keyframe_container(const RdCommandOptions& o) {
  const std::filesystem::path container = std::filesystem::path(o.out) / "keyframes.vreel";
  std::error_code ec;
  if (std::filesystem::exists(std::filesystem::symlink_status(container, ec))) {
    const std::string why = " (--keyframe-gaps writes its containers to '" + container.string() +
                            "' and removes it afterwards: move it away or choose another --out)";
    try {
      encoder::refuse_existing_output(container, false, true);
    } catch (const InputError& e) {
      throw InputError(std::string(e.what()) + why);
    }
    // It is removed whole: only what a container holds may be there.
    for (const auto& entry : std::filesystem::directory_iterator(container, ec)) {
      const std::string name = entry.path().filename().string();
      if (name != "manifest.json" && name != "dictionary.bin" && name != "frames" &&
          name.find(".tmp-") == std::string::npos)
        throw InputError("'" + entry.path().string() + "' is not a container's file" + why);
    }
  }
  return container;
}

/// `volreel encode --max-keyframe-gap G` writes it (every byte counted), then every time step
/// decoded as the player draws it, interpolated nodes included.
std::vector<psnr::RdPoint> keyframe_points(const datasets::SeriesReader& series,
                                           const RdCommandOptions& o, double range) {
  std::vector<psnr::RdPoint> points;
  const std::filesystem::path container = keyframe_container(o);
  std::filesystem::create_directories(o.out);
  // Removed afterwards, also when an encode or a measurement fails.
  struct Remove {
    std::filesystem::path path;
    ~Remove() {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  } remove{container};
  const double runs = static_cast<double>(o.keyframe_gaps.size() * o.tolerances.size() *
                                          o.lagrangian_factors.size());
  ProgressBar bar("keyframes", "encodes");
  double done = 0;
  for (const std::uint32_t gap : o.keyframe_gaps)
    for (const double factor : o.lagrangian_factors)
      for (const double relative : o.tolerances) {
        encoder::EncodeRequest request;
        request.coding.rule = encoder::VariableRateRule::lagrangian;
        request.coding.lagrangian_factor = factor;
        request.coding.selection = dictionary::pursuit_from_name(o.pursuit);
        request.coding.level_tolerance_factor = o.level_factor;
        request.coding.level_detail_ratio = o.level_detail;
        request.coding.coef_step_factor = o.coef_step;
        request.coding.brick_size = encoder::brick_size_from_text(o.brick_size);
        request.tolerance.tolerance = relative * range;
        request.dictionary = o.dictionary;
        request.half_atoms = o.atom_storage == "f16";
        request.overwrite = true;
        request.max_frames = o.rd.max_frames;
        request.max_keyframe_gap = gap;
        const encoder::EncodeSummary summary = encoder::encode(series, container, request);
        psnr::RdPoint p;
        p.family = "volreel keyframes G=" + std::to_string(gap);
        if (o.lagrangian_factors.size() > 1) p.family += " k=" + format::number_text(factor);
        char setting[48];
        std::snprintf(setting, sizeof setting, "eps=%.2e", relative * range);
        p.setting = setting;
        p.bytes = summary.container_bytes;
        p.compress_mvoxels_per_s = summary.mvoxels_per_s;
        psnr::measure_decoded_series(series, ContainerSeries(container), o.rd, p);
        points.push_back(std::move(p));
        done += 1;
        bar.progress().report(done, runs, points.back().setting);
      }
  bar.finish();
  return points;
}

void run_rd(const RdCommandOptions& o) {
  const StopOnSignal stop;  // Ctrl-C removes OUT/keyframes.vreel
  std::error_code ec;
  if (std::filesystem::exists(o.out, ec) && !std::filesystem::is_directory(o.out, ec))
    throw InputError("--out '" + o.out + "' is " +
                     format::detail::file_kind(std::filesystem::status(o.out, ec).type()) +
                     ": expected a folder for rd.csv, rd_equal_bps.csv and rd.png");
  format::detail::check_writable(o.out, "--out");
  if (!o.keyframe_gaps.empty()) keyframe_container(o);
  const auto series = datasets::open_series(o.series, o.reader.to_open_options());
  const auto& info = series->info();
  const std::size_t frames = o.rd.max_frames ? std::min(o.rd.max_frames, info.frames) : info.frames;
  std::printf("volreel bench rd\nmachine: %s\ninput:   %s, %s, %zu of %zu frames, variable '%s'\n",
              describe_machine().c_str(), info.source.c_str(), to_string(info.dims).c_str(), frames,
              info.frames, info.variable.c_str());
  std::pair<double, double> range;
  {
    ProgressBar bar("reading", "frames");
    range = psnr::series_range(*series, o.rd, bar.progress());
    bar.finish();
  }
  std::printf("value range [%.6g, %.6g]\n", range.first, range.second);
  std::uint32_t brick_size = encoder::brick_size_from_text(o.brick_size);
  const std::array<std::uint32_t, 3> dims{static_cast<std::uint32_t>(info.dims.x),
                                          static_cast<std::uint32_t>(info.dims.y),
                                          static_cast<std::uint32_t>(info.dims.z)};
  if (brick_size == 0) brick_size = format::choose_brick_shape(dims).size;
  std::printf(
      "volreel bricks: %u^3 voxels (%s; blocks holding voxels of the volume store %.3g "
      "values per voxel, all levels)\n",
      brick_size, o.brick_size == "auto" ? "chosen for this volume" : "--brick-size",
      format::coded_block_share(dims, {brick_size}));
  auto codecs = psnr::make_zfp_sweep(range.second - range.first);
  if (!o.dictionary.empty()) {
    // The dictionary as volreel encode stores it in the container (binary16 atoms by default).
    auto file = o.dictionary == "dct" ? format::dct_dictionary(6, VOLREEL_VERSION)
                                      : format::read_dictionary_file(o.dictionary);
    file = format::container_dictionary(std::move(file), o.atom_storage == "f16");
    const auto bytes = format::serialize_dictionary_file(file).size();
    auto dict = std::make_shared<const dictionary::Dictionary>(dictionary::from_file(file));
    std::printf(
        "volreel codecs: dictionary %s (K = %d, atoms stored as %s, %zu bytes, counted once in "
        "bps)\n",
        o.dictionary.c_str(), dict->atom_count(), file.half_atoms ? "f16" : "f32", bytes);
    VolreelSweep sweep{o.tolerances, o.lagrangian_factors, o.tolerance_rule, o.sparsities, {}};
    sweep.selection = dictionary::pursuit_from_name(o.pursuit);
    sweep.level_tolerance_factor = o.level_factor;
    sweep.level_detail_ratio = o.level_detail;
    sweep.coef_step_factor = o.coef_step;
    sweep.brick_size = brick_size;
    std::printf(
        "volreel pursuit %s; variable rate (Lagrangian rule) codes level d above the finest to "
        "eps*%g^d, or %g times what a brick's downsampling lost where that is coarser\n",
        o.pursuit.c_str(), o.level_factor, o.level_detail);
    for (auto& c : make_volreel_sweep(dict, bytes, range.first, range.second, sweep))
      codecs.push_back(std::move(c));
  }
  if (!o.zfp_bricks.empty()) {
    VolreelSweep sweep{{}, {}, false, {}, o.zfp_bricks};
    sweep.brick_size = brick_size;
    for (auto& c : make_volreel_sweep(nullptr, 0, range.first, range.second, sweep))
      codecs.push_back(std::move(c));
  }
  if (o.dictionary.empty())
    std::printf("no --dictionary: volreel's sparse codecs are skipped (zfp only)\n");
  std::vector<psnr::RdPoint> points;
  {
    ProgressBar bar("compressing", "frames");
    points = psnr::run_rate_distortion(*series, codecs, o.rd, bar.progress());
    bar.finish();
  }
  if (!o.keyframe_gaps.empty()) {
    if (o.dictionary.empty())
      throw InputError("--keyframe-gaps needs --dictionary (a dictionary file or 'dct')");
    for (auto& p : keyframe_points(*series, o, range.second - range.first))
      points.push_back(std::move(p));
  }
  std::cout << '\n';
  psnr::print_rd_table(std::cout, points);
  std::filesystem::create_directories(o.out);
  const std::filesystem::path csv = std::filesystem::path(o.out) / "rd.csv";
  psnr::write_rd_csv(csv, points);
  std::cout << '\n';
  const psnr::EqualBpsTable equal = psnr::equal_bps_table(points, o.at_bps);
  psnr::print_equal_bps_table(std::cout, equal);
  const std::filesystem::path equal_csv = std::filesystem::path(o.out) / "rd_equal_bps.csv";
  psnr::write_equal_bps_csv(equal_csv, equal);
  std::printf("\nwrote %s and %s\n", csv.c_str(), equal_csv.c_str());
  if (!o.no_plot) {
    const std::filesystem::path png = std::filesystem::path(o.out) / "rd.png";
    try {
      psnr::write_rd_plot(png, points,
                          "Rate-distortion: " + info.variable + " " + to_string(info.dims) + " x " +
                              std::to_string(frames) + " frames");
      std::printf("wrote %s\n", png.c_str());
    } catch (const InputError& e) {
      std::fprintf(stderr, "volreel: warning: %s\n", e.what());
    }
  }
}

}  // namespace

void add_bench_command(CLI::App& app) {
  CLI::App* bench = app.add_subcommand(
      "bench", "Benchmarks: print measured figures with the machine, build and input");
  bench->require_subcommand(1);

  auto o = std::make_shared<RdCommandOptions>();
  CLI::App* rd =
      bench->add_subcommand("rd",
                            "Rate-distortion of the codecs on a series: zfp fixed-accuracy "
                            "(tolerances range*2^-k, k=-1,0,1,...,12) and\n"
                            "fixed-rate (0.125 to 8 bits/value). Prints bps, PSNR, SSIM, "
                            "compression and decompression MVoxel/s per\n"
                            "setting, then every codec's PSNR at equal bps (--at-bps); writes "
                            "OUT/rd.csv, OUT/rd_equal_bps.csv and\n"
                            "OUT/rd.png (PSNR vs bps, via gnuplot).");
  rd->add_option(
        "SERIES", o->series,
        "Raw series directory, HDF5 file, raw file or quoted pattern of raw files (see below)")
      ->required();
  rd->add_option(
        "--out", o->out,
        "Directory for rd.csv, rd_equal_bps.csv and rd.png (and, while it runs, keyframes.vreel)")
      ->capture_default_str();
  rd->add_option("--max-frames", o->rd.max_frames, "Use only the first N frames (0: all)")
      ->capture_default_str();
  rd->add_option("--ssim-frames", o->rd.ssim_frames,
                 "3D SSIM on this many evenly spaced frames (0: none)")
      ->capture_default_str();
  rd->add_flag("--no-plot", o->no_plot, "Write the CSV only");
  rd->add_option("--dictionary", o->dictionary,
                 "Dictionary (volreel train, or 'dct' for the DCT basis alone): adds volreel "
                 "variable rate (--tolerances) and fixed "
                 "rate (--sparsities), each\n"
                 "frame encoded into a frame file in memory and decoded by the CPU decoder; the "
                 "dictionary counts in bps");
  rd->add_option("--atom-storage", o->atom_storage,
                 "How the dictionary's atoms are stored and counted: f16 (what volreel encode "
                 "stores by default) or f32")
      ->check(CLI::IsMember({"f16", "f32"}))
      ->capture_default_str();
  rd->add_option("--tolerances", o->tolerances,
                 "Variable rate: eps as fractions of the value range; each block gets the atoms "
                 "that lower its squared\n"
                 "error by at least k*216*eps^2 (the rate-distortion optimal, Lagrangian rule)")
      ->check(positive())
      ->capture_default_str();
  rd->add_option("--lagrangian-factors", o->lagrangian_factors,
                 "Variable rate: k, one row per value and eps")
      ->check(positive())
      ->capture_default_str();
  rd->add_flag("--tolerance-rule", o->tolerance_rule,
               "Also variable rate with the eps rule (atoms until each block's RMS error <= eps), "
               "for comparison");
  rd->add_option("--sparsities", o->sparsities, "Fixed rate: atoms per block (1..216)")
      ->check(CLI::Range(1, 216))
      ->capture_default_str();
  rd->add_option("--pursuit", o->pursuit,
                 "volreel's rows: ormp or omp (as volreel encode --pursuit)")
      ->check(CLI::IsMember({"ormp", "omp"}))
      ->capture_default_str();
  rd->add_option("--level-factor", o->level_factor,
                 "Variable rate: code level d above the finest to eps*F^d (as volreel encode "
                 "--level-factor; the\n"
                 "finest level, which the table measures, is the same, so F changes only the bps)")
      ->check(in_range(1, 16))
      ->capture_default_str();
  rd->add_option("--level-detail", o->level_detail,
                 "Variable rate: also code a brick above the finest level to R times what its "
                 "downsampling lost where\nthat is coarser than eps*F^d (as volreel encode "
                 "--level-detail; changes only the bps, as --level-factor)")
      ->check(in_range(0, 4))
      ->capture_default_str();
  rd->add_option("--coef-step", o->coef_step,
                 "Variable rate: the largest coefficient step as a multiple of eps (as volreel "
                 "encode --coef-step)")
      ->check(positive())
      ->capture_default_str();
  rd->add_option("--at-bps", o->at_bps,
                 "Rows of the equal-bps table (OUT/rd_equal_bps.csv): each codec's PSNR at these "
                 "bps, linear in bps\n"
                 "between the two settings that bracket each value, never extrapolated, and "
                 "volreel variable rate's\n"
                 "difference from each")
      ->check([](const std::string& text) {
        return positive_number(text)
                   ? std::string()
                   : "expected bits per voxel > 0, e.g. 0.3, found '" + text + "'";
      })
      ->capture_default_str();
  rd->add_option("--brick-size", o->brick_size,
                 "Stored voxels per brick axis of volreel's rows, as volreel encode --brick-size "
                 "(auto: chosen for the volume)")
      ->capture_default_str();
  rd->add_option("--zfp-bricks", o->zfp_bricks,
                 "Also zfp per brick inside the container, accuracy as fractions of the range")
      ->check(positive());
  rd->add_option("--keyframe-gaps", o->keyframe_gaps,
                 "Also volreel variable rate with sparse keyframes, one curve per gap G: each "
                 "--tolerances value encoded\n"
                 "into OUT/keyframes.vreel as volreel encode --max-keyframe-gap G writes it "
                 "(every byte counted) and every\n"
                 "time step decoded as the player draws it, interpolated nodes included "
                 "(needs --dictionary)")
      ->check(CLI::Range(1u, 65535u));
  o->reader.add_to(*rd);
  rd->callback([o] { run_rd(*o); });
  add_bench_train_command(*bench);
  add_bench_codes_command(*bench);
#ifdef VOLREEL_HAVE_VULKAN
  add_bench_decode_command(*bench);
#endif
#ifdef VOLREEL_HAVE_PLAYER
  add_bench_stream_command(*bench);
  add_bench_index_command(*bench);
#endif
#ifdef VOLREEL_HAVE_VULKAN
  add_bench_play_command(*bench);
#endif
}

}  // namespace volreel::cli
