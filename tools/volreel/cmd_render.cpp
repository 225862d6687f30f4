// cmd_render.cpp: `volreel render NAME.vreel` — headless rendering of a tour (no window, no
// display): every frame drives the streaming loop (scheduler → uploads → decode → ray casting) on
// the Vulkan device, or on the CPU (--renderer), and writes DIR/frame_NNNNN.png and
// a row of DIR/metrics.csv; optionally encodes the frames with ffmpeg (--video) and measures each
// frame against a ground-truth render of the original series (--compare). Without --realtime a
// frame is drawn once the bricks it needs have arrived (loop::wait_for_view, within
// --wait-timeout), so a movie never starts black or shows data still streaming in; with it, frames
// keep the tour's pace and show what has arrived, as the player does.
#include <cctype>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "commands.hpp"
#include "loop_options.hpp"
#include "process.hpp"
#include "progress.hpp"
#include "read_failures.hpp"
#include "remote_options.hpp"
#include "render_truth.hpp"
#include "volreel/cpu_render/renderer.hpp"
#include "volreel/cpu_render/tour.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/loop/auto_transfer.hpp"
#include "volreel/loop/frame_loop.hpp"
#include "volreel/loop/loop_settings.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/vulkan_render/open_frame_loop.hpp"

namespace volreel::cli {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct RenderCommandOptions {
  std::string container, tour, out, video, compare, transfer;
  std::string renderer = "auto";
  bool cpu = false, realtime = false;
  double wait_timeout = 30;  ///< seconds a frame waits for its bricks (not with --realtime)
  std::size_t max_frames = 0;
  loop::LoopSettings loop;
  ReaderOptions reader;
  RemoteCli remote;
};

/// The frames an earlier render wrote into `dir`: the rows of its metrics.csv (a row a frame,
/// under volreel's header), 0 where there is none.
std::size_t earlier_render_frames(const fs::path& dir) {
  std::ifstream csv(dir / "metrics.csv");
  std::string line;
  if (!csv || !std::getline(csv, line) || !line.starts_with("frame,time_s,playhead,")) return 0;
  std::size_t rows = 0;
  while (std::getline(csv, line)) rows += !line.empty();
  return rows;
}

/// "frame_00042.png": the name of frame i.
std::string frame_png(std::size_t i) {
  char name[32];
  std::snprintf(name, sizeof name, "frame_%05zu.png", i);
  return name;
}

/// The PNGs of the first n frames: "frame_00000.png .. frame_00041.png", "frame_00000.png" or
/// "no frame".
std::string frames_text(std::size_t n) {
  if (n == 0) return "no frame";
  return n == 1 ? frame_png(0) : frame_png(0) + " .. " + frame_png(n - 1);
}

/// Removes frame_NNNNN.png of `dir` for N in [frames, earlier): those of an earlier, longer render
/// into the same folder (earlier_render_frames), which would otherwise pass for this one's.
/// Returns how many it removed.
std::size_t remove_later_frames(const fs::path& dir, std::size_t frames, std::size_t earlier) {
  std::size_t removed = 0;
  for (std::size_t i = frames; i < earlier; ++i) {
    const std::string name = frame_png(i);
    std::error_code ec;
    if (fs::is_regular_file(fs::symlink_status(dir / name, ec)) && fs::remove(dir / name, ec))
      ++removed;
  }
  return removed;
}

void run_render(const RenderCommandOptions& o) {
  check_renderer_options(o.renderer, o.cpu, o.loop.decode);
  // 1. Input, tour, output folder; ffmpeg is checked before any work.
  if (const std::string given = o.reader.given(); !given.empty() && o.compare.empty())
    throw InputError(given + ": options of the --compare series, which is not given; give " +
                     "--compare SERIES, or leave them out (--max-frames limits the frames " +
                     "rendered)");
  const format::Container container(open_container_source(o.container, o.remote));
  const format::Manifest& m = container.manifest();
  // The manifest's (a constant sequence's empty value range widened), over the frames written.
  cpu_render::TourContext tour_context = cpu_render::TourContext::of(m);
  tour_context.keyframes = container.frame_count();
  const cpu_render::Tour tour = o.tour.empty() ? cpu_render::Tour::default_for(tour_context)
                                               : cpu_render::Tour::load(o.tour, tour_context);
  std::string ffmpeg;
  if (!o.video.empty()) {
    ffmpeg = find_on_path("ffmpeg");
    if (ffmpeg.empty())
      throw InputError(
          "--video " + o.video +
          ": needs ffmpeg, which is not installed or not on PATH (Debian: apt-get install ffmpeg); "
          "nothing was rendered: install it, or run without --video to write the PNG frames only");
  }
  const fs::path out = o.out;
  if (fs::exists(out) && !fs::is_directory(out))
    throw InputError("--out " + o.out + ": exists and is not a directory");
  if (datasets::path_within(o.container, out))
    throw InputError("--out " + o.out + ": is inside the container " + o.container +
                     ", whose files would mix with the frames; choose a folder outside it");
  format::detail::check_writable(out, "--out");
  if (!o.video.empty()) {
    if (fs::is_directory(o.video))
      throw InputError("--video " + o.video + ": is a directory; give the video file's name");
    if (datasets::path_within(o.container, o.video))
      throw InputError("--video " + o.video + ": is inside the container " + o.container +
                       "; choose a place outside it");
    // (Its name, a video's, is none of the files this render writes into --out.)
    // ffmpeg writes the video in place: into a FIFO or a device too.
    const fs::file_type type = fs::status(o.video).type();
    if (type != fs::file_type::fifo && type != fs::file_type::character)
      format::detail::check_writable(o.video, "--video");
  }
  loop::FrameLoopOptions options;
  options.width = tour.width();
  options.height = tour.height();
  options.render.background = {0.06f, 0.06f, 0.08f};
  try {
    loop::apply(o.loop, options);
  } catch (const std::invalid_argument& e) {
    throw InputError(e.what());
  }
  // Without a tour, the default tour with a transfer function from the data's quantiles (the
  // default tour's cool-warm over the whole range leaves turbulence pressure an opaque haze).
  const std::string transfer_spec = !o.transfer.empty() ? o.transfer : o.tour.empty() ? "auto" : "";
  std::optional<cpu_render::TransferFunction> transfer;
  if (!transfer_spec.empty()) transfer = loop::transfer_from_spec(transfer_spec, container);
  std::optional<GroundTruth> truth;
  if (!o.compare.empty()) truth.emplace(o.compare, o.reader, m);
  fs::create_directories(out);  // once every option is known good

  // 2. The renderer: Vulkan, or the CPU where there is no device.
  // Vulkan frames with readback (serial: the time split is exact), or the CPU loop.
  const std::unique_ptr<loop::FrameLoop> renderer = vulkan_render::open_frame_loop(
      container, options,
      o.cpu ? vulkan_render::RendererChoice::cpu : vulkan_render::parse_renderer(o.renderer),
      vulkan_render::NoDevice::use_cpu, "");
  const std::size_t frames =
      o.max_frames ? std::min(o.max_frames, tour.frame_count()) : tour.frame_count();
  std::printf("volreel render\nmachine: %s\ndevice:  %s\ninput:   %s: %ux%ux%u, %zu frames, %s\n",
              describe_machine().c_str(), renderer->describe().c_str(),
              remote::without_credentials(o.container).c_str(), m.dims[0], m.dims[1], m.dims[2],
              container.frame_count(), m.codec == format::Codec::ksvd ? "ksvd" : "zfp");
  std::printf("transfer function: %s\n",
              transfer_spec.empty() ? "the tour's" : transfer_spec.c_str());
  std::printf(
      "tour:    %s, %.1f s at %.0f fps, %zu frames, %dx%d\natlas:   %u slots (%.0f MiB), upload "
      "budget %.0f MiB/frame, "
      "bandwidth %s, latency %s, SSE target %g\n",
      o.tour.empty() ? "default tour" : o.tour.c_str(), tour.duration(), tour.fps(), frames,
      options.width, options.height, renderer->slot_count(), o.loop.atlas_mb,
      o.loop.upload_budget_mb,
      options.scheduler.loader.bandwidth_bytes_per_s > 0 ? o.loop.bandwidth.c_str() : "unlimited",
      o.loop.latency.c_str(), o.loop.sse_target);
  if (remote::is_url(o.container) && (options.scheduler.loader.bandwidth_bytes_per_s > 0 ||
                                      options.scheduler.loader.latency_s > 0))
    std::printf(
        "note: for a URL the network is the link: --bandwidth and --latency are not simulated on "
        "top of it\n");
  std::fflush(stdout);

  // 3. Frames: render, write the PNG on a worker thread while the next frame renders.
  const std::size_t earlier = earlier_render_frames(out);
  // Over an earlier render the frames go to a folder of their own and are moved in once all are
  // drawn, so that a run that fails or is interrupted leaves the earlier one whole.
  const fs::path written = earlier > 0 ? out / format::detail::replacement_folder_name : out;
  struct Aside {
    fs::path dir;
    ~Aside() {
      std::error_code ec;
      if (!dir.empty()) fs::remove_all(dir, ec);
    }
  } aside;
  if (earlier > 0) {
    std::error_code ec;
    fs::remove_all(written, ec);  // what an interrupted run left
    if (!fs::create_directory(written, ec) || ec)
      throw InputError("cannot create " + written.string() + ": " + ec.message());
    aside.dir = written;
  }
  std::ofstream csv(written / "metrics.csv");
  if (!csv)
    throw InputError("cannot write " + (written / "metrics.csv").string() + ": " +
                     std::strerror(errno));
  csv << "frame,time_s,playhead,frame_ms,fps,schedule_ms,upload_ms,decode_ms,render_ms,readback_ms,"
         "atlas_occupied,"
         "atlas_capacity,atlas_occupancy,requests_in_flight,requests_sent,uploads,mb_uploaded,mb_"
         "loaded,"
         "fraction_at_target,holes,svo_nodes,svo_leaves,errors,wait_ms"
      << (truth ? ",psnr_db,ssim" : "") << '\n';
  std::future<void> writing;
  double sum_ms[5] = {0, 0, 0, 0, 0};
  double sum_psnr = 0, sum_ssim = 0;
  std::size_t compared = 0, timeouts = 0;
  std::size_t atlas_short = 0;  // frames drawn coarser than their target: the atlas was full
  ReadFailures failures;
  double waited_s = 0;
  loop::FrameReport last;
  const auto start = Clock::now();
  // Ctrl-C or SIGTERM stops between frames (or while a frame waits for its bricks): the frames
  // drawn so far and their rows of metrics.csv are complete.
  std::size_t drawn = 0;
  std::optional<StopOnSignal> stop;  // for the frames only: ffmpeg after them takes Ctrl-C itself
  stop.emplace();
  try {
    ProgressBar bar("rendering", "frames");
    for (std::size_t i = 0; i < frames; ++i) {
      stop_if_interrupted();
      const double time = tour.frame_time(i);
      if (o.realtime)
        std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(
                                                  std::chrono::duration<double>(time)));
      cpu_render::TourFrame tf = tour.at(time);
      if (transfer) tf.transfer = *transfer;
      tf.camera.width = options.width;
      tf.camera.height = options.height;
      // Without --realtime a frame is drawn once what it needs has arrived (or nothing more
      // can), so that a movie never shows a frame still streaming in.
      double wait_ms = 0;
      std::size_t new_errors = 0;  // bricks and frames that failed while this frame waited or drew
      if (!o.realtime) {
        loop::ViewWait wait = loop::wait_for_view(*renderer, tf.camera, tf.playhead, o.wait_timeout,
                                                  stop_if_interrupted);
        wait_ms = 1000 * wait.seconds;
        waited_s += wait.seconds;
        failures.add(wait.new_errors, "\n");
        new_errors += wait.new_errors.size();
        if (!wait.complete && !wait.timed_out && wait.stats.atlas_capacity > 0 &&
            wait.stats.atlas_occupied >= wait.stats.atlas_capacity)
          ++atlas_short;
        if (wait.timed_out) {
          ++timeouts;
          std::fprintf(stderr,
                       "\nvolreel: warning: frame %zu drawn after waiting %.1f s (--wait-timeout) "
                       "with %.0f%% of its visible nodes at their target level of detail and %zu "
                       "requests in flight\n",
                       i, wait.seconds, 100 * wait.stats.fraction_at_target,
                       wait.stats.requests_in_flight);
        }
      }
      const loop::FrameReport report = renderer->frame(tf.camera, tf.playhead, tf.transfer, true);
      const auto read_start = Clock::now();
      cpu_render::RgbaImage image = renderer->read_back(report.ticket);
      const double readback_ms =
          std::chrono::duration<double, std::milli>(Clock::now() - read_start).count();
      failures.add(report.new_errors, "\n");
      new_errors += report.new_errors.size();
      std::optional<psnr::ImageComparison> quality;
      if (truth) {
        const auto reference = truth->render(tf.playhead, container.frame_count(), tf.camera,
                                             tf.transfer, options.render);
        quality =
            psnr::compare_images(cpu_render::to_image(reference), cpu_render::to_image(image));
        sum_psnr += quality->psnr;
        sum_ssim += quality->ssim;
        ++compared;
      }
      if (writing.valid()) writing.get();
      writing =
          std::async(std::launch::async, [path = written / frame_png(i), img = std::move(image)] {
            cpu_render::write_png(path, img);
          });
      const auto& s = report.stats;
      const auto& t = report.timings;
      const double frame_ms = t.frame_ms + readback_ms;
      const double values[5] = {frame_ms, t.schedule_ms, t.upload_ms, t.decode_ms, t.render_ms};
      for (int k = 0; k < 5; ++k) sum_ms[k] += values[k];
      char row[512];
      std::snprintf(row, sizeof row,
                    "%zu,%.4f,%.4f,%.3f,%.2f,%.3f,%.3f,%.3f,%.3f,%.3f,%u,%u,%.4f,%zu,%zu,%zu,%.4f,%"
                    ".4f,%.4f,%u,%u,%u,%zu,%.3f",
                    i, time, tf.playhead, frame_ms, 1000.0 / frame_ms, t.schedule_ms, t.upload_ms,
                    t.decode_ms, t.render_ms, readback_ms, s.atlas_occupied, s.atlas_capacity,
                    s.atlas_capacity ? double(s.atlas_occupied) / double(s.atlas_capacity) : 0.0,
                    s.requests_in_flight, s.requests_sent, s.uploads,
                    double(s.bytes_uploaded) * 1e-6, double(s.bytes_loaded) * 1e-6,
                    s.fraction_at_target, s.holes, s.svo_nodes, s.svo_leaves, new_errors, wait_ms);
      csv << row;
      if (quality) csv << ',' << quality->psnr << ',' << quality->ssim;
      csv << '\n' << std::flush;  // every frame's row, also when the run is interrupted
      char status[96];
      std::snprintf(status, sizeof status, "%.1f fps, %.0f%% at target LOD", 1000.0 / frame_ms,
                    100 * s.fraction_at_target);
      drawn = i + 1;  // its PNG on its way, its row written (the update may stop the run)
      last = report;
      bar.update({static_cast<double>(i + 1), static_cast<double>(frames), status});
    }
    if (writing.valid()) writing.get();
    bar.finish();
  } catch (const Interrupted&) {
    if (writing.valid()) writing.get();
    csv.close();
    if (earlier > 0)
      std::fprintf(stderr,
                   "\nvolreel render: interrupted after %zu of %zu frames, which are not kept: "
                   "%s holds the earlier render's %s and metrics.csv as they were\n",
                   drawn, frames, out.c_str(), frames_text(earlier).c_str());
    else
      std::fprintf(stderr,
                   "\nvolreel render: interrupted after %zu of %zu frames: %s holds %s, each with "
                   "its row of metrics.csv\n",
                   drawn, frames, out.c_str(), frames_text(drawn).c_str());
    throw;
  }
  stop.reset();
  csv.close();
  if (!csv) throw InputError("writing " + (written / "metrics.csv").string() + " failed");
  if (earlier > 0) {
    // The earlier render's metrics.csv goes first, so that none lists a mix of frames. Should a
    // move fail, what is not moved yet stays where it is, and the message says where.
    aside.dir.clear();
    try {
      fs::remove(out / "metrics.csv");
      for (std::size_t i = 0; i < frames; ++i)
        fs::rename(written / frame_png(i), out / frame_png(i));
      fs::rename(written / "metrics.csv", out / "metrics.csv");
    } catch (const fs::filesystem_error& e) {
      throw InputError("moving the frames drawn in " + written.string() + " into " + out.string() +
                       " failed (" + e.code().message() +
                       "): the frames not moved and metrics.csv are still there");
    }
    aside.dir = written;  // empty now: removed on the way out
  }

