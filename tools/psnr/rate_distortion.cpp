// rate_distortion.cpp: runs codecs over a series and reports bps, PSNR, SSIM and speed, as a
// table, a CSV and a PSNR-vs-bps plot.
#include "volreel/psnr/rate_distortion.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <ostream>
#include <sstream>

#include "volreel/psnr/metrics.hpp"

namespace volreel::psnr {

namespace fs = std::filesystem;

namespace {

/// Writes text to path through a temporary name, so a reader never sees half a file.
void write_atomically(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp);
    f << text;
    if (!f.flush()) throw InputError("cannot write '" + tmp.string() + "'");
  }
  fs::rename(tmp, path);
}

std::size_t frames_used(const datasets::SeriesReader& series, const RdOptions& options) {
  const std::size_t n = series.info().frames;
  return options.max_frames ? std::min(n, options.max_frames) : n;
}

/// Indices of `count` evenly spaced frames out of n (first and last included when count ≥ 2).
std::vector<std::size_t> spread(std::size_t n, std::size_t count) {
  std::vector<std::size_t> picks;
  count = std::min(count, n);
  for (std::size_t i = 0; i < count; ++i)
    picks.push_back(count == 1 ? n / 2 : i * (n - 1) / (count - 1));
  return picks;
}

double seconds_since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

/// What a point measured over `frames` frames: bps from its bytes, the errors, the mean SSIM of
/// the `ssim_frames` frames sampled, and the decoding speed.
void set_measured(RdPoint& p, const ErrorStats& e, std::size_t frames, Dims dims, double ssim_sum,
                  std::size_t ssim_frames, double decompress_s) {
  const double voxels = static_cast<double>(dims.voxels()) * static_cast<double>(frames);
  p.frames = frames;
  p.bps = 8.0 * static_cast<double>(p.bytes) / voxels;
  p.psnr = e.psnr;
  p.psnr_zfp = e.psnr_zfp;
  p.rmse = e.rmse;
  p.max_abs_error = e.max_abs_error;
  p.ssim_frames = ssim_frames;
  p.ssim = ssim_frames == 0 ? std::nan("") : ssim_sum / static_cast<double>(ssim_frames);
  p.decompress_mvoxels_per_s = voxels / 1e6 / std::max(decompress_s, 1e-9);
}

}  // namespace

std::pair<double, double> series_range(const datasets::SeriesReader& series,
                                       const RdOptions& options, const Progress& progress) {
  const std::size_t frames = frames_used(series, options);
  std::vector<float> frame(series.info().dims.voxels());
  double lo = INFINITY, hi = -INFINITY;
  for (std::size_t t = 0; t < frames; ++t) {
    series.read_frame(t, frame);
    const auto [mn, mx] = std::minmax_element(frame.begin(), frame.end());
    lo = std::min(lo, static_cast<double>(*mn));
    hi = std::max(hi, static_cast<double>(*mx));
    progress.report(static_cast<double>(t + 1), static_cast<double>(frames), "value range");
  }
  return {lo, hi};
}

