// tolerance_search.cpp: choosing ε — the order of the sources (choose_tolerance), and rate
// control for a size target: trial encodes of sample frames, stepping along the slope of ln bps
// against ln ε until the target is bracketed, then regula falsi (search_tolerance, solve_for_bps).
#include "volreel/encoder/tolerance.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "detail.hpp"
#include "volreel/encoder/frame_encoder.hpp"
#include "volreel/format/error.hpp"

namespace volreel::encoder {

std::vector<std::size_t> detail::evenly_spaced_indices(std::size_t frames, std::size_t count) {
  std::vector<std::size_t> indices;
  const std::size_t n = std::min(count, frames);
  for (std::size_t i = 0; i < n; ++i)
    indices.push_back(n == 1 ? frames / 2 : i * (frames - 1) / (n - 1));
  return indices;
}

std::vector<Volume> detail::evenly_spaced_frames(const datasets::SeriesReader& series,
                                                 std::size_t frames, std::size_t count) {
  std::vector<Volume> samples;
  for (std::size_t i : evenly_spaced_indices(frames, count))
    samples.push_back(series.read_frame(i));
  return samples;
}

BpsSolution solve_for_bps(const std::function<double(double)>& bps_at, double target_bps,
                          double start, double min_tolerance, double max_tolerance, double relative,
                          double& slope, const Progress& progress) {
  if (!(target_bps > 0) || !std::isfinite(target_bps) || !(min_tolerance > 0) ||
      !(max_tolerance >= min_tolerance) || !std::isfinite(max_tolerance))
    throw std::invalid_argument(
        "solve_for_bps: the target must be positive and finite, and the "
        "tolerances 0 < min <= max, finite");
  // In x = ln ε and y = ln(bps/target), bps(ε) falls as ε grows and y is close to a line.
  struct Point {
    double x = 0, y = 0;
  };
  const double x_min = std::log(min_tolerance), x_max = std::log(max_tolerance);
  const double max_step = std::log(max_rate_step);
  std::optional<Point> fine, coarse;  // the bracket: y > 0 (too many bits) and y < 0
  std::optional<Point> previous;
  int kept_fine = 0, kept_coarse = 0;  // how many times in a row each end stayed (Illinois)
  // The bracket's width when it last halved, and the steps since: regula falsi that does not halve
  // it in two steps (a rate shaped like a step) gives way to a bisection.
  double halved_width = std::numeric_limits<double>::infinity();
  int slow_steps = 0;
  BpsSolution best;  // tolerance 0 until a trial (ε > 0) is kept
  double x = std::clamp(std::log(start), x_min, x_max);
  for (int trial = 1; trial <= max_rate_trials; ++trial) {
    const double eps = std::exp(x);
    const double bps = bps_at(eps);
    char text[64];
    std::snprintf(text, sizeof text, "eps %.4g -> %.4f bps", eps, bps);
    progress.report(trial, max_rate_trials, text);
    ++best.trials;
    if (std::isnan(bps)) break;  // nothing to go on
    if (best.tolerance == 0 || std::abs(bps - target_bps) < std::abs(best.bps - target_bps))
      best.tolerance = eps, best.bps = bps;
    if (std::abs(bps - target_bps) <= relative * target_bps) break;
    // bps ≤ 0 (nothing coded at all): too few bits by any measure, y = −∞.
    const Point p{x,
                  bps > 0 ? std::log(bps / target_bps) : -std::numeric_limits<double>::infinity()};
    // The slope between the last two trials, where they are far enough apart to measure one.
    // Flatter than min_rate_slope (or rising, or not finite), the rate barely moves with ε there:
    // a stretch where every block is coded as finely as the format allows, or holds its mean
    // alone. The next step is then the largest, towards the target or the end of the range.
    // The trial measured from stays until one lands far enough from it, so that short steps
    // add up to a measurement instead of never making one.
    bool flat = !std::isfinite(p.y);
    if (!previous) {
      previous = p;
    } else if (std::abs(p.x - previous->x) >= min_slope_spacing) {
      const double measured = (p.y - previous->y) / (p.x - previous->x);
      flat = flat || !(measured < -min_rate_slope);
      if (measured < 0 && std::isfinite(measured))
        slope = std::clamp(measured, -1 / min_rate_slope, -min_rate_slope);
      previous = p;
    }
    if (p.y > 0)
      fine = p, ++kept_coarse, kept_fine = 0;
    else
      coarse = p, ++kept_fine, kept_coarse = 0;
    double next;
    if (fine && coarse) {
      // Narrower than this, bps jumps across the target's window: the closest trial it is.
      const double width = std::abs(coarse->x - fine->x);
      if (!(width > min_bracket)) break;
      if (width <= halved_width / 2)
        halved_width = width, slow_steps = 0;
      else
        ++slow_steps;
      if (!std::isfinite(coarse->y) || !std::isfinite(fine->y) || slow_steps >= 2) {
        next = (fine->x + coarse->x) / 2;
        halved_width = width, slow_steps = 0;  // the next bracket is half of this one
      } else {
        // Regula falsi between the ends, the Illinois way: an end kept twice in a row counts
        // half, so that the other end moves too.
        const double yf = fine->y / (kept_fine > 1 ? 1 << (kept_fine - 1) : 1);
        const double yc = coarse->y / (kept_coarse > 1 ? 1 << (kept_coarse - 1) : 1);
        next = fine->x + yf * (coarse->x - fine->x) / (yf - yc);
      }
    } else {
      // One side known: a step along the slope, at most a factor max_rate_step in ε.
      next = x + (flat ? (p.y > 0 ? max_step : -max_step)
                       : std::clamp(-p.y / slope, -max_step, max_step));
      next = std::clamp(next, x_min, x_max);
      if (next == x) {  // at the end of the range and still on one side: out of reach
        best.tolerance = eps, best.bps = bps;
        break;
      }
    }
    x = next;
  }
  return best;
}

RateSearch search_tolerance(const datasets::SeriesReader& series,
                            const dictionary::Dictionary& dictionary, std::uint64_t fixed_bytes,
                            CodingSettings settings, double target_bps, std::size_t frames,
                            std::size_t sample_frames, double relative, const Progress& progress) {
  const auto& info = series.info();
  if (frames == 0) frames = info.frames;
  const double voxels = static_cast<double>(info.dims.voxels()) * static_cast<double>(frames);
  const double floor_bps = 8 * static_cast<double>(fixed_bytes) / voxels;
  if (!(target_bps > floor_bps)) {
    // The basis alone (K = M³ − 1 atoms) is a few hundred bytes: then the manifest is the most.
    const bool learned = dictionary.atom_count() > dictionary.block_length() - 1;
    throw InputError("--bps " + format::number_text(target_bps) +
                     " is below what the container's files besides its frames take (" +
                     std::to_string(fixed_bytes) + " bytes, the manifest and the dictionary: " +
                     format::number_text(floor_bps) + " bps over these " + std::to_string(frames) +
                     " frames): ask for more than that" +
                     (learned ? ", use a smaller dictionary (volreel train --atoms)" : "") +
                     " or encode more frames at a time");
  }
  // 1. Sample frames, evenly spaced; a trial reads and encodes them one at a time.
  std::vector<std::size_t> sample = detail::evenly_spaced_indices(frames, sample_frames);
  const double range = tolerance_range(settings.value_min, settings.value_max);
  settings.fixed_sparsity = 0;
  RateSearch r;
  // Each (ε, frame) once encoded: its bytes, coded bricks and those that kept the learned atoms.
  // The check (step 3) encodes only the frames it adds.
  struct Trial {
    double bytes = 0;
    std::size_t bricks = 0, learned = 0;
  };
  std::map<std::pair<double, std::size_t>, Trial> sized;
  const bool side_by_side =
      detail::frames_side_by_side(info.dims, format::BrickShape{settings.brick_size});
  const auto estimate = [&](double eps) {
    settings.tolerance = eps;
    const FrameEncoder encoder(&dictionary, settings);
    std::vector<std::size_t> todo;
    for (std::size_t i : sample)
      if (!sized.contains({eps, i})) todo.push_back(i);
    std::vector<Trial> trials(todo.size());
    const auto trial = [&](std::size_t k, const Volume& frame) {
      FrameStats stats;
      trials[k].bytes = static_cast<double>(encoder.encode(todo[k], frame, &stats).size());
      for (std::size_t n : stats.mean_bits_histogram) trials[k].bricks += n;
      trials[k].learned = trials[k].bricks - stats.split_bricks;
    };
    if (side_by_side) {  // small frames: read, then coded side by side
      std::vector<Volume> read;
      for (std::size_t i : todo) read.push_back(series.read_frame(i));
      detail::for_each_side_by_side(todo.size(), [&](std::size_t k) { trial(k, read[k]); });
    } else {
      for (std::size_t k = 0; k < todo.size(); ++k) trial(k, series.read_frame(todo[k]));
    }
    for (std::size_t k = 0; k < todo.size(); ++k) sized[{eps, todo[k]}] = trials[k];
    double bytes = 0;
    for (std::size_t i : sample) bytes += sized.at({eps, i}).bytes;
    ++r.iterations;
    return 8 *
           (bytes / static_cast<double>(sample.size()) * static_cast<double>(frames) +
            static_cast<double>(fixed_bytes)) /
           voxels;
  };
  // 2. Solve bps(ε) = target from a start in the middle of the usual range (60 dB), carrying
  //    the slope the first search measured into the check's.
  double slope = default_rate_slope;
  const auto search = [&](double start) {
    const auto solved =
        solve_for_bps(estimate, target_bps, start, range * 1e-9, range, relative, slope, progress);
    r.tolerance = solved.tolerance;
    r.estimated_bps = solved.bps;
  };
  search(range * 1e-3);
  // 3. The ε found, checked on as many frames again, evenly spaced among the others: a sequence
  //    whose frames differ in cost (a flow going from smooth to turbulent and back) can mislead
  //    the first sample by 20 % and more. Where the estimate over both misses the target, the
  //    search runs again on both from the ε found; at most rate_check_rounds times.
  for (int round = 0; round < rate_check_rounds && sample.size() < frames; ++round) {
    std::vector<std::size_t> rest;
    for (std::size_t i = 0; i < frames; ++i)
      if (!std::binary_search(sample.begin(), sample.end(), i)) rest.push_back(i);
    for (std::size_t k : detail::evenly_spaced_indices(rest.size(), sample_frames))
      sample.push_back(rest[k]);
    std::sort(sample.begin(), sample.end());
    search(r.tolerance);
    if (std::abs(r.estimated_bps - target_bps) <= relative * target_bps) break;
  }
  r.sample_frames = sample.size();
  // 4. The bricks of the final sample at the ε chosen (every search step ends with it estimated
  //    on the sample), and those that kept the learned atoms.
  for (std::size_t i : sample) {
    const auto at = sized.find({r.tolerance, i});
    if (at == sized.end()) {  // not coded at this ε: nothing known
      r.sample_bricks = r.learned_bricks = 0;
      break;
    }
    r.sample_bricks += at->second.bricks;
    r.learned_bricks += at->second.learned;
  }
  return r;
}

ToleranceChoice choose_tolerance(const datasets::SeriesReader& series,
                                 const format::DictionaryFile& dictionary,
                                 std::uint64_t fixed_bytes, const CodingSettings& settings,
                                 std::size_t frames, const ToleranceRequest& request,
                                 const Progress& progress) {
  const double range = tolerance_range(settings.value_min, settings.value_max);
  ToleranceChoice choice;
  if (settings.fixed_sparsity > 0) {
    choice.source = ToleranceSource::fixed_rate;
  } else if (request.tolerance) {
    choice.source = ToleranceSource::tolerance;
    choice.tolerance = *request.tolerance;
  } else if (request.psnr) {
    choice.source = ToleranceSource::psnr;
    choice.tolerance = tolerance_for_psnr_target(*request.psnr, range);
  } else if (request.bps) {
    choice.source = ToleranceSource::bps;
    choice.rate_search = search_tolerance(
        series, dictionary::from_file(dictionary), fixed_bytes, settings, *request.bps, frames,
        request.rate_sample_frames, request.rate_relative, progress);
    choice.tolerance = choice.rate_search.tolerance;
  } else if (dictionary.training.tolerance > 0) {
    choice.source = ToleranceSource::dictionary_training;
    choice.tolerance = dictionary.training.tolerance;
  } else {
    choice.source = ToleranceSource::default_psnr;
    choice.tolerance = dictionary::tolerance_for_psnr(dictionary::default_encoding_psnr, range);
  }
  return choice;
}

double tolerance_range(double value_min, double value_max) {
  const double range = value_max - value_min;
  return range > 0 ? range : std::max(1.0, std::abs(value_max));
}

double tolerance_for_psnr_target(double psnr_db, double value_range) {
  return std::max(dictionary::tolerance_for_psnr(psnr_db, value_range),
                  smallest_relative_tolerance * value_range);
}

double tolerance_to_train_at(const ToleranceRequest& request, double value_range) {
  if (request.tolerance) return *request.tolerance;
  return tolerance_for_psnr_target(request.psnr ? *request.psnr : dictionary::default_encoding_psnr,
                                   value_range);
}

}  // namespace volreel::encoder
