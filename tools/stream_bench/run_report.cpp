// run_report.cpp: a bench stream run as CSV, JSON and a table (see run_report.hpp).
#include "volreel/stream_bench/run_report.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

#include "volreel/datasets/volume.hpp"

namespace volreel::stream_bench {

std::string mb_text(double bytes) {
  char s[32];
  std::snprintf(s, sizeof s, "%.2f MB", bytes * 1e-6);
  return s;
}

void write_csv(const std::filesystem::path& path, const RunResult& r,
               const std::vector<std::pair<double, double>>& seeks) {
  std::ofstream csv(path);
  if (!csv) throw InputError("cannot write " + path.string());
  csv << "frame,time_s,playhead,seek,psnr_db,ssim,popping,working_set_popping,seam,"
         "fraction_at_target,fraction_current,"
         "at_target_nodes,current_nodes,target_nodes,holes,root_resident,bytes_loaded,"
         "bytes_uploaded_total,uploads,bytes_uploaded,requests_sent,requests_in_flight,"
         "arrivals_discarded,atlas_occupied,selected,svo_nodes,svo_leaves,hidden_nodes,"
         "hidden_targets,forced_nodes,restricted_nodes,blended_leaves,update_ms,decode_ms,render_"
         "ms,measure_ms,"
         "frame_ms\n";
  std::size_t next_seek = 0;
  for (std::size_t i = 0; i < r.frames.size(); ++i) {
    const FrameRecord& f = r.frames[i];
    bool seek = false;
    while (next_seek < seeks.size() && f.time >= seeks[next_seek].first) {
      seek = true;
      ++next_seek;
    }
    const auto& s = f.stats;
    char row[512];
    std::snprintf(
        row, sizeof row,
        "%zu,%.4f,%.4f,%d,%.4f,%.5f,%.4f,%.4f,%.4f,%.5f,%.5f,%u,%u,%u,%u,%d,%llu,%llu,%zu,%llu,%zu,"
        "%zu,%"
        "zu,%u,%u,%u,%u,%u,%u,%u,%u,%u,%.3f,%.3f,"
        "%.3f,%.3f,%.3f\n",
        i, f.time, f.playhead, seek ? 1 : 0, f.psnr, f.ssim, f.popping, f.working_set_popping,
        f.seam, s.fraction_at_target, f.fraction_current, s.at_target_nodes, f.current_nodes,
        s.target_nodes, s.holes, f.root_resident ? 1 : 0,
        static_cast<unsigned long long>(s.bytes_loaded),
        static_cast<unsigned long long>(f.bytes_uploaded), s.uploads,
        static_cast<unsigned long long>(s.bytes_uploaded), s.requests_sent, s.requests_in_flight,
        s.arrivals_discarded, s.atlas_occupied, s.selected, s.svo_nodes, s.svo_leaves,
        s.hidden_nodes, s.hidden_targets, s.forced_nodes, s.restricted_nodes, s.blended_leaves,
        f.update_ms, f.decode_ms, f.render_ms, f.measure_ms, f.frame_ms);
    csv << row;
  }
  csv.close();
  if (!csv) throw InputError("writing " + path.string() + " failed");
}

std::string seconds_or_dash(double s) {
  if (std::isnan(s)) return "-";
  char t[32];
  std::snprintf(t, sizeof t, "%.2f s", s);
  return t;
}

nlohmann::json summary_json(const RunResult& r) {
  nlohmann::json seeks = nlohmann::json::array();
  for (const SeekResult& s : r.seeks)
    seeks.push_back(
        {{"time_s", s.time},
         {"keyframe", s.keyframe},
         {"to_full_quality_s", std::isnan(s.to_full_quality) ? nlohmann::json(nullptr)
                                                             : nlohmann::json(s.to_full_quality)},
         {"to_full_lod_s",
          std::isnan(s.to_full_lod) ? nlohmann::json(nullptr) : nlohmann::json(s.to_full_lod)}});
  const auto finite = [](double v) {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  return {{"policy", r.name},
          {"frames", r.frames.size()},
          {"wall_s", r.wall_s},
          {"mean_psnr_db", r.mean_psnr},
          {"min_psnr_db", finite(r.min_psnr)},
          {"mean_ssim", r.mean_ssim},
          {"mean_popping", finite(r.mean_popping)},
          {"max_popping", finite(r.max_popping)},
          {"popping_frames", r.popping_frames},
          {"mean_popping_all", finite(r.mean_popping_all)},
          {"mean_working_set_popping", finite(r.mean_working_set_popping)},
          {"max_working_set_popping", finite(r.max_working_set_popping)},
          {"working_set_popping_frames", r.working_set_popping_frames},
          {"mean_seam", finite(r.mean_seam)},
          {"seam_frames", r.seam_frames},
          {"mean_fraction_at_target", r.mean_fraction},
          {"full_lod_frames_share", r.full_lod_share},
          {"mean_fraction_current", r.mean_current},
          {"full_quality_frames_share", r.full_quality_share},
          {"first_root_brick_s", finite(r.first_root_s)},
          {"frames_with_holes", r.hole_frames},
          {"frames_with_holes_after_first_root", r.frames_with_holes_after_root},
          {"max_holes_after_first_root", r.max_holes_after_root},
          {"bytes_loaded", r.bytes_loaded},
          {"bytes_uploaded", r.bytes_uploaded},
          {"bricks_loaded", r.bricks_loaded},
          {"loader_reads", r.loader_reads},
          {"transfer_requests", r.transfer_requests},
          {"transfer_bytes", r.transfer_bytes},
          {"errors", r.errors},
          {"mean_update_ms", r.mean_update_ms},
          {"mean_decode_ms", r.mean_decode_ms},
          {"mean_render_ms", r.mean_render_ms},
          {"mean_frame_ms", r.mean_frame_ms},
          {"seeks", seeks}};
}

void print_side_by_side(const std::vector<RunResult>& runs) {
  const auto row = [&](const char* label, auto&& cell) {
    std::printf("  %-40s", label);
    for (const RunResult& r : runs) std::printf(" %22s", cell(r).c_str());
    std::printf("\n");
  };
  const auto num = [](const char* fmt, double v) {
    char s[64];
    std::snprintf(s, sizeof s, fmt, v);
    return std::string(s);
  };
  std::printf("\n  %-40s", "");
  for (const RunResult& r : runs)
    std::printf(" %22s", r.name == "patent" ? "patent [0045]" : "nearest-keyframe-first");
  std::printf("\n");
  row("frames rendered", [&](const RunResult& r) { return std::to_string(r.frames.size()); });
  row("mean frame time (update/decode/render)", [&](const RunResult& r) {
    char s[64];
    std::snprintf(s, sizeof s, "%.0f (%.1f/%.1f/%.0f) ms", r.mean_frame_ms, r.mean_update_ms,
                  r.mean_decode_ms, r.mean_render_ms);
    return std::string(s);
  });
  row("mean image PSNR", [&](const RunResult& r) { return num("%.2f dB", r.mean_psnr); });
  row("min image PSNR", [&](const RunResult& r) { return num("%.2f dB", r.min_psnr); });
  row("mean image SSIM", [&](const RunResult& r) { return num("%.4f", r.mean_ssim); });
  // Popping and seam error in 8-bit units (RMS); '-' where no frame had a value.
  const auto units = [&](double v) { return std::isnan(v) ? std::string("-") : num("%.2f", v); };
  row("popping: uploads RMS, max / all RMS", [&](const RunResult& r) {
    return units(r.mean_popping) + ", " + units(r.max_popping) + " / " + units(r.mean_popping_all);
  });
  if (runs.front().working_set_popping_frames > 0)
    row("working-set popping: RMS, max", [&](const RunResult& r) {
      return units(r.mean_working_set_popping) + ", " + units(r.max_working_set_popping);
    });
  row("mean error step at LOD seams (frames)", [&](const RunResult& r) {
    return units(r.mean_seam) + " (" + std::to_string(r.seam_frames) + ")";
  });
  row("mean fraction of nodes at target LOD",
      [&](const RunResult& r) { return num("%.3f", r.mean_fraction); });
  row("frames entirely at target LOD",
      [&](const RunResult& r) { return num("%.1f %%", 100 * r.full_lod_share); });
  row("mean fraction at target LOD and time",
      [&](const RunResult& r) { return num("%.3f", r.mean_current); });
  row("frames at full quality (LOD and time)",
      [&](const RunResult& r) { return num("%.1f %%", 100 * r.full_quality_share); });
  row("first root brick drawn at",
      [&](const RunResult& r) { return seconds_or_dash(r.first_root_s); });
  row("frames with holes (all)", [&](const RunResult& r) { return std::to_string(r.hole_frames); });
  row("frames with holes after first root", [&](const RunResult& r) {
    return std::to_string(r.frames_with_holes_after_root) + " (max " +
           std::to_string(r.max_holes_after_root) + ")";
  });
  row("bytes loaded (read by the loader)",
      [&](const RunResult& r) { return mb_text(r.bytes_loaded); });
  row("bytes uploaded (decoded into the atlas)",
      [&](const RunResult& r) { return mb_text(r.bytes_uploaded); });
  const std::size_t seeks = runs.empty() ? 0 : runs.front().seeks.size();
  for (std::size_t k = 0; k < seeks; ++k) {
    char label[64];
    std::snprintf(label, sizeof label, "seek %zu (%.1f s -> %.2f): full LOD, quality", k + 1,
                  runs.front().seeks[k].time, runs.front().seeks[k].keyframe);
    row(label, [&](const RunResult& r) {
      return seconds_or_dash(r.seeks[k].to_full_lod) + ", " +
             seconds_or_dash(r.seeks[k].to_full_quality);
    });
  }
  if (seeks > 0)
    row("mean time to full quality (reached)", [&](const RunResult& r) {
      double sum = 0;
      std::size_t n = 0;
      for (const SeekResult& s : r.seeks)
        if (!std::isnan(s.to_full_quality)) sum += s.to_full_quality, ++n;
      return n ? num("%.2f s", sum / static_cast<double>(n)) + " (" + std::to_string(n) + "/" +
                     std::to_string(r.seeks.size()) + ")"
               : std::string("not reached");
    });
  row("errors", [&](const RunResult& r) { return std::to_string(r.errors); });
  if (runs.front().transfer_requests > 0) {
    row("HTTP requests per brick loaded", [&](const RunResult& r) {
      return num("%.3f", static_cast<double>(r.transfer_requests) /
                             static_cast<double>(std::max<std::uint64_t>(r.bricks_loaded, 1))) +
             " (" + std::to_string(r.transfer_requests) + ")";
    });
    row("bytes received / brick bytes", [&](const RunResult& r) {
      return num("%.3f", static_cast<double>(r.transfer_bytes) / std::max(r.bytes_loaded, 1.0));
    });
  }
  std::printf(
      "  (at target LOD: both keyframes from the node's own bricks, whichever keyframes they are; "
      "full quality:\n"
      "   also the keyframes around the playhead, as with everything loaded; '-': not reached "
      "before the next\n"
      "   seek; seek times have the resolution of one rendered frame; popping: RMS change of the "
      "image error\n"
      "   from the previous frame, its RMS over frames with uploads and over all (seeks and "
      "frames after holes\n"
      "   left out);%s seam: RMS step of the image\n"
      "   error between neighbouring pixels within 2 pixels of a level-of-detail boundary; all in "
      "8-bit units)\n",
      runs.front().working_set_popping_frames > 0
          ? " working-set popping: RMS change of the image from what the previous frame's\n"
            "   bricks and blending draw at this frame's view and time, over the same frames;"
          : "");
}

}  // namespace volreel::stream_bench
