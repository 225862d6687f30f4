// tour_run.cpp: a bench stream run and its measurement (see tour_run.hpp).
#include "volreel/stream_bench/tour_run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include "volreel/datasets/volume.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/image/image.hpp"
#include "volreel/loop/cpu_frame_loop.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/stream/selection.hpp"

namespace volreel::stream_bench {
namespace {

using Clock = std::chrono::steady_clock;

}  // namespace

GroundTruth::GroundTruth(const format::Container& container,
                         std::unique_ptr<datasets::SeriesReader> series)
    : container_(container), series_(std::move(series)), steps_(container) {
  const format::Manifest& m = container.manifest();
  geometry_ = cpu_render::VolumeGeometry::of(m.dims, m.shape());
  if (series_) {
    const auto& info = series_->info();
    if (info.dims.x != m.dims[0] || info.dims.y != m.dims[1] || info.dims.z != m.dims[2])
      throw InputError("--series " + info.source + ": the series is " + to_string(info.dims) +
                       ", the container " + std::to_string(m.dims[0]) + "x" +
                       std::to_string(m.dims[1]) + "x" + std::to_string(m.dims[2]));
    if (info.frames < container.frame_count())
      throw InputError("--series " + info.source + ": the series has " +
                       std::to_string(info.frames) + " frames, the container " +
                       std::to_string(container.frame_count()));
  }
}

const std::vector<float>& GroundTruth::frame(std::size_t t, std::size_t keep) {
  auto it = cache_.find(t);
  if (it != cache_.end()) return it->second;
  while (cache_.size() >= 4)
    cache_.erase(cache_.begin()->first == keep ? std::next(cache_.begin()) : cache_.begin());
  std::vector<float> values;
  if (series_) {
    const auto& d = series_->info().dims;
    values.resize(d.voxels());
    series_->read_frame(t, values);
  } else {
    values = steps_.decode(t, geometry_.levels - 1).data;
  }
  return cache_.emplace(t, std::move(values)).first->second;
}

cpu_render::RgbaImage GroundTruth::render(double playhead, const player::OrbitCamera& camera,
                                          const cpu_render::TransferFunction& tf,
                                          const cpu_render::RenderOptions& options) {
  const std::size_t keyframes = container_.frame_count();
  const double p = std::clamp(playhead, 0.0, static_cast<double>(keyframes - 1));
  const auto t0 = static_cast<std::size_t>(std::floor(p));
  const std::size_t t1 = std::min(t0 + 1, keyframes - 1);
  const auto f = static_cast<float>(p - static_cast<double>(t0));
  const std::uint32_t finest = geometry_.levels - 1;
  const std::vector<float>& a = frame(t0);
  const std::vector<float>& b = frame(t1, t0);
  return cpu_render::render_reference({geometry_.dims, a, finest}, {geometry_.dims, b, finest}, f,
                                      geometry_, camera, tf, options);
}

const char* policy_name(stream::PriorityPolicy p) {
  return p == stream::PriorityPolicy::patent ? "patent" : "nearest";
}

namespace {

double ms_since(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

cpu_render::TourFrame frame_at(const RunSetup& s, double time) {
  cpu_render::TourFrame f = s.tour->at(time);
  if (s.transfer) f.transfer = *s.transfer;
  f.camera.width = s.width;
  f.camera.height = s.height;
  return f;
}

/// Whether frame t holds exact data for spatial node `node`: its own brick, or an ancestor that is
/// a constant subtree at t.
bool has_exact_data(const stream::SpatialIndex& index, std::uint32_t node, std::uint32_t t) {
  if (index.find_keyframe(node, t) != stream::no_keyframe) return true;
  for (std::uint32_t a = index.node(node).parent; a != stream::no_node; a = index.node(a).parent) {
    const stream::KeyframeId k = index.find_keyframe(a, t);
    if (k != stream::no_keyframe && index.keyframe(k).subtree_constant) return true;
  }
  return false;
}

}  // namespace

/// Target nodes drawn exactly as with everything loaded (those the ray feedback did not hide):
/// both picks at full detail and from the time steps with data nearest the playhead on each
/// side. StreamStats::fraction_at_target counts
/// spatial detail only — a node drawn from its own bricks of keyframes far from the playhead
/// counts there (a stale frame after a seek), not here. Recomputed from the scheduler's atlas
/// with the same view traversal and selection as its update(), before the restricted drawing
/// (SelectionSettings::restricted): a node it draws coarser still counts here. It only draws a
/// node coarser while a touching region's finer bricks are missing, so once the view's bricks
/// are all loaded both agree.
std::uint32_t current_target_nodes(const stream::StreamScheduler& scheduler,
                                   const player::OrbitCamera& camera, double playhead,
                                   stream::ViewTraversal& view,
                                   stream::ResidentKeyframes& resident) {
  const stream::SpatialIndex& index = scheduler.index();
  if (index.node_count() == 0 || index.frame_count() == 0) return 0;
  view.run(index, camera, scheduler.settings().priority.sse_target,
           scheduler.settings().priority.restricted);
  std::vector<stream::ResidentKeyframe> entries;
  for (const std::uint32_t slot : scheduler.atlas().occupied_slots()) {
    const auto key = scheduler.atlas().key(slot);
    if (!key) continue;
    const stream::KeyframeId id = index.find_keyframe(*key);
    if (id != stream::no_keyframe) entries.push_back({id, slot});
  }
  resident.assign(index, entries);
  const double p = std::clamp(playhead, 0.0, static_cast<double>(index.frame_count() - 1));
  std::uint32_t current = 0;
  stream::StoredTimes stored;  // shared by the view's nodes, as in the scheduler's SVO pass
  stored.start(index, p);
  for (const stream::ViewTraversal::Visit& v : view.visits()) {
    // (Nodes the ray feedback hid are not target nodes: StreamStats::hidden_targets.)
    if (v.refine || scheduler.hidden(v.node)) continue;
    const stream::KeyframePair pair = stream::select_keyframe_pair(
        index, v.node, p, resident, scheduler.settings().selection, &stored);
    if (!pair.at_full_detail()) continue;
    // The time steps with data nearest the playhead on each side (p itself when it has data).
    std::int64_t before = static_cast<std::int64_t>(std::floor(p));
    while (before >= 0 && !has_exact_data(index, v.node, static_cast<std::uint32_t>(before)))
      --before;
    auto after = static_cast<std::int64_t>(std::ceil(p));
    const auto frames = static_cast<std::int64_t>(index.frame_count());
    while (after < frames && !has_exact_data(index, v.node, static_cast<std::uint32_t>(after)))
      ++after;
    const bool a_ok = before < 0 ? true : pair.a.t == static_cast<std::uint32_t>(before);
    const bool b_ok = after >= frames ? true : pair.b.t == static_cast<std::uint32_t>(after);
    if (before < 0 && after >= frames) continue;
    // With data on one side only, the selection takes the other side's nearest for both.
    const bool ok = before < 0        ? pair.a.t == static_cast<std::uint32_t>(after) && b_ok
                    : after >= frames ? pair.b.t == static_cast<std::uint32_t>(before) && a_ok
                                      : a_ok && b_ok;
    current += ok ? 1 : 0;
  }
  return current;
}

RunResult run_tour(const RunSetup& s, stream::PriorityPolicy policy, const Progress& progress) {
  RunResult r;
  r.name = policy_name(policy);
  loop::FrameLoopOptions options;
  options.scheduler = s.settings;
  options.scheduler.priority.policy = policy;
  double simulated_time = 0;
  if (s.simulated_fps > 0)
    options.scheduler.loader.clock = [&simulated_time] { return simulated_time; };
  options.atlas_bytes = std::uint64_t{s.settings.atlas_slots} *
                        loop::CpuFrameLoop::gpu_slot_bytes(s.container->manifest().shape());
  options.width = s.width;
  options.height = s.height;
  options.render = s.render;
  options.render.level_map = true;  // for the seam metric (measure)
  // Indexing (frame files opened and validated) happened once, before the runs.
  loop::CpuFrameLoop frames(*s.container, *s.index, options);
  const stream::StreamScheduler& scheduler = frames.scheduler();
  const double duration = s.tour->duration();

  const format::ContainerSource& source = s.container->source();
  const std::uint64_t requests_before = source.requests(), bytes_before = source.bytes_received();
  const auto start = Clock::now();
  bool root = false;
  std::uint64_t uploaded = 0;
  stream::ViewTraversal view;
  stream::ResidentKeyframes resident;
  for (std::uint64_t frame = 1;; ++frame) {
    const auto frame_start = Clock::now();
    const double time =
        std::min(s.simulated_fps > 0 ? static_cast<double>(frame - 1) / s.simulated_fps
                                     : std::chrono::duration<double>(frame_start - start).count(),
                 duration);
    simulated_time = time;
    const cpu_render::TourFrame tf = frame_at(s, time);
    FrameRecord rec;
    rec.time = time;
    rec.playhead = tf.playhead;
    // 0. On the simulated clock: what the previous frame's working set draws at this frame's
    //    view and time, before this frame's uploads change the atlas (working-set popping).
    cpu_render::RgbaImage previous_working_set;
    if (s.simulated_fps > 0)
      previous_working_set =
          frames.render_previous_working_set(tf.camera, tf.playhead, tf.transfer);
    // 1.-4. Scheduler, decode (a bad payload becomes the lowest value), render, retire.
    const loop::FrameReport report = frames.frame(tf.camera, tf.playhead, tf.transfer);
    if (report.ticket != frame) throw std::logic_error("bench stream: frame numbers out of step");
    const stream::FrameUpdate& update = frames.last_update();
    // The scheduler's problems; a decode error is reported to it and printed with the next frame's.
    for (const std::string& e : update.new_errors)
      std::fprintf(stderr, "\nvolreel: warning: %s\n", e.c_str());
    for (const stream::BrickUpload& u : update.uploads) {
      if (u.key.level == 0) root = true;
      uploaded += u.payload.size();
    }
    rec.update_ms = report.timings.schedule_ms;
    rec.decode_ms = report.timings.decode_ms;
    rec.render_ms = report.timings.render_ms;
    const cpu_render::RgbaImage& drawn = frames.last_image(report.ticket);
    rec.image = cpu_render::to_image(drawn);
    if (previous_working_set.width > 0)
      rec.working_set_popping =
          image_change_rms(cpu_render::to_image(previous_working_set), rec.image);
    rec.lod_map = drawn.levels;
    rec.stats = report.stats;
    rec.root_resident = root;
    rec.bytes_uploaded = uploaded;
    const auto t_current = Clock::now();
    rec.current_nodes = current_target_nodes(scheduler, tf.camera, tf.playhead, view, resident);
    rec.fraction_current = update.stats.target_nodes > 0
                               ? static_cast<double>(rec.current_nodes) /
                                     static_cast<double>(update.stats.target_nodes)
                               : 1.0;
    rec.measure_ms = ms_since(t_current);
    if (root && std::isnan(r.first_root_s)) r.first_root_s = time;
    rec.frame_ms = ms_since(frame_start);
    char status[96];
    std::snprintf(status, sizeof status, "frame %llu, playhead %.2f, %.0f%% at target LOD",
                  static_cast<unsigned long long>(frame), tf.playhead,
                  100 * update.stats.fraction_at_target);
    if (progress) progress(time, duration, status);
    r.frames.push_back(std::move(rec));
    if (time >= duration) break;
  }
  r.wall_s = std::chrono::duration<double>(Clock::now() - start).count();
  r.transfer_requests = source.requests() - requests_before;
  r.transfer_bytes = source.bytes_received() - bytes_before;
  if (!r.frames.empty()) {
    r.bricks_loaded = r.frames.back().stats.bricks_loaded;
    r.loader_reads = r.frames.back().stats.loader_reads;
  }
  r.errors = s.index_errors + scheduler.error_count();
  return r;
}

/// Ground truth for every frame of a run (after the timed loop), then the averages.
void measure(RunResult& r, const RunSetup& s, GroundTruth& truth,
             const std::vector<std::pair<double, double>>& seeks, const std::filesystem::path& out,
             std::size_t png_every, const Progress& progress) {
  // 1. Frames in playhead order, so each original frame is read about once.
  std::vector<std::size_t> order(r.frames.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return r.frames[a].playhead < r.frames[b].playhead;
  });
  // PNGs (streamed | ground truth side by side): every png_every-th frame, else the first frame
  // after each seek, the first frame half a second after it, and the last frame.
  std::vector<bool> png(r.frames.size(), false);
  if (png_every > 0) {
    for (std::size_t i = 0; i < png.size(); i += png_every) png[i] = true;
  } else {
    for (const auto& [time, keyframe] : seeks)
      for (const double at : {time, time + 0.5}) {
        const auto it = std::find_if(r.frames.begin(), r.frames.end(),
                                     [&](const FrameRecord& f) { return f.time >= at; });
        if (it != r.frames.end()) png[static_cast<std::size_t>(it - r.frames.begin())] = true;
      }
  }
  if (!png.empty()) png.back() = true;
  const std::filesystem::path png_dir = out / ("frames_" + r.name);
  // Popping compares each frame with the previous one in time order, which the playhead order
  // visits at some other point: a frame's reference image is kept until both of its neighbours in
  // time have been visited, so only the frames at the edges of the visited playhead ranges hold
  // one (a few, unless the playhead jumps back and forth between frames).
  const std::size_t n = r.frames.size();
  std::vector<image::Image> references(n);
  std::vector<bool> visited(n, false);
  for (FrameRecord& f : r.frames) f.popping = f.seam = std::numeric_limits<double>::quiet_NaN();
  {
    std::size_t done = 0;
    for (const std::size_t i : order) {
      FrameRecord& f = r.frames[i];
      const cpu_render::TourFrame tf = frame_at(s, f.time);
      image::Image reference =
          cpu_render::to_image(truth.render(f.playhead, tf.camera, tf.transfer, s.render));
      const psnr::ImageComparison c = psnr::compare_images(reference, f.image);
      f.psnr = c.psnr;
      f.ssim = c.ssim;
      f.seam = seam_rms(reference, f.image, f.lod_map);
      if (png[i]) {
        std::filesystem::create_directories(png_dir);
        image::Image both;
        both.width = 2 * f.image.width;
        both.height = f.image.height;
        both.channels = 3;
        both.pixels.resize(static_cast<std::size_t>(both.width) *
                           static_cast<std::size_t>(both.height) * 3);
        const auto row = static_cast<std::size_t>(f.image.width) * 3;
        for (std::size_t y = 0; y < static_cast<std::size_t>(f.image.height); ++y) {
          std::copy_n(f.image.pixels.begin() + static_cast<std::ptrdiff_t>(y * row), row,
                      both.pixels.begin() + static_cast<std::ptrdiff_t>(2 * y * row));
          std::copy_n(reference.pixels.begin() + static_cast<std::ptrdiff_t>(y * row), row,
                      both.pixels.begin() + static_cast<std::ptrdiff_t>((2 * y + 1) * row));
        }
        char name[48];
        std::snprintf(name, sizeof name, "frame_%05zu.png", i);
        image::write_png(png_dir / name, both);
      }
      // Popping with the neighbours in time already visited; then the references no longer
      // needed are dropped.
      references[i] = std::move(reference);
      visited[i] = true;
      if (i > 0 && visited[i - 1])
        f.popping = popping_rms(references[i - 1], r.frames[i - 1].image, references[i], f.image);
      if (i + 1 < n && visited[i + 1])
        r.frames[i + 1].popping =
            popping_rms(references[i], f.image, references[i + 1], r.frames[i + 1].image);
      for (std::size_t k = i > 0 ? i - 1 : 0; k <= std::min(i + 1, n - 1); ++k)
        if (visited[k] && (k == 0 || visited[k - 1]) && (k + 1 == n || visited[k + 1]))
          references[k] = image::Image{};
      ++done;
      if (progress) progress(static_cast<double>(done), static_cast<double>(order.size()), {});
    }
  }
  // 2. Averages (popping and seam error among them) and the time from each seek to full quality.
  stream_bench::summarize(r, seeks);
}

}  // namespace volreel::stream_bench
