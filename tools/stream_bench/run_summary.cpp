// run_summary.cpp: the averages and the seek times of a bench stream run (see run_summary.hpp).
#include "volreel/stream_bench/run_summary.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace volreel::stream_bench {

void summarize(RunResult& r, const std::vector<std::pair<double, double>>& seeks) {
  // 1. Averages.
  const double n = static_cast<double>(std::max<std::size_t>(r.frames.size(), 1));
  r.min_psnr = std::numeric_limits<double>::infinity();
  std::size_t full = 0, full_lod = 0;
  for (const FrameRecord& f : r.frames) {
    r.mean_psnr += std::min(f.psnr, psnr_cap_db);
    r.min_psnr = std::min(r.min_psnr, f.psnr);
    r.mean_ssim += f.ssim;
    r.mean_fraction += f.stats.fraction_at_target;
    r.mean_current += f.fraction_current;
    full_lod += f.stats.at_target_nodes == f.stats.target_nodes ? 1 : 0;
    full += f.current_nodes == f.stats.target_nodes ? 1 : 0;
    r.hole_frames += f.stats.holes > 0 ? 1 : 0;
    if (f.root_resident && f.stats.holes > 0) {
      ++r.frames_with_holes_after_root;
      r.max_holes_after_root = std::max(r.max_holes_after_root, f.stats.holes);
    }
    r.mean_update_ms += f.update_ms;
    r.mean_decode_ms += f.decode_ms;
    r.mean_render_ms += f.render_ms;
    r.mean_frame_ms += f.frame_ms;
  }
  for (double* v : {&r.mean_psnr, &r.mean_ssim, &r.mean_fraction, &r.mean_current,
                    &r.mean_update_ms, &r.mean_decode_ms, &r.mean_render_ms, &r.mean_frame_ms})
    *v /= n;
  r.full_quality_share = static_cast<double>(full) / n;
  r.full_lod_share = static_cast<double>(full_lod) / n;
  r.bytes_loaded = r.frames.empty() ? 0 : static_cast<double>(r.frames.back().stats.bytes_loaded);
  r.bytes_uploaded = r.frames.empty() ? 0 : static_cast<double>(r.frames.back().bytes_uploaded);
  // Popping (frames after the first; where bricks were uploaded, and everywhere) and seam error
  // (frames that have boundary pixels).
  // The first frame at or after a seek is a cut: its change is the seek's, not popping.
  std::vector<bool> cut(r.frames.size(), false);
  for (const auto& [time, keyframe] : seeks)
    for (std::size_t i = 0; i < r.frames.size(); ++i)
      if (r.frames[i].time >= time) {
        cut[i] = true;
        break;
      }
  double popping = 0, popping_all = 0, seam = 0, working_set = 0;
  std::size_t popping_all_frames = 0;
  r.popping_frames = r.seam_frames = r.working_set_popping_frames = 0;
  r.max_popping = r.max_working_set_popping = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0; i < r.frames.size(); ++i) {
    const FrameRecord& f = r.frames[i];
    if (std::isfinite(f.seam)) {
      seam += f.seam;
      ++r.seam_frames;
    }
    // A frame after one with holes shows what was not drawn before (at start-up, the first
    // bricks): an appearance, not a change between drawings.
    if (i == 0 || cut[i] || r.frames[i - 1].stats.holes > 0) continue;
    if (std::isfinite(f.working_set_popping)) {
      working_set += f.working_set_popping * f.working_set_popping;
      r.max_working_set_popping = r.working_set_popping_frames == 0
                                      ? f.working_set_popping
                                      : std::max(r.max_working_set_popping, f.working_set_popping);
      ++r.working_set_popping_frames;
    }
    if (!std::isfinite(f.popping)) continue;
    popping_all += f.popping * f.popping;
    ++popping_all_frames;
    if (f.stats.uploads > 0 || f.stats.blended_leaves > 0) {
      popping += f.popping * f.popping;
      r.max_popping = r.popping_frames == 0 ? f.popping : std::max(r.max_popping, f.popping);
      ++r.popping_frames;
    }
  }
  const auto mean = [](double sum, std::size_t count) {
    return count > 0 ? sum / static_cast<double>(count) : std::numeric_limits<double>::quiet_NaN();
  };
  // Quadratic means: a change spread over several frames counts less than the same change at once.
  r.mean_popping = std::sqrt(mean(popping, r.popping_frames));
  r.mean_popping_all = std::sqrt(mean(popping_all, popping_all_frames));
  r.mean_working_set_popping = std::sqrt(mean(working_set, r.working_set_popping_frames));
  r.mean_seam = mean(seam, r.seam_frames);
  // 2. Time to full quality after each seek: the first frame at or after the seek whose target
  // nodes are all drawn as with everything loaded, before the next seek (and the same for the
  // target LOD alone).
  for (std::size_t k = 0; k < seeks.size(); ++k) {
    SeekResult sr;
    sr.time = seeks[k].first;
    sr.keyframe = seeks[k].second;
    const double next =
        k + 1 < seeks.size() ? seeks[k + 1].first : std::numeric_limits<double>::infinity();
    for (const FrameRecord& f : r.frames) {
      if (f.time < sr.time || f.time >= next) continue;
      if (std::isnan(sr.to_full_lod) && f.stats.at_target_nodes == f.stats.target_nodes)
        sr.to_full_lod = f.time - sr.time;
      if (std::isnan(sr.to_full_quality) && f.current_nodes == f.stats.target_nodes)
        sr.to_full_quality = f.time - sr.time;
    }
    r.seeks.push_back(sr);
  }
}

