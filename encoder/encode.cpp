// encode.cpp: the whole encode (encode.hpp) — value range, dictionary, ε, the series encoder.
#include "volreel/encoder/encode.hpp"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <utility>

#include "detail.hpp"
#include "volreel/dictionary/coreset.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/pyramid.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/frame_file.hpp"
#include "volreel/format/memory.hpp"

namespace volreel::encoder {

namespace {

namespace fs = std::filesystem;

/// Removes, once per process, the files "volreel-dictionary…-HOST-PID-N.bin" of the temporary
/// folder that this machine's processes left when they were killed (SIGTERM, SIGKILL, an MPI job
/// aborted: no destructor ran): HOST this machine's name, PID a process that is gone. Files of
/// other machines sharing the folder are left alone (their PIDs mean nothing here).
void remove_orphaned_temporaries() {
  static std::once_flag once;
  std::call_once(once, [] {
    const std::string host = "-" + format::detail::host_name() + "-";
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator(fs::temp_directory_path(ec), ec)) {
      const std::string name = entry.path().filename().string();
      if (!name.starts_with("volreel-dictionary") || !name.ends_with(".bin")) continue;
      const std::size_t last = name.rfind('-');
      const std::size_t before =
          last == std::string::npos || last == 0 ? std::string::npos : name.rfind('-', last - 1);
      if (before == std::string::npos || before + 1 < host.size() ||
          name.compare(before + 1 - host.size(), host.size(), host) != 0)
        continue;
      const std::string pid_text = name.substr(before + 1, last - before - 1);
      if (pid_text.empty() || pid_text.size() > 9 ||
          pid_text.find_first_not_of("0123456789") != std::string::npos)
        continue;
      const auto pid = static_cast<pid_t>(std::stol(pid_text));
      if (pid > 0 && ::kill(pid, 0) != 0 && errno == ESRCH) fs::remove(entry.path(), ec);
    }
  });
}

/// A file name in the temporary folder no other encode of this or another process uses; the
/// file is removed when this goes (and by a later encode on this machine if this process is
/// killed first).
class TemporaryFile {
 public:
  explicit TemporaryFile(const std::string& stem) {
    remove_orphaned_temporaries();
    static std::atomic<unsigned> counter{0};
    path_ = fs::temp_directory_path() /
            (stem + "-" + format::detail::host_name() + "-" + std::to_string(::getpid()) + "-" +
             std::to_string(counter++) + ".bin");
  }
  ~TemporaryFile() {
    std::error_code ec;
    fs::remove(path_, ec);
  }
  TemporaryFile(const TemporaryFile&) = delete;
  TemporaryFile& operator=(const TemporaryFile&) = delete;
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

/// A stage of EncodeEvents: started when made, done when it goes (also on an exception).
class Stage {
 public:
  Stage(const EncodeEvents& events, const std::string& name, const std::string& unit)
      : events_(events) {
    if (events_.stage) progress_ = events_.stage(name, unit);
  }
  ~Stage() {
    if (events_.stage && events_.stage_done) events_.stage_done();
  }
  Stage(const Stage&) = delete;
  Stage& operator=(const Stage&) = delete;
  const Progress& progress() const { return progress_; }

