// cmd_compare.cpp: `volreel compare A B` — error metrics between two volumes, two series or two
// PNG images, as a table, JSON or CSV.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <memory>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "container_series.hpp"
#include "progress.hpp"
#include "volreel/format/error.hpp"
#include "volreel/psnr/metrics.hpp"

namespace volreel::cli {

namespace {

struct CompareOptions {
  std::string a, b;
  ReaderOptions reader;
  bool json = false, csv = false, no_ssim = false;
  double max_error = 0, min_psnr = 0;  ///< > 0: bounds the comparison must meet (exit status 1)
};

bool is_png(const std::string& path) {
  return path.size() > 4 && (path.ends_with(".png") || path.ends_with(".PNG"));
}

/// SSIM for the table: "-" when it was not computed (--no-ssim, or an axis shorter than its
/// window).
std::string ssim_text(double ssim) {
  if (std::isnan(ssim)) return "-";
  char text[16];
  std::snprintf(text, sizeof text, "%.5f", ssim);
  return text;
}

/// JSON has no infinity: a perfect match is written as null.
nlohmann::json number(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
}

void compare_images(const CompareOptions& o) {
  if (o.max_error > 0)
    throw InputError("--max-error bounds the values of volumes; for images give --min-psnr");
  const image::Image a = image::read_png(o.a), b = image::read_png(o.b);
  const psnr::ImageComparison c = psnr::compare_images(a, b);
  if (o.json) {
    nlohmann::json j{{"a", o.a},
                     {"b", o.b},
                     {"width", a.width},
                     {"height", a.height},
                     {"channels", a.channels},
                     {"psnr", number(c.psnr)},
                     {"ssim", c.ssim},
                     {"mse", c.mse},
                     {"definitions",
                      {{"psnr", "10*log10(255^2/MSE) over the colour channels (alpha left out)"},
                       {"ssim", "Gaussian-window SSIM (sigma 1.5) per colour channel, averaged"}}}};
    std::cout << j.dump(2) << '\n';
  } else if (o.csv) {
    std::printf(
        "a,b,width,height,channels,psnr_db,ssim,mse\n\"%s\",\"%s\",%d,%d,%d,%.6f,%.6f,%.6f\n",
        o.a.c_str(), o.b.c_str(), a.width, a.height, a.channels, c.psnr, c.ssim, c.mse);
  } else {
    std::printf(
        "images %dx%d, %d channel(s)%s\nPSNR  %.3f dB  (10*log10(255^2/MSE))\nSSIM  %.5f  (per "
        "channel, averaged)\nMSE   %.4f\n",
        a.width, a.height, a.channels, c.colour_channels < a.channels ? " (alpha left out)" : "",
        c.psnr, c.ssim, c.mse);
  }
  if (o.min_psnr > 0 && !(c.psnr >= o.min_psnr))
    throw InputError("the images' PSNR " + format::number_text(c.psnr) +
                     " dB is below --min-psnr " + format::number_text(o.min_psnr));
}

void compare_series(const CompareOptions& o) {
  if (is_container(o.a))
    throw InputError("'" + o.a +
                     "' is a volreel container: compare takes the original as A and the container "
                     "as B (volreel compare ORIGINAL " +
                     o.a + ")");
  const datasets::OpenOptions open = o.reader.to_open_options();
  // Each input kind's options (raw: --dims, --dtype, --frames; HDF5: --dataset; NetCDF:
  // --variable, --time-dim) are for the side of that kind: a container, or a series of another
  // kind, compared with it takes none of them.
  const std::filesystem::path a_path = o.a, b_path = o.b;
  const bool b_series = !is_container(o.b);
  const auto a =
      datasets::open_series(o.a, datasets::options_for(a_path, open, b_series ? &b_path : nullptr));
  // B may be a NAME.vreel container: its frames are decoded at full resolution (CPU decoder).
  const ContainerSeries* container = nullptr;
  std::unique_ptr<datasets::SeriesReader> b;
  if (is_container(o.b)) {
    auto c = std::make_unique<ContainerSeries>(o.b);
    container = c.get();
    b = std::move(c);
  } else {
    b = datasets::open_series(o.b, datasets::options_for(b_path, open, &a_path));
  }
  const auto& ia = a->info();
  const auto& ib = b->info();
  // bps of a container: all its bytes over the voxels of all its frames (docs/design.md,
  // "Metrics").
  const double bps = container ? 8.0 * static_cast<double>(container->container().total_bytes()) /
                                     (static_cast<double>(ia.dims.voxels()) *
                                      static_cast<double>(container->info().frames))
                               : std::nan("");
  if (ia.dims != ib.dims)
    throw InputError("'" + o.a + "' is " + to_string(ia.dims) + " but '" + o.b + "' is " +
                     to_string(ib.dims));
  // A container encoded from the first frames of A (encode --max-frames) compares with those.
  const std::size_t frames = container ? std::min(ia.frames, ib.frames) : ia.frames;
  if (container && ia.frames < ib.frames)
    throw InputError("'" + o.a + "' has " + std::to_string(ia.frames) +
                     " frames but the container '" + o.b + "' has " + std::to_string(ib.frames) +
                     ": compare a container with the series it was encoded from (as many frames, "
                     "or more when it was encoded with --max-frames)");
  if (!container && ia.frames != ib.frames)
    throw InputError("'" + o.a + "' has " + std::to_string(ia.frames) + " frames but '" + o.b +
                     "' has " + std::to_string(ib.frames));
  if (frames < ia.frames)
    std::fprintf(stderr,
                 "volreel compare: note: the container holds %zu of the %zu frames of '%s': "
                 "frames %zu..%zu of A are not compared\n",
                 frames, ia.frames, o.a.c_str(), frames, ia.frames - 1);

  struct Row {
    psnr::ErrorStats e;
    double ssim;
  };
  // SSIM's window does not fit an axis of 2 to 10 voxels: the other metrics without it.
  const std::string ssim_unfit = o.no_ssim ? "" : psnr::ssim_unfit(ia.dims);
  const bool with_ssim = !o.no_ssim && ssim_unfit.empty();
  if (!ssim_unfit.empty())
    std::fprintf(stderr, "note: SSIM not computed: %s (the other metrics are)\n",
                 ssim_unfit.c_str());
  std::vector<Row> rows;
  psnr::ErrorAccumulator sequence;
  double ssim_sum = 0;
  Volume va(ia.dims), vb(ia.dims);
  ProgressBar bar("comparing", "frames");
  for (std::size_t t = 0; t < frames; ++t) {
    a->read_frame(t, va.data);
    b->read_frame(t, vb.data);
    sequence.add(va.data, vb.data);
    Row row{psnr::compare(va.data, vb.data), std::nan("")};
    if (with_ssim) {
      row.ssim = psnr::ssim(ia.dims, va.data, vb.data);
      ssim_sum += row.ssim;
    }
    rows.push_back(row);
    if (frames > 1) bar.update({static_cast<double>(t + 1), static_cast<double>(frames), {}});
  }
  if (frames > 1) bar.finish();
  const psnr::ErrorStats total = sequence.result();
  // Every frame rated against the sequence's value range, as the 'all' row, encode's --psnr and
  // the container's value range are.
  for (Row& row : rows) row.e = psnr::against_range(row.e, total.original_min, total.original_max);
  const double mean_ssim = with_ssim ? ssim_sum / static_cast<double>(frames) : std::nan("");
  // After the tables: the bounds asked for, as an error naming the worst frame.
  const auto enforce_bounds = [&] {
    std::size_t worst = 0;
    for (std::size_t t = 1; t < rows.size(); ++t)
      if (rows[t].e.max_abs_error > rows[worst].e.max_abs_error) worst = t;
    if (o.max_error > 0 && total.max_abs_error > o.max_error)
      throw InputError("the largest error " + format::number_text(total.max_abs_error) +
                       " (frame " + std::to_string(worst) + ") exceeds --max-error " +
                       format::number_text(o.max_error));
    std::size_t lowest = 0;  // the frame of the lowest PSNR
    for (std::size_t t = 1; t < rows.size(); ++t)
      if (rows[t].e.psnr < rows[lowest].e.psnr) lowest = t;
    if (o.min_psnr > 0 && !(total.psnr >= o.min_psnr))
      throw InputError("the sequence PSNR " + format::number_text(total.psnr) +
                       " dB is below --min-psnr " + format::number_text(o.min_psnr) +
                       " (the worst frame: " + std::to_string(lowest) + " at " +
                       format::number_text(rows[lowest].e.psnr) + " dB)");
  };

  if (o.json) {
    nlohmann::json frame_rows = nlohmann::json::array();
    for (std::size_t t = 0; t < rows.size(); ++t) {
      const auto& e = rows[t].e;
      frame_rows.push_back({{"frame", t},
                            {"psnr", number(e.psnr)},
                            {"psnr_zfp", number(e.psnr_zfp)},
                            {"rmse", e.rmse},
                            {"max_abs_error", e.max_abs_error},
                            {"ssim", number(rows[t].ssim)},
                            {"range", e.range()}});
    }
    nlohmann::json j{
        {"a", o.a},
        {"b", o.b},
        {"dims", {ia.dims.x, ia.dims.y, ia.dims.z}},
        {"frames", frame_rows},
        {"sequence",
         {{"psnr", number(total.psnr)},
          {"psnr_zfp", number(total.psnr_zfp)},
          {"rmse", total.rmse},
          {"max_abs_error", total.max_abs_error},
          {"ssim", number(mean_ssim)},
          {"range", total.range()}}},
        {"bps", number(bps)},
        {"definitions",
         {{"psnr",
           "10*log10(range^2/MSE), range: max - min of the first input over the sequence "
           "(MTV-Player)"},
          {"psnr_zfp", "20*log10(range/(2*RMSE)) (zfp's definition)"},
          {"ssim", "3D Gaussian-window SSIM (sigma 1.5), data range of the first input"}}}};
    std::cout << j.dump(2) << '\n';
    enforce_bounds();
    return;
  }
  if (o.csv) {
    std::printf("frame,psnr_db,psnr_zfp_db,rmse,max_abs_error,ssim\n");
    for (std::size_t t = 0; t < rows.size(); ++t)
      std::printf("%zu,%.6f,%.6f,%.6e,%.6e,%.6f\n", t, rows[t].e.psnr, rows[t].e.psnr_zfp,
                  rows[t].e.rmse, rows[t].e.max_abs_error, rows[t].ssim);
    std::printf("all,%.6f,%.6f,%.6e,%.6e,%.6f\n", total.psnr, total.psnr_zfp, total.rmse,
                total.max_abs_error, mean_ssim);
    if (container) std::printf("# bps,%.6f\n", bps);
    enforce_bounds();
    return;
  }
  std::printf("A: %s\nB: %s\n%s, %zu frame(s)\n", ia.source.c_str(), ib.source.c_str(),
              to_string(ia.dims).c_str(), frames);
  std::printf("%7s %10s %12s %12s %12s %9s\n", "frame", "PSNR dB", "PSNRzfp dB", "RMSE", "max err",
              "SSIM");
  for (std::size_t t = 0; t < rows.size(); ++t)
    std::printf("%7zu %10.3f %12.3f %12.4e %12.4e %9s\n", t, rows[t].e.psnr, rows[t].e.psnr_zfp,
                rows[t].e.rmse, rows[t].e.max_abs_error, ssim_text(rows[t].ssim).c_str());
  std::printf("%7s %10.3f %12.3f %12.4e %12.4e %9s\n", "all", total.psnr, total.psnr_zfp,
              total.rmse, total.max_abs_error, ssim_text(mean_ssim).c_str());
  if (container)
    std::printf(
        "B is a volreel container: %.4f bps (8 * all its bytes / (voxels per frame * frames))\n",
        bps);
  std::printf(
      "PSNR = 10*log10(range^2/MSE), range = max-min of A over the whole sequence (every row, "
      "as encode's --psnr).\n"
      "PSNRzfp = 20*log10(range/(2*RMSE)), zfp's definition (6.02 dB lower). SSIM: 3D, Gaussian "
      "window sigma 1.5.\n");
  if (!(total.original_max > total.original_min) && total.rmse > 0)
    std::printf(
        "A is constant (its range is 0): PSNR is not defined for it (-inf above, null in "
        "--json); RMSE and the max error measure B.\n");
  enforce_bounds();
}

}  // namespace

void add_compare_command(CLI::App& app) {
  auto o = std::make_shared<CompareOptions>();
  CLI::App* cmd = app.add_subcommand(
      "compare",
      "Error metrics between an original A and a reconstruction B: two series "
      "(raw series directories, raw files\n"
      "or patterns, HDF5 or NetCDF; B may also be a NAME.vreel container, "
      "decoded at full resolution, its bps\n"
      "printed) or two PNG images. Volumes: PSNR (MTV: 10*log10(range^2/MSE)) and "
      "zfp's PSNR, RMSE, max error, 3D SSIM,\n"
      "per frame and over the sequence. Images: PSNR (range 255) and SSIM per "
      "colour channel, averaged.");
  cmd->add_option("A", o->a, "The original")->required();
  cmd->add_option("B", o->b, "The reconstruction")->required();
  o->reader.add_to(*cmd);
  auto* json = cmd->add_flag("--json", o->json, "Print JSON");
  cmd->add_flag("--csv", o->csv, "Print CSV")->excludes(json);
  cmd->add_flag("--no-ssim", o->no_ssim, "Skip SSIM (faster on large volumes)");
  cmd->add_option("--max-error", o->max_error,
                  "Volumes: fail (exit status 1, naming the worst frame) if any value of B is off "
                  "by more than this\n(the bound of volreel encode --max-error)")
      ->check(positive());
  cmd->add_option("--min-psnr", o->min_psnr,
                  "Fail (exit status 1) if the sequence PSNR (volumes) or the images' PSNR is "
                  "below this (dB)")
      ->check(positive());
  cmd->callback([o] {
    const bool a_png = is_png(o->a), b_png = is_png(o->b);
    if (a_png != b_png)
      throw InputError(
          "cannot compare an image with a volume: give two PNG files or two volumes/series");
    if (a_png)
      compare_images(*o);
    else
      compare_series(*o);
  });
}

}  // namespace volreel::cli