std::vector<RdPoint> run_rate_distortion(const datasets::SeriesReader& series,
                                         std::span<const std::unique_ptr<FrameCodec>> codecs,
                                         const RdOptions& options, const Progress& progress) {
  const Dims dims = series.info().dims;
  const std::size_t frames = frames_used(series, options);
  // SSIM's window does not fit an axis of 2 to 10 voxels: no frame takes it there.
  const std::vector<std::size_t> ssim_picks =
      spread(frames, ssim_unfit(dims).empty() ? options.ssim_frames : 0);

  struct State {
    ErrorAccumulator errors;
    std::uint64_t bytes = 0;
    double ssim_sum = 0, compress_s = 0, decompress_s = 0;
    std::vector<std::uint8_t> stream;
    std::vector<float> decoded;
  };
  std::vector<State> states(codecs.size());
  for (auto& s : states) s.decoded.resize(dims.voxels());

  std::vector<float> frame(dims.voxels());
  for (std::size_t t = 0; t < frames; ++t) {
    series.read_frame(t, frame);
    const bool with_ssim = std::find(ssim_picks.begin(), ssim_picks.end(), t) != ssim_picks.end();
    const auto n = static_cast<std::ptrdiff_t>(codecs.size());
    // One codec per thread, so each speed figure is that of a single core.
#pragma omp parallel for schedule(dynamic, 1)
    for (std::ptrdiff_t c = 0; c < n; ++c) {
      State& s = states[static_cast<std::size_t>(c)];
      FrameCodec& codec = *codecs[static_cast<std::size_t>(c)];
      auto start = std::chrono::steady_clock::now();
      codec.compress(dims, frame, s.stream);
      s.compress_s += seconds_since(start);
      start = std::chrono::steady_clock::now();
      codec.decompress(dims, s.stream, s.decoded);
      s.decompress_s += seconds_since(start);
      s.bytes += s.stream.size();
      s.errors.add(frame, s.decoded);
      if (with_ssim) s.ssim_sum += ssim(dims, frame, s.decoded);
    }
    progress.report(static_cast<double>(t + 1), static_cast<double>(frames),
                    "frame " + std::to_string(t + 1));
  }

  std::vector<RdPoint> points;
  const double voxels = static_cast<double>(dims.voxels()) * static_cast<double>(frames);
  for (std::size_t c = 0; c < codecs.size(); ++c) {
    const State& s = states[c];
    RdPoint p;
    p.family = codecs[c]->family();
    p.setting = codecs[c]->setting();
    p.bytes = s.bytes + codecs[c]->shared_bytes();
    p.compress_mvoxels_per_s = voxels / 1e6 / std::max(s.compress_s, 1e-9);
    set_measured(p, s.errors.result(), frames, dims, s.ssim_sum, ssim_picks.size(), s.decompress_s);
    points.push_back(std::move(p));
  }
  std::stable_sort(points.begin(), points.end(), [](const RdPoint& a, const RdPoint& b) {
    return a.family != b.family ? a.family < b.family : a.bps < b.bps;
  });
  return points;
}

void measure_decoded_series(const datasets::SeriesReader& original,
                            const datasets::SeriesReader& decoded, const RdOptions& options,
                            RdPoint& point, const Progress& progress) {
  const Dims dims = original.info().dims;
  if (decoded.info().dims != dims)
    throw InputError("the decoded series '" + decoded.info().source + "' has " +
                     to_string(decoded.info().dims) + " voxels per frame; the original '" +
                     original.info().source + "' has " + to_string(dims));
  const std::size_t frames = frames_used(original, options);
  if (decoded.info().frames < frames)
    throw InputError("the decoded series '" + decoded.info().source + "' has " +
                     std::to_string(decoded.info().frames) + " frames; expected " +
                     std::to_string(frames));
  // SSIM's window does not fit an axis of 2 to 10 voxels: no frame takes it there.
  const std::vector<std::size_t> ssim_picks =
      spread(frames, ssim_unfit(dims).empty() ? options.ssim_frames : 0);
  ErrorAccumulator errors;
  double ssim_sum = 0, decompress_s = 0;
  std::vector<float> frame(dims.voxels()), out(dims.voxels());
  for (std::size_t t = 0; t < frames; ++t) {
    original.read_frame(t, frame);
    const auto start = std::chrono::steady_clock::now();
    decoded.read_frame(t, out);
    decompress_s += seconds_since(start);
    errors.add(frame, out);
    if (std::find(ssim_picks.begin(), ssim_picks.end(), t) != ssim_picks.end())
      ssim_sum += ssim(dims, frame, out);
    progress.report(static_cast<double>(t + 1), static_cast<double>(frames),
                    "frame " + std::to_string(t + 1));
  }
  set_measured(point, errors.result(), frames, dims, ssim_sum, ssim_picks.size(), decompress_s);
}

void print_rd_table(std::ostream& out, std::span<const RdPoint> points) {
  char line[256];
  std::snprintf(line, sizeof line, "%-20s %-14s %9s %9s %10s %8s %10s %10s %9s %9s\n", "codec",
                "setting", "bps", "PSNR dB", "PSNRzfp dB", "SSIM", "RMSE", "max err", "enc MV/s",
                "dec MV/s");
  out << line;
  for (const RdPoint& p : points) {
    std::snprintf(line, sizeof line,
                  "%-20s %-14s %9.4f %9.2f %10.2f %8.5f %10.3e %10.3e %9.1f %9.1f\n",
                  p.family.c_str(), p.setting.c_str(), p.bps, p.psnr, p.psnr_zfp, p.ssim, p.rmse,
                  p.max_abs_error, p.compress_mvoxels_per_s, p.decompress_mvoxels_per_s);
    out << line;
  }
  if (!points.empty())
    out << "PSNR = 10·log10(range²/MSE) over all " << points.front().frames
        << " frames (MTV-Player); PSNRzfp = 20·log10(range/(2·RMSE)) (zfp's, 6.02 dB lower); SSIM "
           "= "
        << (points.front().ssim_frames > 0
                ? "mean 3D SSIM of " + std::to_string(points.front().ssim_frames) +
                      " evenly spaced frames"
                : std::string("nan: not computed (an axis shorter than its 11-voxel window, or "
                              "--ssim-frames 0)"))
        << "; MV/s = MVoxel/s on one core.\n";
}

