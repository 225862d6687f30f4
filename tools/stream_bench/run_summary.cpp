// run_summary.cpp: the averages and the seek times of a bench stream run (see run_summary.hpp).
#include "volreel/stream_bench/run_summary.hpp"

#include <algorithm>
#include <cmath>

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

}  // namespace volreel::stream_bench