 private:
  const EncodeEvents& events_;
  Progress progress_;
};

/// The request's provenance with the coding choices encode records (encode_series adds the
/// variable-rate rule and its parameters).
nlohmann::json job_provenance(nlohmann::json provenance, const CodingSettings& c) {
  if (!provenance.is_object()) provenance = nlohmann::json::object();
  provenance["refit_quantization"] = c.refit_quantization;
  provenance["extend_pursuit"] = c.extend_pursuit;
  provenance["max_atoms"] = c.max_atoms;
  provenance["coef_step_factor"] = c.coef_step_factor;
  provenance["max_error"] = c.max_error;
  provenance["learned_pursuit"] = c.learned_pursuit;
  return provenance;
}

std::string printed(const char* format, double a, double b = 0) {
  char text[160];
  std::snprintf(text, sizeof text, format, a, b);
  return text;
}

/// Bytes in MiB, to three significant digits ("0.527 MiB", "4096 MiB").
std::string mebibytes(double bytes) {
  const double mib = bytes / 1048576;
  return mib >= 100 ? printed("%.0f MiB", mib) : printed("%.3g MiB", mib);
}

/// The training settings of an encode given no dictionary (volreel train's defaults).
DefaultDictionaryOptions training_options(const EncodeRequest& request, double eps,
                                          std::size_t frames) {
  DefaultDictionaryOptions d;
  d.tolerance = eps;
  d.atoms = request.atoms;
  d.frames = frames;
  d.sample_frames = request.tolerance.rate_sample_frames;
  d.half_atoms = request.half_atoms;
  d.coding = request.coding;
  // The coreset from the frames this encode codes (--max-frames), not the whole series.
  if (d.coreset.candidate_frames.empty())
    for (std::size_t t = 0; t < frames; ++t) d.coreset.candidate_frames.push_back(t);
  return d;
}

/// The coreset of an encode that trains, drawn by every process from its share of the chosen
/// frames and merged on rank 0 (the same draw as one process's, coreset.hpp); empty elsewhere.
std::optional<dictionary::CoresetHierarchy> draw_training_coreset(
    const datasets::SeriesReader& series, const EncodeRequest& request, std::size_t frames,
    const Ranks& ranks, const EncodeEvents& events) {
  const dictionary::CoresetOptions options = training_options(request, 0, frames).coreset;
  Stage stage(events, "coreset", "frames");
  const std::vector<std::size_t> chosen = dictionary::coreset_frames(series, options);
  const auto [first, last] = ranks.share(chosen.size());
  dictionary::CoresetDraw draw = dictionary::draw_coreset(
      series, options, std::span(chosen).subspan(first, last - first), stage.progress());
  if (ranks.size() > 1) {
    const auto parts = ranks.gather_to_root(draw.to_bytes());
    if (!ranks.root()) return std::nullopt;
    for (std::size_t r = 1; r < parts.size(); ++r)
      draw.merge(dictionary::CoresetDraw::from_bytes(parts[r], options));
  }
  dictionary::CoresetHierarchy h = draw.finish(options.levels);
  h.frames = chosen;
  return h;
}

/// Trains the dictionary of an encode given none into `path`, on its coreset `h`.
void train_dictionary(const datasets::SeriesReader& series, const EncodeRequest& request,
                      double eps, std::size_t frames, const dictionary::CoresetHierarchy& h,
                      const EncodeEvents& events, const fs::path& path) {
  const DefaultDictionaryOptions d = training_options(request, eps, frames);
  const auto chosen = train_default_dictionary(series, h, d, events.candidate);
  if (chosen.dct_only) {
    format::write_dictionary_file(path, format::dct_dictionary(6, VOLREEL_VERSION));
    if (events.message) events.message(printed("using the DCT basis alone (eps %.4g)", eps));
    return;
  }
  dictionary::save_dictionary(path, chosen.dictionary, chosen.training);
  if (events.message)
    events.message(printed("using the dictionary of K = %.0f atoms (eps %.4g)",
                           chosen.dictionary.atom_count(), eps));
}

}  // namespace

std::uint64_t default_encode_memory() {
  return format::detail::usable_memory_bytes() / 2;
}

double whole_frame_bytes(const Dims& dims) {
  return 2.0 * 4.0 * static_cast<double>(dims.voxels());
}

std::uint32_t default_keyframe_gap(const Dims& dims, format::BrickShape shape, bool size_target,
                                   std::uint64_t memory, bool* lowered) {
  if (lowered) *lowered = false;
  if (size_target) return 1;
  if (memory == 0) memory = default_encode_memory();
  const double per_frame = detail::stretch_bytes_per_frame(dims, shape);
  std::uint32_t gap = default_max_keyframe_gap;
  while (gap > 1 && memory > 0 && (gap + 1) * per_frame > static_cast<double>(memory)) --gap;
  if (lowered) *lowered = gap < default_max_keyframe_gap;
  return gap;
}

void check_request(const EncodeRequest& request) {
  if (request.tolerance.bps && request.max_keyframe_gap && *request.max_keyframe_gap > 1)
    throw InputError(
        "--bps searches eps on sample frames coded whole, every node stored, and "
        "--max-keyframe-gap " +
        std::to_string(*request.max_keyframe_gap) +
        " would leave nodes to interpolation: the container would land below the "
        "target. Leave --max-keyframe-gap out with --bps (every frame is then a "
        "keyframe), or ask for --psnr or --tolerance");
}

MissedTargets missed_targets(const EncodeSummary& s, double psnr_target, double bps_target) {
  const CodingSettings& c = s.coding;
  MissedTargets m;
  m.psnr = psnr_target > 0 && c.codec == format::Codec::ksvd && c.fixed_sparsity == 0 &&
           s.delivered.frames > 0 && s.delivered.worst_frame_psnr < psnr_target;
  m.bps = bps_target > 0 && std::abs(s.bps - bps_target) > bps_tolerance * bps_target;
  m.max_error = c.max_error > 0 && s.blocks_over_bound > 0;
  return m;
}

EncodeSummary encode(const datasets::SeriesReader& series, const fs::path& out,
                     EncodeRequest request, const EncodeEvents& events) {
  const auto say = [&](const std::string& line) {
    if (events.message) events.message(line);
  };
  const auto& info = series.info();
  const std::size_t frames =
      request.max_frames ? std::min(request.max_frames, info.frames) : info.frames;
  const Ranks& ranks = request.ranks ? *request.ranks : single_process();
  check_request(request);
  // Over a container, --overwrite writes the new one beside it and swaps it in once complete, so
  // that a failed or interrupted run leaves the old one whole; --resume continues such a
  // replacement, and a swap an earlier run left halfway is finished first. Rank 0 decides (the
  // others could see its first files): 1 replaces, 0 not, -1 rank 0 failed.
  const fs::path next = replacement_folder(out);
  std::string prepare_failure;
  const double decision = ranks.broadcast_value([&] {
    if (!ranks.root()) return 0.0;
    try {
      std::error_code ec;
      if (!fs::exists(out / "manifest.json", ec) && complete_replacement(out)) {
        commit_replacement(out);
        say("finished moving the complete container in " + next.string() + " over " + out.string() +
            " (an earlier run stopped while moving it)");
      }
      if (!fs::exists(out / "manifest.json", ec) && !fs::exists(next / "manifest.json", ec) &&
          !request.resume)
        fs::remove_all(next, ec);  // an orphan
      return replaces_container(out, request.overwrite, request.resume) ? 1.0 : 0.0;
    } catch (const std::exception& e) {
      prepare_failure = e.what();
      return -1.0;
    }
  }());
  if (decision < 0)
    throw InputError(ranks.root() ? prepare_failure : "rank 0 could not prepare " + out.string());
  const bool replaces = decision > 0;
  refuse_existing_output(out, request.resume, request.overwrite);
  const fs::path target = replaces ? next : out;
  if (replaces) {
    if (!request.resume) refuse_existing_output(next, false, true);
    say(request.resume
            ? "continuing the interrupted replacement of " + out.string() + " in " + next.string() +
                  "; it replaces the old container once complete"
            : out.string() + " holds a container: the new one is written to " + next.string() +
                  " and replaces it once complete (the old one stays whole until then)");
  }
  // A dictionary given is read (and checked) now, not after the value range and rate control.
  // (Rank 0 alone reads it, here and below; its error aborts the job.)
  if (ranks.root() && !request.dictionary.empty() && request.dictionary != "dct") {
    detail::require_brick_blocks(format::read_dictionary_file(request.dictionary).block_size,
                                 request.dictionary + ": ");
  }
  // The brick size: given, the container's own (resume), or chosen for the volume.
  const std::array<std::uint32_t, 3> dims{static_cast<std::uint32_t>(info.dims.x),
                                          static_cast<std::uint32_t>(info.dims.y),
                                          static_cast<std::uint32_t>(info.dims.z)};
  bool chosen_brick_size = false;
  if (request.coding.brick_size == 0 && request.resume && fs::exists(target / "manifest.json"))
    request.coding.brick_size = format::Container(target, true).manifest().brick_size;
  if (request.coding.brick_size == 0) {
    chosen_brick_size = true;
    request.coding.brick_size = format::choose_brick_shape(dims).size;
  }
  const format::BrickShape shape{request.coding.brick_size};
  if (!format::valid_brick_size(shape.size))
    throw InputError("--brick-size must be auto or a multiple of 6 in 12..66, not " +
                     std::to_string(shape.size));
  say("bricks of " + std::to_string(shape.size) + "^3 voxels (" + std::to_string(shape.interior()) +
      "^3 interior + apron)" +
      (chosen_brick_size ? printed(", chosen for this volume (its blocks that hold voxels of "
                                   "the volume store %.3g values per voxel, all levels)",
                                   format::coded_block_share(dims, shape))
                         : std::string()));
  EncodeJob job;
  job.ranks = &ranks;
  job.resume = request.resume;
  job.overwrite = request.overwrite;
  job.max_frames = frames;
  job.coding = request.coding;
  job.half_atoms = request.half_atoms;
  if (request.tolerance.psnr) job.psnr_target = *request.tolerance.psnr;
  const std::uint64_t memory = request.memory ? request.memory : default_encode_memory();
  const std::string memory_text = request.memory
                                      ? "--memory (" + mebibytes(static_cast<double>(memory)) + ")"
                                      : std::string("half the memory");
  job.memory = memory;
  job.piecewise = memory > 0 && whole_frame_bytes(info.dims) > static_cast<double>(memory);
  if (job.piecewise) {
    const std::string frame_size = "frames of " +
                                   mebibytes(4.0 * static_cast<double>(info.dims.voxels())) +
                                   " (coded whole, " + mebibytes(whole_frame_bytes(info.dims)) +
                                   " with their decoding) do not fit " + memory_text + " whole";
    if (request.max_keyframe_gap && *request.max_keyframe_gap > 1)
      throw InputError(frame_size +
                       ", so they are coded piecewise, which needs --max-keyframe-gap 1 (a "
                       "keyframe stretch holds its frames whole); or give more --memory");
    if (request.tolerance.bps)
      throw InputError(frame_size +
                       ", and --bps codes sample frames whole: ask for --psnr or --tolerance, or "
                       "give more --memory");
    if (request.coding.codec == format::Codec::ksvd && request.dictionary.empty() &&
        !(request.resume && fs::exists(target / "dictionary.bin")))
      throw InputError(frame_size +
                       ", and training a dictionary reads frames whole: give one (--dictionary "
                       "FILE from volreel train on a smaller series, or --dictionary dct), or "
                       "give more --memory");
    // A row of bricks' planes (S, and as many again while the next row reads) on every level, the
    // coarser levels' with their detail where the coding uses it (PyramidWindow::brick_detail).
    const double window = PyramidWindow::planes_bytes(format::level_geometry(dims, shape),
                                                      2.0 * static_cast<double>(shape.size),
                                                      request.coding.uses_level_detail());
    if (window > static_cast<double>(memory))
      throw InputError(frame_size + ", and coding them piecewise holds about " + mebibytes(window) +
                       " of planes: give at least that --memory");
    job.max_keyframe_gap = 1;
    say(frame_size + ": each is coded piecewise, a row of bricks at a time (keyframe gap 1)");
  } else if (request.max_keyframe_gap) {
    job.max_keyframe_gap = *request.max_keyframe_gap;
  } else {
    bool lowered = false;
    job.max_keyframe_gap =
        default_keyframe_gap(info.dims, shape, request.tolerance.bps.has_value(), memory, &lowered);
    if (lowered)
      say("keyframe gap " + std::to_string(job.max_keyframe_gap) + " (not " +
          std::to_string(default_max_keyframe_gap) +
          "): " + std::to_string(job.max_keyframe_gap + 1) +
          printed(" frames of %.0f MB each fit in ",
                  detail::stretch_bytes_per_frame(info.dims, shape) / 1e6) +
          memory_text);
  }
  auto& c = job.coding;
  {
    Stage stage(events, "value range", "frames");
    std::tie(c.value_min, c.value_max) = value_range(series, frames, stage.progress(), ranks);
  }
  check_value_range(c.value_min, c.value_max, info.source);
  const double range = tolerance_range(c.value_min, c.value_max);
  say(printed("value range [%.6g, %.6g]", c.value_min, c.value_max) +
      (c.value_max > c.value_min ? "" : " (constant: every brick is stored as the value)"));

  std::optional<TemporaryFile> copy;
  if (c.codec == format::Codec::zfp) {
    c.zfp_accuracy = request.zfp_accuracy.value_or(range * 1e-3);
    say(printed("codec zfp, fixed accuracy %.4g per brick", c.zfp_accuracy));
  } else {
    // The dictionary: given, the container's own (resume), or trained here; with several
    // processes rank 0 finds it and chooses ε, and sends both to the others.
    copy.emplace("volreel-dictionary-copy");
    job.dictionary_file = copy->path();
    std::vector<std::byte> dictionary_bytes;
    std::string failure;
    // Training (no dictionary given, none to resume with, values not constant): every process
    // draws its share of the coreset first.
    const bool trains = request.dictionary.empty() &&
                        !(request.resume && fs::exists(target / "dictionary.bin")) &&
                        c.value_max > c.value_min;
    std::optional<dictionary::CoresetHierarchy> coreset;
    const double train_eps = tolerance_to_train_at(request.tolerance, range);
    if (trains) {
      say(printed("no dictionary given: training one with volreel train's defaults at eps %.4g, ",
                  train_eps) +
          (request.atoms ? "K = " + std::to_string(request.atoms)
                         : std::string("K chosen by the total size it gives")));
      coreset = draw_training_coreset(series, request, frames, ranks, events);
    }
    if (ranks.root()) {
      try {
        fs::path dict_path = request.dictionary;
        std::optional<TemporaryFile> trained;
        if (dict_path.empty() && request.resume && fs::exists(target / "dictionary.bin"))
          dict_path = target / "dictionary.bin";
        if (dict_path.empty() && !(c.value_max > c.value_min))
          dict_path = "dct";  // nothing to learn
        if (trains) {
          trained.emplace("volreel-dictionary");
          train_dictionary(series, request, train_eps, frames, *coreset, events, trained->path());
          dict_path = trained->path();
        }
        // A copy, so that the container's own dictionary.bin can be used to resume.
        if (dict_path == "dct")
          format::write_dictionary_file(copy->path(), format::dct_dictionary(6, VOLREEL_VERSION));
        else
          fs::copy_file(dict_path, copy->path(), fs::copy_options::overwrite_existing);
        auto file = format::read_dictionary_file(copy->path());
        if ((job.half_atoms && !file.half_atoms) || !file.dct_atoms) {
          // Stored as the container will store it, so that a size target measures what is
          // written.
          file = format::container_dictionary(std::move(file), job.half_atoms);
          format::write_dictionary_file(copy->path(), file);
        }
        ToleranceChoice eps;
        {
          const bool search = request.tolerance.bps && c.fixed_sparsity == 0;
          std::optional<Stage> stage;
          if (search) stage.emplace(events, "rate control", "steps");
          // The container's bytes besides its frames: the dictionary and the manifest (with the
          // provenance keys added below, of the same size).
          const std::uint64_t fixed_bytes =
              fs::file_size(copy->path()) +
              (search ? estimated_manifest_bytes(series.info(), frames, c, job.max_keyframe_gap,
                                                 job_provenance(request.provenance, c),
                                                 file.atom_count)
                      : 0);
          eps = choose_tolerance(series, file, fixed_bytes, c, frames, request.tolerance,
                                 stage ? stage->progress() : Progress{});
        }
        c.tolerance = eps.tolerance;
        // The learned atoms paid in none of the rate search's sample bricks at this ε, the
        // sample being every frame or at least min_skip_sample_bricks bricks: the whole
        // dictionary's pursuit is skipped (CodingSettings::learned_pursuit).
        const RateSearch& rs = eps.rate_search;
        c.learned_pursuit = !(
            eps.source == ToleranceSource::bps && rs.sample_bricks > 0 && rs.learned_bricks == 0 &&
            (rs.sample_frames >= frames || rs.sample_bricks >= min_skip_sample_bricks));
        if (events.tolerance_chosen) events.tolerance_chosen(eps, c, file.atom_count);
        dictionary_bytes =
            format::detail::read_whole_file(copy->path(), format::detail::max_dictionary_bytes);
      } catch (const std::exception& e) {
        if (ranks.size() == 1) throw;
        failure = e.what();
      }
    }
    if (ranks.size() > 1) {
      // The dictionary file's bytes, or (empty) rank 0's error; then ε.
      std::vector<std::byte> message;
      for (const char ch : failure) message.push_back(static_cast<std::byte>(ch));
      ranks.broadcast(message);
      if (!message.empty())
        throw InputError(
            std::string(reinterpret_cast<const char*>(message.data()), message.size()));
      ranks.broadcast(dictionary_bytes);
      c.tolerance = ranks.broadcast_value(c.tolerance);
      c.learned_pursuit = ranks.broadcast_value(c.learned_pursuit ? 1.0 : 0.0) != 0;
      if (!ranks.root()) format::detail::write_file_atomically(copy->path(), dictionary_bytes);
    }
  }
  job.provenance = job_provenance(std::move(request.provenance), c);
  Stage stage(events, "encoding", "frames");
  EncodeSummary summary = encode_series(series, target, job, stage.progress());
  if (replaces) {
    ranks.barrier();  // every rank has read the new container
    if (ranks.root()) commit_replacement(out);
  }
  return summary;
}

}  // namespace volreel::encoder