void write_rd_csv(const fs::path& path, std::span<const RdPoint> points) {
  std::ostringstream s;
  s << "codec,setting,frames,bytes,bps,psnr_db,psnr_zfp_db,ssim,rmse,max_abs_error,encode_mvoxel_s,"
       "decode_mvoxel_s\n";
  s.precision(9);
  for (const RdPoint& p : points)
    s << '"' << p.family << "\"," << '"' << p.setting << "\"," << p.frames << ',' << p.bytes << ','
      << p.bps << ',' << p.psnr << ',' << p.psnr_zfp << ',' << p.ssim << ',' << p.rmse << ','
      << p.max_abs_error << ',' << p.compress_mvoxels_per_s << ',' << p.decompress_mvoxels_per_s
      << '\n';
  write_atomically(path, s.str());
}

std::optional<double> psnr_at_bps(std::span<const RdPoint> points, const std::string& family,
                                  double bps) {
  std::vector<const RdPoint*> curve;
  for (const RdPoint& p : points)
    if (p.family == family && std::isfinite(p.psnr) && std::isfinite(p.bps)) curve.push_back(&p);
  std::stable_sort(curve.begin(), curve.end(),
                   [](const RdPoint* a, const RdPoint* b) { return a->bps < b->bps; });
  if (curve.empty() || !(bps >= curve.front()->bps && bps <= curve.back()->bps))
    return std::nullopt;
  for (std::size_t i = 0; i + 1 < curve.size(); ++i) {
    const RdPoint &a = *curve[i], &b = *curve[i + 1];
    if (bps > b.bps) continue;
    if (!(b.bps > a.bps)) return std::max(a.psnr, b.psnr);  // equal bps: the better setting
    return a.psnr + (b.psnr - a.psnr) * (bps - a.bps) / (b.bps - a.bps);
  }
  return curve.front()->psnr;  // a single setting, exactly at its bps
}

EqualBpsTable equal_bps_table(std::span<const RdPoint> points, std::span<const double> bps,
                              const std::string& reference) {
  EqualBpsTable t;
  for (const RdPoint& p : points)
    if (p.family == reference) t.reference = reference;
  if (!t.reference.empty()) t.families.push_back(t.reference);
  for (const RdPoint& p : points)
    if (std::find(t.families.begin(), t.families.end(), p.family) == t.families.end())
      t.families.push_back(p.family);
  t.bps.assign(bps.begin(), bps.end());
  for (double b : t.bps) {
    auto& row = t.psnr.emplace_back();
    for (const std::string& f : t.families) row.push_back(psnr_at_bps(points, f, b));
  }
  return t;
}

namespace {

/// The reference family's PSNR in row r, NaN when there is none or it was not measured there.
double reference_psnr(const EqualBpsTable& t, std::size_t r) {
  if (t.reference.empty() || t.psnr[r].empty() || !t.psnr[r].front()) return std::nan("");
  return *t.psnr[r].front();
}

}  // namespace

void print_equal_bps_table(std::ostream& out, const EqualBpsTable& t) {
  out << "At equal bps: PSNR dB, linear in bps between the two settings that bracket each value "
         "('-': outside "
         "the settings measured)"
      << (t.reference.empty() ? "" : "; in parentheses " + t.reference + " minus that codec")
      << ":\n";
  int width = 24;  // every column as wide as the longest codec name
  for (const std::string& f : t.families) width = std::max(width, static_cast<int>(f.size()));
  char cell[128];
  std::string header = "    bps";
  for (const std::string& f : t.families) {
    std::snprintf(cell, sizeof cell, "  %*s", width, f.c_str());
    header += cell;
  }
  out << header << '\n';
  for (std::size_t r = 0; r < t.bps.size(); ++r) {
    std::snprintf(cell, sizeof cell, "%7.3f", t.bps[r]);
    std::string line = cell;
    const double ref = reference_psnr(t, r);
    for (std::size_t f = 0; f < t.families.size(); ++f) {
      const std::optional<double>& v = t.psnr[r][f];
      if (!v)
        std::snprintf(cell, sizeof cell, "  %*s", width, "-");
      else if (t.reference.empty() || f == 0)
        std::snprintf(cell, sizeof cell, "  %*.2f", width, *v);
      else if (std::isfinite(ref))
        std::snprintf(cell, sizeof cell, "  %*.2f (%+6.2f)", width - 9, *v, ref - *v);
      else
        std::snprintf(cell, sizeof cell, "  %*.2f %8s", width - 9, *v, "");
      line += cell;
    }
    out << line << '\n';
  }
}