  // 4. Summary, video.
  const double n = static_cast<double>(std::max<std::size_t>(frames, 1));
  std::printf(
      "\n%zu frames in %s: mean frame %.1f ms (%.1f fps): schedule %.1f, upload %.1f, decode %.1f, "
      "render %.1f ms\n",
      frames, format_duration(std::chrono::duration<double>(Clock::now() - start).count()).c_str(),
      sum_ms[0] / n, 1000.0 * n / sum_ms[0], sum_ms[1] / n, sum_ms[2] / n, sum_ms[3] / n,
      sum_ms[4] / n);
  std::printf(
      "last frame: %.0f%% of the visible nodes at their target LOD, atlas %u of %u slots, %.1f MB "
      "loaded\n",
      100 * last.stats.fraction_at_target, last.stats.atlas_occupied, last.stats.atlas_capacity,
      double(last.stats.bytes_loaded) * 1e-6);
  if (!o.realtime)
    std::printf("waited %.2f s in all for bricks before drawing frames%s\n", waited_s,
                timeouts ? (", " + std::to_string(timeouts) +
                            " frames drawn incomplete after --wait-timeout")
                               .c_str()
                         : "");
  if (atlas_short > 0)
    std::fprintf(stderr,
                 "volreel render: warning: %zu frames drawn with part of the view coarser than "
                 "its target level of detail: the view wants more bricks than the atlas's %u "
                 "slots hold; give a larger --atlas-mb\n",
                 atlas_short, renderer->slot_count());
  print_remote_summary(container.source(), "render");
  if (compared)
    std::printf(
        "image quality against the original series (CPU render_reference, time-interpolated): mean "
        "PSNR %.2f dB "
        "(10*log10(255^2/MSE), 8-bit RGB), mean SSIM %.4f over %zu frames\n",
        sum_psnr / double(compared), sum_ssim / double(compared), compared);
  std::printf("wrote %s/%s and %s\n", out.c_str(), frames_text(frames).c_str(),
              (out / "metrics.csv").c_str());
  if (const std::size_t stale = remove_later_frames(out, frames, earlier))
    std::printf(
        "removed %zu frame_NNNNN.png past frame_%05zu.png, left by an earlier, longer "
        "render into %s\n",
        stale, frames ? frames - 1 : 0, out.c_str());
  if (!ffmpeg.empty()) {
    // Exactly this run's frames (-frames:v: the folder may hold more frame_NNNNN.png that no
    // render's metrics.csv listed); '%' in the folder name escaped for ffmpeg's image-sequence
    // pattern; -nostdin: ffmpeg must not read the terminal (it stops a `volreel render ... &` job).
    std::string pattern;
    for (const char c : (out / "frame_").string())
      pattern += c == '%' ? std::string("%%") : std::string(1, c);
    pattern += "%05d.png";
    const fs::path video = o.video;
    if (const fs::path parent = video.parent_path(); !parent.empty())
      fs::create_directories(parent);
    // A file is written under a temporary name (the same extension, for ffmpeg's choice of
    // container) and renamed once complete: a failed encode leaves no half-written video, nor
    // replaces an earlier one. A FIFO or a device is written in place.
    const fs::file_type type = fs::status(video).type();
    // (A link is written through, as ffmpeg does, not replaced by the renamed file.)
    const bool in_place = type == fs::file_type::fifo || type == fs::file_type::character ||
                          fs::is_symlink(fs::symlink_status(video));
    const fs::path target = in_place ? video
                                     : video.parent_path() / (video.stem().string() + ".partial" +
                                                              video.extension().string());
    const int status =
        run_program(ffmpeg, {"-nostdin", "-y", "-loglevel", "error", "-framerate",
                             format::number_text(tour.fps()), "-start_number", "0", "-i", pattern,
                             "-frames:v", std::to_string(frames), "-c:v", "libx264", "-pix_fmt",
                             "yuv420p", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", target.string()});
    std::error_code ec;
    if (status != 0 && !in_place) fs::remove(target, ec);
    if (status < 0) throw InputError("could not run " + ffmpeg + " to encode " + o.video);
    if (status != 0)
      throw InputError("ffmpeg failed (exit status " + std::to_string(status) + ") encoding " +
                       o.video + " (its messages above); the frames are in " + out.string());
    if (!in_place) fs::rename(target, video);
    std::printf("wrote %s (%zu frames, H.264)\n", o.video.c_str(), frames);
  }
  // The frames are written (drawn without what failed); the exit status still says it failed.
  failures.fail_if_any("the frames were drawn without them");
  // Written and complete, but not what was asked: frames drawn before their bricks arrived.
  if (timeouts > 0)
    throw TargetMissed(std::to_string(timeouts) + " of " + std::to_string(frames) +
                       " frames were drawn incomplete after waiting --wait-timeout " +
                       format::number_text(o.wait_timeout) +
                       " s for their bricks (the warnings above); the frames and metrics.csv are "
                       "written");
}

}  // namespace

void add_render_command(CLI::App& app) {
  auto o = std::make_shared<RenderCommandOptions>();
  CLI::App* cmd = app.add_subcommand("render",
                                     "Render a tour of a container headlessly (no window or "
                                     "display): PNG frames and per-frame metrics, on the "
                                     "Vulkan device or, where there is none, on the CPU");
  cmd->add_option("CONTAINER", o->container, container_argument_help)->required();
  add_remote_options(*cmd, o->remote);
  cmd->add_option(
      "--tour", o->tour,
      "Tour JSON (camera, playhead and transfer-function keys; see player/cpu_render tour.hpp); "
      "default: the built-in tour (play, reverse, seek, slow motion, one orbit)");
  cmd->add_option("--out", o->out,
                  "Output folder for frame_NNNNN.png and metrics.csv (a row a frame); an earlier "
                  "render's there are replaced, and its frames past this run's last removed at "
                  "the end")
      ->required();
  cmd->add_option("--size", o->loop.size, "Image size WxH (default: the tour's, 512x512)")
      ->check(image_size());
  cmd->add_option(
      "--transfer", o->transfer,
      "Transfer function for every frame: auto (from the data's quantiles), a preset (grayscale, "
      "cool-warm, fire, turbulence, transparent) or a JSON file; default: the tour's, or auto "
      "without --tour");
  cmd->add_option("--video", o->video,
                  "Also encode the frames into this video with ffmpeg (H.264), an .mp4, .mkv or "
                  ".mov file")
      ->check(CLI::Validator(
          [](const std::string& text) {
            std::string ext = fs::path(text).extension().string();
            for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
            return ext == ".mp4" || ext == ".mkv" || ext == ".mov"
                       ? std::string()
                       : "expected a video file named .mp4, .mkv or .mov (ffmpeg chooses the "
                         "container by it), found '" +
                             text + "'";
          },
          "VIDEO"));
  add_renderer_options(*cmd, o->renderer, o->cpu);
  add_loop_options(*cmd, o->loop);
  cmd->add_flag("--realtime", o->realtime,
                "Start frame i no earlier than i/fps seconds in and draw it with whatever has "
                "arrived, as the player does; by default each frame is drawn once the bricks it "
                "needs have arrived (see --wait-timeout)");
  cmd->add_option("--wait-timeout", o->wait_timeout,
                  "Without --realtime: seconds a frame waits for its bricks before it is drawn "
                  "with what it has (reported; the exit status is then 3)")
      ->check(non_negative())
      ->capture_default_str();
  cmd->add_option("--max-frames", o->max_frames,
                  "Render only the first N frames of the tour (0: all of them)")
      ->check(in_range(0, 1e8))
      ->capture_default_str();
  cmd->add_option(
      "--compare", o->compare,
      "Original series (raw series directory, HDF5 or raw file): measure each frame's image "
      "PSNR/SSIM "
      "against a CPU render of the original data at that playhead, interpolated in time");
  o->reader.add_to(*cmd);
  cmd->callback([o] { run_render(*o); });
}

}  // namespace volreel::cli