namespace {

/// Throws std::invalid_argument unless the frame's reference and image have the same size and
/// channels and hold that many bytes.
void check_pair(const image::Image& reference, const image::Image& image, const char* what) {
  const auto bytes = static_cast<std::size_t>(std::max(image.width, 0)) *
                     static_cast<std::size_t>(std::max(image.height, 0)) *
                     static_cast<std::size_t>(std::max(image.channels, 0));
  if (reference.width != image.width || reference.height != image.height ||
      reference.channels != image.channels || reference.pixels.size() != bytes ||
      image.pixels.size() != bytes)
    throw std::invalid_argument(std::string(what) +
                                ": the reference and the image differ in size or channels");
}

}  // namespace

double popping_rms(const image::Image& previous_reference, const image::Image& previous_image,
                   const image::Image& reference, const image::Image& image) {
  check_pair(previous_reference, previous_image, "popping_rms (previous frame)");
  check_pair(reference, image, "popping_rms");
  if (image.width != previous_image.width || image.height != previous_image.height ||
      image.channels != previous_image.channels)
    return std::numeric_limits<double>::quiet_NaN();
  const std::size_t n = image.pixels.size();
  if (n == 0) return std::numeric_limits<double>::quiet_NaN();
  double sum = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const int e = int{image.pixels[k]} - int{reference.pixels[k]};
    const int e_previous = int{previous_image.pixels[k]} - int{previous_reference.pixels[k]};
    const auto d = static_cast<double>(e - e_previous);
    sum += d * d;
  }
  return std::sqrt(sum / static_cast<double>(n));
}

double image_change_rms(const image::Image& before, const image::Image& after) {
  const std::size_t n = after.pixels.size();
  if (before.width != after.width || before.height != after.height ||
      before.channels != after.channels || before.pixels.size() != n || n == 0)
    return std::numeric_limits<double>::quiet_NaN();
  double sum = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const auto d = static_cast<double>(int{after.pixels[k]} - int{before.pixels[k]});
    sum += d * d;
  }
  return std::sqrt(sum / static_cast<double>(n));
}

std::vector<std::uint8_t> lod_boundary(std::span<const std::uint8_t> lod_map, int width, int height,
                                       int radius) {
  if (width < 0 || height < 0 || radius < 0 ||
      lod_map.size() != static_cast<std::size_t>(width) * static_cast<std::size_t>(height))
    throw std::invalid_argument("lod_boundary: the LOD map holds " +
                                std::to_string(lod_map.size()) + " values for " +
                                std::to_string(width) + "x" + std::to_string(height) +
                                " pixels (radius " + std::to_string(radius) + ")");
  // A pixel's neighbourhood holds a level other than its own exactly when the smallest or the
  // largest level in it (255 left out) differs from its own: the window's minimum and maximum,
  // computed separably (rows, then columns), with 255 counting as no level: a window without
  // any level keeps minimum 255 and maximum 0, which pass neither test below.
  constexpr std::uint8_t none = 255;
  const auto w = static_cast<std::size_t>(width), h = static_cast<std::size_t>(height);
  const auto at = [w](std::size_t x, std::size_t y) { return y * w + x; };
  const auto r = static_cast<std::size_t>(radius);
  std::vector<std::uint8_t> row_min(lod_map.size(), none), row_max(lod_map.size(), 0);
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x) {
      const std::size_t x1 = std::min(x + r, w - 1);
      for (std::size_t xx = x > r ? x - r : 0; xx <= x1; ++xx) {
        const std::uint8_t v = lod_map[at(xx, y)];
        if (v == none) continue;
        row_min[at(x, y)] = std::min(row_min[at(x, y)], v);
        row_max[at(x, y)] = std::max(row_max[at(x, y)], v);
      }
    }
  std::vector<std::uint8_t> boundary(lod_map.size(), 0);
  for (std::size_t y = 0; y < h; ++y)
    for (std::size_t x = 0; x < w; ++x) {
      const std::uint8_t v = lod_map[at(x, y)];
      if (v == none) continue;
      const std::size_t y1 = std::min(y + r, h - 1);
      for (std::size_t yy = y > r ? y - r : 0; yy <= y1; ++yy)
        if (row_min[at(x, yy)] < v || row_max[at(x, yy)] > v) {
          boundary[at(x, y)] = 1;
          break;
        }
    }
  return boundary;
}

double seam_rms(const image::Image& reference, const image::Image& image,
                std::span<const std::uint8_t> lod_map, int radius) {
  check_pair(reference, image, "seam_rms");
  if (lod_map.empty()) return std::numeric_limits<double>::quiet_NaN();
  const std::vector<std::uint8_t> boundary =
      lod_boundary(lod_map, image.width, image.height, radius);
  const auto channels = static_cast<std::size_t>(image.channels);
  const auto w = static_cast<std::size_t>(image.width);
  const auto error = [&](std::size_t p, std::size_t c) {
    return int{image.pixels[p * channels + c]} - int{reference.pixels[p * channels + c]};
  };
  double sum = 0;
  std::size_t values = 0;
  // Pairs of neighbours (right, below) both on the boundary: the step of the error between them.
  for (std::size_t p = 0; p < boundary.size(); ++p) {
    if (!boundary[p]) continue;
    const std::size_t x = p % w;
    for (const std::size_t q : {x + 1 < w ? p + 1 : p, p + w < boundary.size() ? p + w : p}) {
      if (q == p || !boundary[q]) continue;
      for (std::size_t c = 0; c < channels; ++c) {
        const auto d = static_cast<double>(error(p, c) - error(q, c));
        sum += d * d;
      }
      values += channels;
    }
  }
  return values > 0 ? std::sqrt(sum / static_cast<double>(values))
                    : std::numeric_limits<double>::quiet_NaN();
}

}  // namespace volreel::stream_bench