void write_equal_bps_csv(const fs::path& path, const EqualBpsTable& t) {
  std::ostringstream s;
  s.precision(9);
  s << "bps,codec,psnr_db,reference,reference_minus_codec_db\n";
  for (std::size_t r = 0; r < t.bps.size(); ++r)
    for (std::size_t f = 0; f < t.families.size(); ++f) {
      const std::optional<double>& v = t.psnr[r][f];
      const double ref = reference_psnr(t, r);
      s << t.bps[r] << ",\"" << t.families[f] << "\",";
      if (v) s << *v;
      s << ",\"" << t.reference << "\",";
      if (v && std::isfinite(ref)) s << ref - *v;
      s << '\n';
    }
  write_atomically(path, s.str());
}

namespace {

bool on_path(const std::string& program) {
  const char* path = std::getenv("PATH");
  if (!path) return false;
  std::stringstream dirs(path);
  std::string dir;
  while (std::getline(dirs, dir, ':')) {
    std::error_code ec;
    if (!dir.empty() && fs::exists(fs::path(dir) / program, ec)) return true;
  }
  return false;
}

std::string shell_quote(const std::string& text) {
  std::string q = "'";
  for (char c : text) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string gnuplot_quote(const std::string& text) {
  std::string q = "'";
  for (char c : text) q += c == '\'' ? std::string("''") : std::string(1, c);
  return q + "'";
}

}  // namespace

void write_rd_plot(const fs::path& png, std::span<const RdPoint> points, const std::string& title) {
  if (!on_path("gnuplot"))
    throw InputError(
        "gnuplot is not installed, so no plot was drawn (the CSV has the numbers): "
        "apt-get install gnuplot-nox");
  std::map<std::string, std::vector<const RdPoint*>> families;
  for (const RdPoint& p : points)
    if (std::isfinite(p.psnr)) families[p.family].push_back(&p);
  const fs::path data = png.string() + ".dat", script = png.string() + ".gp",
                 tmp = png.string() + ".tmp.png";
  {
    std::ofstream d(data);
    for (const auto& [family, list] : families) {
      d << "# " << family << '\n';
      for (const RdPoint* p : list) d << p->bps << ' ' << p->psnr << '\n';
      d << "\n\n";
    }
    std::ofstream g(script);
    g << "set terminal pngcairo size 960,640 enhanced font 'DejaVu Sans,11'\n"
      << "set output " << gnuplot_quote(tmp.string()) << "\n"
      << "set title " << gnuplot_quote(title) << "\n"
      << "set xlabel 'bits per voxel (bps), all bytes counted'\nset ylabel 'PSNR (dB) = 10 "
         "log_{10}(range^2/MSE)'\n"
      << "set logscale x 2\nset grid\nset key bottom right noenhanced\n";
    g << "plot ";
    int index = 0;
    for (const auto& [family, list] : families) {
      g << (index ? ", \\\n     " : "") << gnuplot_quote(data.string()) << " index " << index
        << " using 1:2 with linespoints lw 2 pt 7 title " << gnuplot_quote(family);
      ++index;
    }
    g << '\n';
  }
  const std::string command = "gnuplot " + shell_quote(script.string()) + " 2>&1";
  std::FILE* pipe = popen(command.c_str(), "r");
  std::string output;
  if (pipe) {
    char buffer[256];
    while (std::fgets(buffer, sizeof buffer, pipe)) output += buffer;
  }
  const int status = pipe ? pclose(pipe) : -1;
  std::error_code ec;
  fs::remove(script, ec);
  fs::remove(data, ec);
  if (status != 0 || !fs::exists(tmp, ec)) {
    fs::remove(tmp, ec);
    throw InputError("gnuplot failed to draw '" + png.string() + "': " + output);
  }
  fs::rename(tmp, png);
}

}  // namespace volreel::psnr
