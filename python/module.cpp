// module.cpp: volreel's Python module (volreel._volreel, wrapped by volreel/__init__.py) — a
// container opened as frames in numpy arrays, the whole encode and the dictionary training from
// arrays or iterables of arrays, and the PSNR and SSIM of `volreel compare`. The GIL is released
// while decoding, encoding, training and measuring.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <omp.h>
#include <pthread.h>
#include <unistd.h>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "volreel/datasets/series.hpp"
#include "volreel/dictionary/training.hpp"
#include "volreel/encoder/encode.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/time_step.hpp"
#include "volreel/psnr/metrics.hpp"
#include "volreel/remote/http_client.hpp"
#include "volreel/remote/http_source.hpp"

namespace py = pybind11;
namespace fs = std::filesystem;

namespace volreel::python {

namespace {

using FloatArray = py::array_t<float, py::array::c_style | py::array::forcecast>;

/// Set while a thread runs a call from Python that may wait for the network: the only threads
/// on which remote reads look for Python's pending signals. A thread the library starts while the
/// caller holds the GIL must not wait for it.
thread_local bool python_caller = false;

struct PythonCall {
  PythonCall() { python_caller = true; }
  ~PythonCall() { python_caller = false; }
  PythonCall(const PythonCall&) = delete;
  PythonCall& operator=(const PythonCall&) = delete;
};

/// How a URL is read (volreel.open's keywords, the command line's --tries, --stall-timeout,
/// --connections, --cache, --cache-size and --ca-file); a signal handler's exception
/// (KeyboardInterrupt on Ctrl-C) ends a wait for the server.
struct UrlOptions {
  unsigned tries = remote::RemoteOptions{}.attempts;
  double stall_timeout = remote::HttpOptions{}.stall_timeout_s;
  unsigned connections = remote::HttpOptions{}.max_connections;
  std::optional<fs::path> cache;
  std::string cache_size = remote::RemoteOptions::default_cache_size;
  std::optional<fs::path> ca_file;

  remote::RemoteOptions checked() const {
    using Limits = remote::RemoteOptions;
    const auto bad = [](const std::string& what) { throw InputError(what); };
    if (tries < 1 || tries > Limits::max_attempts)
      bad("tries: expected 1.." + std::to_string(Limits::max_attempts) +
          " tries of a read, found " + std::to_string(tries));
    if (!(stall_timeout >= Limits::min_stall_timeout_s &&
          stall_timeout <= Limits::max_stall_timeout_s))
      bad("stall_timeout: expected " + format::number_text(Limits::min_stall_timeout_s) + ".." +
          format::number_text(Limits::max_stall_timeout_s) + " seconds, found " +
          format::number_text(stall_timeout));
    if (connections < 1 || connections > Limits::max_connections)
      bad("connections: expected 1.." + std::to_string(Limits::max_connections) +
          " connections, found " + std::to_string(connections));
    if (ca_file && !fs::is_regular_file(*ca_file))
      bad("ca_file: '" + ca_file->string() +
          "' is not a file (expected a PEM file of "
          "certificate authorities)");
    remote::RemoteOptions o;
    o.attempts = tries;
    o.http.stall_timeout_s = stall_timeout;
    o.http.max_connections = connections;
    if (ca_file) o.http.ca_file = ca_file->string();
    if (cache) {
      o.cache_dir = *cache;
      try {
        o.cache_bytes = format::detail::parse_byte_size(cache_size, "cache_size");
      } catch (const std::invalid_argument& e) {
        bad(e.what());
      }
    }
    o.while_waiting = [] {
      if (!python_caller || omp_in_parallel()) return;
      py::gil_scoped_acquire gil;
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    };
    return o;
  }
};

/// An integer argument (a Python int, or anything with __index__, as numpy's integers) as an
/// int64, a value beyond that range as the nearest int64, which every range check below refuses;
/// the TypeError of Python's own where it is no integer.
std::int64_t integer_argument(const py::handle& value) {
  const auto index = py::reinterpret_steal<py::object>(PyNumber_Index(value.ptr()));
  if (!index) throw py::error_already_set();
  int overflow = 0;
  const long long v = PyLong_AsLongLongAndOverflow(index.ptr(), &overflow);
  if (overflow != 0)
    return overflow > 0 ? std::numeric_limits<std::int64_t>::max()
                        : std::numeric_limits<std::int64_t>::min();
  return static_cast<std::int64_t>(v);
}

/// An open container: its frames decoded as the player draws them (format::TimeStepDecoder).
/// close() lets go of its frames and its connection or files; what the manifest says stays.
class PyContainer {
 public:
  explicit PyContainer(const std::string& location, const UrlOptions& url = {})
      : container_(open(location, url)),
        manifest_(container_->manifest()),
        location_(container_->directory().string()),
        total_bytes_(container_->total_bytes()),
        steps_(std::in_place, *container_) {}

  const format::Manifest& manifest() const { return manifest_; }
  std::size_t frames() const { return manifest_.frames.size(); }
  const std::string& location() const { return location_; }
  std::uint64_t total_bytes() const { return total_bytes_; }
  double bps() const {
    const auto& d = manifest().dims;
    const double voxels = double(d[0]) * d[1] * d[2] * static_cast<double>(frames());
    return voxels > 0 ? 8.0 * static_cast<double>(total_bytes()) / voxels : 0;
  }
  bool closed() const { return closed_.load(); }
  void close() {
    py::gil_scoped_release release;
    std::lock_guard lock(mutex_);
    closed_ = true;
    steps_.reset();
    container_.reset();
  }

  /// Time step t (negative: from the end) at `level` (None: the finest) as a [z, y, x] array.
  /// `out`: an array to decode into (float32, C order, the level's shape), or None for a new one.
  py::array frame(const py::object& t_given, const py::object& level,
                  std::optional<py::array> out_given) {
    const auto n = static_cast<std::int64_t>(frames());
    std::int64_t t = integer_argument(t_given);
    if (t < 0 && t >= -n) t += n;
    if (t < 0 || t >= n)
      throw py::index_error("frame " + std::string(py::str(t_given)) +
                            " is out of range: the container has frames 0.." +
                            std::to_string(n - 1) + " (negative frames count from the end, -1)");
    const std::uint32_t l = level_index(level.is_none() ? py::int_(-1) : level);
    const auto dims = level_dims(l);
    const std::vector<py::ssize_t> shape = {dims[2], dims[1], dims[0]};
    py::array out;
    if (out_given) {
      out = *out_given;
      const bool fits = out.dtype().is(py::dtype::of<float>()) &&
                        (out.flags() & py::array::c_style) && out.writeable() && out.ndim() == 3 &&
                        std::equal(shape.begin(), shape.end(), out.shape());
      if (!fits)
        throw py::value_error("out: expected a writeable C-contiguous float32 array of shape (" +
                              std::to_string(dims[2]) + ", " + std::to_string(dims[1]) + ", " +
                              std::to_string(dims[0]) + ")");
    } else {
      out = FloatArray(shape);
    }
    float* data = static_cast<float*>(out.mutable_data());
    const std::size_t count = static_cast<std::size_t>(out.size());
    bool was_closed = false;
    {
      py::gil_scoped_release release;
      const PythonCall call;
      std::lock_guard lock(mutex_);
      if (steps_)
        steps_->decode(static_cast<std::size_t>(t), static_cast<std::uint32_t>(l), {data, count});
      else
        was_closed = true;
    }
    if (was_closed)
      throw py::value_error("frame: the container " + location_ +
                            " is closed (open it again with volreel.open)");
    return out;
  }

  /// Level `level` (negative: from the finest, -1 being it) as an index 0..levels - 1; an
  /// IndexError naming the range where there is no such level.
  std::uint32_t level_index(const py::handle& level_given) const {
    const auto levels = static_cast<std::int64_t>(manifest().levels);
    const std::int64_t level = integer_argument(level_given);
    const std::int64_t l = level < 0 && level >= -levels ? level + levels : level;
    if (l < 0 || l >= levels)
      throw py::index_error("level " + std::string(py::str(level_given)) +
                            " is out of range: the container has levels 0.." +
                            std::to_string(levels - 1) +
                            " (0 is the root brick; negative levels count from the finest, -1)");
    return static_cast<std::uint32_t>(l);
  }

  /// The size (x, y, z) of level l.
  std::array<std::uint32_t, 3> level_dims(std::uint32_t l) const {
    const auto geometry = format::level_geometry(manifest().dims, manifest().shape());
    if (l >= geometry.size()) throw py::index_error("level " + std::to_string(l));
    return geometry[l].dims;
  }

  /// The container at `location`, its reads waited for without the GIL.
  static format::Container open(const std::string& location, const UrlOptions& url) {
    remote::RemoteOptions options = url.checked();
    py::gil_scoped_release release;
    const PythonCall call;
    return format::Container(remote::open_source(location, options));
  }

  py::dict info() const {
    const py::object loads = py::module_::import("json").attr("loads");
    py::dict d = loads(format::manifest_to_json(manifest()).dump());
    d["location"] = location();
    d["total_bytes"] = total_bytes();
    d["bps"] = bps();
    return d;
  }

 private:
  std::optional<format::Container> container_;
  format::Manifest manifest_;
  std::string location_;
  std::uint64_t total_bytes_;
  std::mutex mutex_;  ///< the decoder keeps frames open between steps
  std::optional<format::TimeStepDecoder> steps_;
  /// Read without the mutex (a decode may hold it while it waits for the GIL).
  std::atomic<bool> closed_{false};
};

/// InputError naming frames[t] and the [z, y, x] index of its first value that is not finite.
void check_finite(std::span<const float> frame, const Dims& d, std::size_t t) {
  for (std::size_t i = 0; i < frame.size(); ++i) {
    if (std::isfinite(frame[i])) continue;
    const auto v = static_cast<std::int64_t>(i);
    throw InputError("frames[" + std::to_string(t) + "]: value " + format::number_text(frame[i]) +
                     " at [z, y, x] = [" + std::to_string(v / d.x / d.y) + ", " +
                     std::to_string(v / d.x % d.y) + ", " + std::to_string(v % d.x) +
                     "] is not finite");
  }
}

/// A series over a [t, z, y, x] float32 array (kept alive; read without the GIL).
class ArraySeries final : public datasets::SeriesReader {
 public:
  ArraySeries(FloatArray array, std::vector<double> timestamps, std::string variable)
      : array_(std::move(array)) {
    if (array_.ndim() != 4)
      throw py::value_error("frames: expected an array [t, z, y, x], found " +
                            std::to_string(array_.ndim()) + " dimensions");
    info_.dims = Dims{array_.shape(3), array_.shape(2), array_.shape(1)};
    info_.frames = static_cast<std::size_t>(array_.shape(0));
    info_.timestamps = std::move(timestamps);
    info_.variable = std::move(variable);
    info_.source = "numpy array [" + std::to_string(array_.shape(0)) + ", " +
                   std::to_string(info_.dims.z) + ", " + std::to_string(info_.dims.y) + ", " +
                   std::to_string(info_.dims.x) + "]";
    data_ = array_.data();
  }
  void read_frame(std::size_t t, std::span<float> out) const override {
    if (t >= info_.frames || out.size() != info_.dims.voxels())
      throw InputError("frame " + std::to_string(t) + ": out of range or the wrong size");
    const float* frame = data_ + t * info_.dims.voxels();
    check_finite({frame, out.size()}, info_.dims, t);
    std::memcpy(out.data(), frame, out.size_bytes());
  }
  using datasets::SeriesReader::read_frame;

 private:
  FloatArray array_;
  const float* data_ = nullptr;
};

/// Timestamps given (one per frame, increasing) or 0, 1, 2, ...
std::vector<double> timestamps_for(std::optional<std::vector<double>> given, std::size_t frames) {
  if (!given) {
    std::vector<double> t(frames);
    for (std::size_t i = 0; i < frames; ++i) t[i] = static_cast<double>(i);
    return t;
  }
  if (given->size() != frames)
    throw py::value_error("times: expected " + std::to_string(frames) +
                          " numbers (one per frame), " + "found " + std::to_string(given->size()));
  for (std::size_t i = 1; i < given->size(); ++i)
    if (!((*given)[i] > (*given)[i - 1]))
      throw py::value_error("times: expected increasing numbers, found " +
                            format::number_text((*given)[i]) + " after " +
                            format::number_text((*given)[i - 1]));
  return *given;
}

/// A raw series directory written from an iterable of 3D arrays, removed when this goes.
class SpooledSeries {
 public:
  SpooledSeries(const py::iterable& frames, const fs::path& near,
                const std::optional<std::vector<double>>& times, const std::string& variable) {
    static std::atomic<unsigned> counter{0};
    fs::path target = fs::absolute(near).lexically_normal();  // "out/" names out too
    if (target.filename().empty()) target = target.parent_path();
    dir_ = target.parent_path() / ("." + target.filename().string() + ".frames-" +
                                   std::to_string(::getpid()) + "-" + std::to_string(counter++));
    std::optional<datasets::RawSeriesWriter> writer;
    std::size_t t = 0;
    try {
      for (const py::handle item : frames) {
        const FloatArray a = FloatArray::ensure(item);
        if (!a)
          throw py::type_error("frames[" + std::to_string(t) +
                               "]: expected a 3D array of numbers, found " +
                               std::string(py::str(py::type::of(item))));
        if (a.ndim() != 3)
          throw py::value_error("frames[" + std::to_string(t) +
                                "]: expected a 3D array [z, y, x], " + "found " +
                                std::to_string(a.ndim()) + " dimensions");
        const Dims d{a.shape(2), a.shape(1), a.shape(0)};
        if (!writer) writer.emplace(dir_, d, variable);
        if (d != writer->dims())
          throw py::value_error("frames[" + std::to_string(t) + "]: shape [" + std::to_string(d.z) +
                                ", " + std::to_string(d.y) + ", " + std::to_string(d.x) +
                                "] differs from the first frame's");
        check_finite({a.data(), static_cast<std::size_t>(a.size())}, d, t);
        writer->write_frame(t, times && t < times->size() ? (*times)[t] : static_cast<double>(t),
                            {a.data(), static_cast<std::size_t>(a.size())});
        ++t;
      }
      if (!writer) throw py::value_error("frames: the iterable gave no frame");
      if (times) timestamps_for(times, t);  // checks count and order
      writer->finish();
    } catch (...) {
      std::error_code ec;
      fs::remove_all(dir_, ec);
      throw;
    }
  }
  ~SpooledSeries() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  SpooledSeries(const SpooledSeries&) = delete;
  SpooledSeries& operator=(const SpooledSeries&) = delete;
  const fs::path& directory() const { return dir_; }

 private:
  fs::path dir_;
};

/// The series `frames` stands for: a 4D array read in place, or an iterable written to a raw
/// series next to `near` first (the value range and the dictionary need every frame).
struct SeriesInput {
  std::unique_ptr<SpooledSeries> spool;
  std::unique_ptr<datasets::SeriesReader> reader;
};
SeriesInput series_input(const py::object& frames, const fs::path& near,
                         const std::optional<std::vector<double>>& times,
                         const std::string& variable) {
  SeriesInput in;
  if (py::isinstance<py::array>(frames) && py::cast<py::array>(frames).ndim() == 4) {
    FloatArray a = FloatArray::ensure(frames);
    if (!a) throw py::type_error("frames: expected an array of numbers");
    const auto count = static_cast<std::size_t>(a.shape(0));
    if (a.size() == 0)
      throw py::value_error("frames: the array [t, z, y, x] of shape [" +
                            std::to_string(a.shape(0)) + ", " + std::to_string(a.shape(1)) + ", " +
                            std::to_string(a.shape(2)) + ", " + std::to_string(a.shape(3)) +
                            "] holds no value: give at least one frame of at least one voxel");
    in.reader = std::make_unique<ArraySeries>(std::move(a), timestamps_for(times, count), variable);
    return in;
  }
  if (py::isinstance<py::array>(frames))
    throw py::value_error(
        "frames: expected an array [t, z, y, x] or an iterable of arrays "
        "[z, y, x], found an array of " +
        std::to_string(py::cast<py::array>(frames).ndim()) + " dimensions");
  if (!py::isinstance<py::iterable>(frames))
    throw py::type_error("frames: expected an array [t, z, y, x] or an iterable of 3D arrays");
  in.spool = std::make_unique<SpooledSeries>(py::reinterpret_borrow<py::iterable>(frames), near,
                                             times, variable);
  in.reader = datasets::open_series(in.spool->directory());
  return in;
}

/// Progress of an encode's stages that raises, in the encoding thread, what a signal handler
/// raised (KeyboardInterrupt on Ctrl-C) as soon as Python has one pending: the encode stops there,
/// as `volreel encode` does on Ctrl-C (its container is then continued with resume=True). Not
/// inside a parallel region, which an exception must not leave.
/// Looked at every signal_check_interval at most (each look takes the GIL, which another
/// Python thread may hold for its switch interval).
struct SignalCheck {
  std::chrono::steady_clock::time_point last{};
};
constexpr std::chrono::milliseconds signal_check_interval{50};

void raise_pending_signal(const ProgressUpdate&, void* user) {
  if (omp_in_parallel()) return;
  auto& check = *static_cast<SignalCheck*>(user);
  const auto now = std::chrono::steady_clock::now();
  if (now - check.last < signal_check_interval) return;
  check.last = now;
  py::gil_scoped_acquire gil;
  if (PyErr_CheckSignals() != 0) throw py::error_already_set();
}

encoder::EncodeEvents interruptible_events(SignalCheck& check) {
  encoder::EncodeEvents events;
  events.stage = [&check](const std::string&, const std::string&) {
    return Progress{raise_pending_signal, &check};
  };
  return events;
}

py::dict encode(const py::object& frames, const fs::path& out, std::optional<double> psnr,
                std::optional<double> bps, std::optional<double> tolerance,
                std::optional<double> max_error, const py::object& dictionary_arg,
                const std::string& codec, std::optional<double> zfp_accuracy, int atoms,
                std::optional<std::uint32_t> max_keyframe_gap, bool overwrite, bool resume,
                const std::optional<std::vector<double>>& times, const std::string& variable,
                const py::object& brick_size_arg,
                const std::optional<std::array<double, 3>>& spacing) {
  if (spacing) datasets::check_spacing(*spacing);
  // dictionary: a str or a path (os.PathLike); brick_size: "auto" or a number, as text or int.
  const std::string dictionary =
      py::str(py::module_::import("os").attr("fspath")(dictionary_arg)).cast<std::string>();
  const std::string brick_size = py::str(brick_size_arg).cast<std::string>();
  if (int(psnr.has_value()) + int(bps.has_value()) + int(tolerance.has_value()) +
          int(max_error.has_value()) >
      1)
    throw py::value_error("give at most one of psnr, bps, tolerance and max_error");
  // What `volreel encode` refuses on its command line, refused here alike.
  for (const auto& [name, value] :
       {std::pair{"psnr", psnr}, std::pair{"bps", bps}, std::pair{"tolerance", tolerance},
        std::pair{"max_error", max_error}, std::pair{"zfp_accuracy", zfp_accuracy}})
    if (value && !(std::isfinite(*value) && *value > 0))
      throw py::value_error(std::string(name) + " must be a finite number > 0, not " +
                            py::repr(py::float_(*value)).cast<std::string>());
  if (overwrite && resume)
    throw py::value_error("overwrite and resume exclude each other: give one");
  if (atoms < 0 || atoms > static_cast<int>(format::dictionary_max_atoms))
    throw py::value_error("atoms must be 0 (try the sizes and keep the best) or 1.." +
                          std::to_string(format::dictionary_max_atoms) + ", not " +
                          std::to_string(atoms));
  if (!dictionary.empty() && atoms != 0)
    throw py::value_error(
        "atoms sizes the dictionary trained when none is given: give dictionary or atoms, not "
        "both");
  if (codec == "zfp") {
    const std::pair<const char*, bool> ksvd_only[] = {
        {"psnr", psnr.has_value()},           {"bps", bps.has_value()},
        {"tolerance", tolerance.has_value()}, {"max_error", max_error.has_value()},
        {"dictionary", !dictionary.empty()},  {"atoms", atoms != 0}};
    for (const auto& [name, given] : ksvd_only)
      if (given)
        throw py::value_error(std::string(name) +
                              " applies to the ksvd codec: codec=\"zfp\" codes every brick to one "
                              "absolute accuracy, zfp_accuracy (default range*1e-3)");
  } else if (zfp_accuracy) {
    throw py::value_error("zfp_accuracy applies to codec=\"zfp\" only");
  }
  if (max_keyframe_gap && (*max_keyframe_gap < 1 || *max_keyframe_gap > 65535))
    throw py::value_error("max_keyframe_gap must be in 1..65535 (1: every frame a keyframe), not " +
                          std::to_string(*max_keyframe_gap));
  // Where the container goes, before an iterable is copied to a temporary series.
  encoder::refuse_existing_output(out, resume, overwrite);
  SeriesInput in = series_input(frames, out, times, variable);
  if (spacing) in.reader->set_spacing(*spacing);
  encoder::EncodeRequest r;
  r.coding.codec = encoder::codec_from_name(codec);
  r.coding.brick_size = encoder::brick_size_from_text(brick_size);
  if (tolerance) r.tolerance.tolerance = *tolerance;
  if (psnr) r.tolerance.psnr = *psnr;
  if (bps) r.tolerance.bps = *bps;
  if (max_error) {
    if (!(*max_error > 0)) throw py::value_error("max_error must be positive");
    r.coding.rule = encoder::VariableRateRule::tolerance;
    r.coding.max_error = *max_error;
    r.tolerance.tolerance = *max_error / 2;
  }
  r.zfp_accuracy = zfp_accuracy;
  r.dictionary = dictionary;
  r.atoms = atoms;
  r.overwrite = overwrite;
  r.resume = resume;
  r.max_keyframe_gap = max_keyframe_gap;
  r.provenance = {{"program", "volreel " VOLREEL_VERSION " (Python)"},
                  {"series", in.reader->info().source}};
  encoder::EncodeSummary s;
  {
    py::gil_scoped_release release;
    SignalCheck check;
    s = encoder::encode(*in.reader, out, r, interruptible_events(check));
  }
  py::dict d;
  d["path"] = out.string();
  d["frames"] = s.frames;
  d["bytes"] = s.container_bytes;
  d["bps"] = s.bps;
  d["seconds"] = s.seconds;
  d["mvoxels_per_s"] = s.mvoxels_per_s;
  const double range = encoder::tolerance_range(s.coding.value_min, s.coding.value_max);
  d["psnr"] = s.delivered.frames > 0 ? s.delivered.sequence_psnr(range)
                                     : std::numeric_limits<double>::quiet_NaN();
  d["worst_frame_psnr"] = s.delivered.worst_frame_psnr;
  d["max_abs_error"] = s.delivered.max_abs_error;
  d["tolerance"] = s.coding.tolerance;
  // A target the container misses: a RuntimeWarning (the container is complete and valid), and
  // "targets_met" false, as `volreel encode` warns and exits with status 3.
  const encoder::MissedTargets missed =
      encoder::missed_targets(s, psnr.value_or(0), bps.value_or(0));
  d["targets_met"] = !missed.any();
  if (missed.any()) {
    char text[320];
    if (missed.psnr)
      std::snprintf(text, sizeof text,
                    "volreel.encode: target PSNR %.2f dB missed: frame %zu reached %.2f dB (the "
                    "container %s is complete and valid)",
                    *psnr, s.delivered.worst_frame, s.delivered.worst_frame_psnr,
                    out.string().c_str());
    else if (missed.bps)
      std::snprintf(text, sizeof text,
                    "volreel.encode: target %.4f bps missed: the container %s is %.4f bps (%+.1f "
                    "%%), complete and valid",
                    *bps, out.string().c_str(), s.bps, 100.0 * (s.bps / *bps - 1));
    else
      std::snprintf(text, sizeof text,
                    "volreel.encode: %zu blocks miss max_error %.4g even at the finest steps a "
                    "payload holds (the container %s is complete and valid; codec=\"zfp\" with "
                    "zfp_accuracy=%.4g holds it)",
                    s.blocks_over_bound, s.coding.max_error, out.string().c_str(),
                    s.coding.max_error);
    if (PyErr_WarnEx(PyExc_RuntimeWarning, text, 1) != 0) throw py::error_already_set();
  }
  return d;
}

std::string python_words(const std::string& message);

py::dict train(const py::object& frames, const fs::path& out, int atoms, std::optional<double> psnr,
               std::optional<double> tolerance, const std::optional<std::vector<double>>& times,
               bool overwrite) {
  if (psnr && tolerance) throw py::value_error("give psnr or tolerance, not both");
  for (const auto& [name, value] : {std::pair{"psnr", psnr}, std::pair{"tolerance", tolerance}})
    if (value && !(std::isfinite(*value) && *value > 0))
      throw py::value_error(std::string(name) + " must be a finite number > 0, not " +
                            py::repr(py::float_(*value)).cast<std::string>());
  if (atoms < 1 || atoms > static_cast<int>(format::dictionary_max_atoms))
    throw py::value_error("atoms must be in 1.." + std::to_string(format::dictionary_max_atoms) +
                          ", not " + std::to_string(atoms));
  if (fs::is_directory(out))
    throw InputError("'" + out.string() + "' is a directory: out names the dictionary file");
  if (!overwrite && fs::exists(fs::symlink_status(out)))
    throw InputError("'" + out.string() +
                     "' already exists: pass overwrite=True to replace it, or choose another out");
  format::detail::check_writable(out, "out");
  SeriesInput in = series_input(frames, out, times, "");
  dictionary::TrainingResult result;
  {
    py::gil_scoped_release release;
    dictionary::CoresetOptions coreset;
    const auto hierarchy = dictionary::build_coreset_hierarchy(*in.reader, coreset);
    if (const std::string warning = dictionary::too_few_blocks_warning(hierarchy, atoms);
        !warning.empty()) {
      py::gil_scoped_acquire gil;
      const std::string text = "volreel.train: " + python_words(warning);
      if (PyErr_WarnEx(PyExc_RuntimeWarning, text.c_str(), 1) != 0) throw py::error_already_set();
    }
    dictionary::TrainingOptions options;
    options.atom_count = atoms;
    options.convergence = 0.01;  // volreel train's default
    options.coding.tolerance = dictionary::training_tolerance(
        tolerance, psnr.value_or(dictionary::default_training_psnr), hierarchy);
    // Ctrl-C ends the training after the K-SVD iteration in progress (KeyboardInterrupt; no file
    // is written).
    SignalCheck check;
    result = dictionary::train_dictionary(
        hierarchy, options,
        [&check](const dictionary::TrainingProgress&) { raise_pending_signal({}, &check); });
    dictionary::save_dictionary(
        out, result.dictionary,
        dictionary::training_provenance(coreset, options, hierarchy, result));
  }
  py::dict d;
  d["path"] = out.string();
  d["atoms"] = result.dictionary.atom_count();
  d["seconds"] = result.seconds;
  d["rms_error"] = result.final_stats.rms_error;
  d["mean_sparsity"] = result.final_stats.mean_sparsity;
  return d;
}

/// An argument of psnr or ssim as float32, as volreel reads data: other types are converted, with a
/// RuntimeWarning where float32 does not hold their values exactly (float64 data that differ by
/// less than float32's precision would otherwise measure as equal, silently).
FloatArray metric_input(const py::object& given, const char* function, const char* name) {
  const py::array x = py::array::ensure(given);
  FloatArray f = x ? FloatArray::ensure(x) : FloatArray();
  if (!x || !f)
    throw py::value_error(std::string(function) + ": " + name + " is not an array of numbers");
  if (!x.dtype().is(py::dtype::of<float>()) &&
      !py::module_::import("numpy")
           .attr("array_equal")(x, f, py::arg("equal_nan") = true)
           .cast<bool>()) {
    const std::string warning = std::string(function) + ": " + name + "'s " +
                                py::str(x.dtype()).cast<std::string>() +
                                " values rounded to float32, as volreel reads data; the metric "
                                "is that of the rounded values";
    if (PyErr_WarnEx(PyExc_RuntimeWarning, warning.c_str(), 1) != 0) throw py::error_already_set();
  }
  return f;
}

/// The two arrays as spans of equal shape.
void check_pair(const FloatArray& a, const FloatArray& b) {
  if (a.ndim() != b.ndim() || !std::equal(a.shape(), a.shape() + a.ndim(), b.shape()))
    throw py::value_error("a and b must have the same shape");
  if (a.size() == 0) throw py::value_error("a and b are empty");
}

double psnr_of(const py::object& a_given, const py::object& b_given) {
  const FloatArray a = metric_input(a_given, "psnr", "a"), b = metric_input(b_given, "psnr", "b");
  check_pair(a, b);
  const std::span<const float> sa(a.data(), static_cast<std::size_t>(a.size())),
      sb(b.data(), static_cast<std::size_t>(b.size()));
  py::gil_scoped_release release;
  return psnr::compare(sa, sb).psnr;
}

double ssim_of(const py::object& a_given, const py::object& b_given) {
  const FloatArray a = metric_input(a_given, "ssim", "a"), b = metric_input(b_given, "ssim", "b");
  check_pair(a, b);
  if (a.ndim() < 1 || a.ndim() > 3)
    throw py::value_error("ssim: expected arrays of 1, 2 or 3 dimensions, found " +
                          std::to_string(a.ndim()));
  std::int64_t shape[3] = {1, 1, 1};  // x, y, z: the last axis varies fastest
  for (py::ssize_t i = 0; i < a.ndim(); ++i) shape[i] = a.shape(a.ndim() - 1 - i);
  const std::span<const float> sa(a.data(), static_cast<std::size_t>(a.size())),
      sb(b.data(), static_cast<std::size_t>(b.size()));
  py::gil_scoped_release release;
  return psnr::ssim(Dims{shape[0], shape[1], shape[2]}, sa, sb);
}

template <typename T>
py::tuple as_tuple(const std::array<T, 3>& v) {
  return py::make_tuple(v[0], v[1], v[2]);
}

/// A message of the library's with the command line's options that volreel.encode, train and open
/// take as keywords written as those keywords: "--brick-size" as brick_size, "--resume" as
/// resume=True, "--bps 0.5" as bps=0.5. A flag after "volreel COMMAND " names that command's
/// own option and stays; one that no keyword takes (--pursuit) stays too, and a note at the end
/// says that it is the command line's.
std::string python_words(const std::string& message) {
  struct Keyword {
    std::string_view flag, name;
    bool flag_only;  ///< a switch: written as name=True
  };
  static constexpr Keyword keywords[] = {{"--brick-size", "brick_size", false},
                                         {"--max-keyframe-gap", "max_keyframe_gap", false},
                                         {"--zfp-accuracy", "zfp_accuracy", false},
                                         {"--max-error", "max_error", false},
                                         {"--tolerance", "tolerance", false},
                                         {"--dictionary", "dictionary", false},
                                         {"--overwrite", "overwrite", true},
                                         {"--variable", "variable", false},
                                         {"--resume", "resume", true},
                                         {"--atoms", "atoms", false},
                                         {"--codec", "codec", false},
                                         {"--psnr", "psnr", false},
                                         {"--bps", "bps", false},
                                         {"--out", "out", false},
                                         {"--tries", "tries", false},
                                         {"--stall-timeout", "stall_timeout", false}};
  const auto word_char = [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '-';
  };
  std::string out, foreign;  // foreign: the flags no keyword takes, as written
  std::size_t i = 0;
  while (i < message.size()) {
    const Keyword* hit = nullptr;
    if (message.compare(i, 2, "--") == 0 && (i == 0 || !word_char(message[i - 1])))
      for (const Keyword& k : keywords)
        if (message.compare(i, k.flag.size(), k.flag) == 0 &&
            (i + k.flag.size() == message.size() || !word_char(message[i + k.flag.size()]))) {
          hit = &k;
          break;
        }
    // "volreel train --atoms": the command's option.
    const std::size_t command = out.rfind("volreel ");
    const bool after_command = command != std::string::npos &&
                               out.find(' ', command + 8) == out.size() - 1 &&
                               out.size() > command + 9;
    if (!hit || after_command) {
      const bool flag = message.compare(i, 2, "--") == 0 && i + 2 < message.size() &&
                        std::isalpha(static_cast<unsigned char>(message[i + 2])) &&
                        (i == 0 || !word_char(message[i - 1]));
      if (flag && !after_command) {
        std::size_t end = i + 2;
        while (end < message.size() && word_char(message[end])) ++end;
        const std::string name = message.substr(i, end - i);
        if (foreign.find(name + ",") == std::string::npos) foreign += name + ",";
      }
      out += message[i++];
      continue;
    }
    i += hit->flag.size();
    out += hit->name;
    if (hit->flag_only) {
      out += "=True";
    } else if (i + 1 < message.size() && message[i] == ' ' &&
               (std::isdigit(static_cast<unsigned char>(message[i + 1])) ||
                message.compare(i + 1, 3, "dct") == 0)) {
      out += '=';  // the value that follows
      ++i;
    }
  }
  if (!foreign.empty()) {
    foreign.pop_back();
    const bool one = foreign.find(',') == std::string::npos;
    std::string list;
    for (char c : foreign) list += c == ',' ? std::string(", ") : std::string(1, c);
    out += " (" + list + (one ? " is an option" : " are options") +
           " of the volreel command line, which this module does not take: use the command for "
           "that)";
  }
  return out;
}

}  // namespace

}  // namespace volreel::python

PYBIND11_MODULE(_volreel, m) {
  using namespace volreel;
  using namespace volreel::python;
  m.doc() = "volreel's library: containers as numpy arrays, encoding, training and metrics";
  m.attr("__version__") = VOLREEL_VERSION;
  // GNU OpenMP's threads do not survive fork(): a child (multiprocessing's default start on
  // Linux) that enters a parallel region after its parent did waits for ever for threads it does
  // not have. A forked child runs volreel on its one thread.
  pthread_atfork(
      nullptr, nullptr, +[] { omp_set_num_threads(1); });

  static py::exception<format::FormatError> format_error(m, "FormatError", PyExc_ValueError);
  static py::exception<InputError> input_error(m, "InputError", PyExc_ValueError);
  // Both a FormatError and a ConnectionError (an OSError), as a network failure is either.
  // Held for the life of the process (never released at exit, after the interpreter).
  static PyObject* const network_error =
      py::module_::import("builtins")
          .attr("type")("NetworkError",
                        py::make_tuple(format_error, py::handle(PyExc_ConnectionError)),
                        py::dict(py::arg("__module__") = "volreel",
                                 py::arg("__doc__") =
                                     "Reading a container over HTTP failed: no connection, a "
                                     "timeout, an HTTP error status or a short answer"))
          .release()
          .ptr();
  m.attr("NetworkError") = py::handle(network_error);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const remote::NetworkError& e) {
      PyErr_SetString(network_error, e.what());
    } catch (const format::FormatError& e) {
      format_error(e.what());
    } catch (const InputError& e) {
      input_error(python_words(e.what()).c_str());
    }
  });

  py::class_<PyContainer>(m, "Container", "A NAME.vreel container opened for reading")
      .def(py::init([](const py::object& location, unsigned tries, double stall_timeout,
                       unsigned connections, std::optional<fs::path> cache,
                       const std::string& cache_size, std::optional<fs::path> ca_file) {
             // A str, or a path object (pathlib.Path) as os.fspath gives it.
             const py::object text = py::module_::import("os").attr("fspath")(location);
             if (!py::isinstance<py::str>(text))
               throw py::type_error(
                   "location: expected a folder's path or a URL as str or "
                   "os.PathLike, found " +
                   std::string(py::str(py::type::of(text))));
             return std::make_unique<PyContainer>(
                 text.cast<std::string>(),
                 UrlOptions{tries, stall_timeout, connections, std::move(cache), cache_size,
                            std::move(ca_file)});
           }),
           py::arg("location"), py::kw_only(), py::arg("tries") = UrlOptions{}.tries,
           py::arg("stall_timeout") = UrlOptions{}.stall_timeout,
           py::arg("connections") = UrlOptions{}.connections, py::arg("cache") = py::none(),
           py::arg("cache_size") = UrlOptions{}.cache_size, py::arg("ca_file") = py::none(),
           "Opens a NAME.vreel folder or an http(s):// URL of one. For a URL: tries of a read "
           "that fails in a way that may pass (1..20), seconds without a byte before a request "
           "is given up (stall_timeout, whole seconds: a fraction is rounded up), HTTP connections "
           "at most, a cache folder kept between "
           "runs and its size limit (e.g. \"2G\"), and a PEM file of certificate authorities "
           "to trust instead of the system's (ca_file)")
      .def_property_readonly(
          "dims", [](const PyContainer& c) { return as_tuple(c.manifest().dims); },
          "The finest level's size (x, y, z); frames are arrays [z, y, x]")
      .def_property_readonly("frames", &PyContainer::frames, "The number of time steps")
      .def_property_readonly(
          "times", [](const PyContainer& c) { return c.manifest().timestamps; },
          "Each time step's simulated time")
      .def_property_readonly(
          "levels", [](const PyContainer& c) { return c.manifest().levels; },
          "Octree levels: 0 is the root brick, levels - 1 full resolution")
      .def_property_readonly(
          "value_range",
          [](const PyContainer& c) {
            return std::pair(c.manifest().value_min, c.manifest().value_max);
          },
          "(min, max) of the values encoded")
      .def_property_readonly("bps", &PyContainer::bps,
                             "Bits per voxel: 8 x all stored bytes / (voxels per frame x frames)")
      .def_property_readonly(
          "variable", [](const PyContainer& c) { return c.manifest().variable; }, "The variable")
      .def_property_readonly(
          "spacing", [](const PyContainer& c) { return as_tuple(c.manifest().spacing); },
          "Voxel spacing (x, y, z)")
      .def_property_readonly("location", &PyContainer::location, "The folder or URL")
      .def(
          "level_dims",
          [](const PyContainer& c, const py::object& l) {
            return as_tuple(c.level_dims(c.level_index(l)));
          },
          py::arg("level"), "The size (x, y, z) of a level (negative: from the finest, -1)")
      .def("frame", &PyContainer::frame, py::arg("t"), py::arg("level") = py::none(),
           py::arg("out") = py::none(),
           "Time step t (negative: from the end) at a level (default the finest) as a float32 "
           "array [z, y, x], decoded as the player draws it (steps without a stored brick "
           "interpolated); into `out` when given (float32, C order, the level's shape)")
      .def("info", &PyContainer::info, "The manifest as a dict, with location, total_bytes, bps")
      .def("close", &PyContainer::close,
           "Lets go of the frames kept decoded and of the files or HTTP connections; frame() "
           "then raises ValueError, the manifest's properties stay. A `with` block closes it")
      .def_property_readonly("closed", &PyContainer::closed, "Whether close() was called");

  m.def("encode", &encode, py::arg("frames"), py::arg("out"), py::kw_only(),
        py::arg("psnr") = py::none(), py::arg("bps") = py::none(),
        py::arg("tolerance") = py::none(), py::arg("max_error") = py::none(),
        py::arg("dictionary") = "", py::arg("codec") = "ksvd", py::arg("zfp_accuracy") = py::none(),
        py::arg("atoms") = 0, py::arg("max_keyframe_gap") = py::none(),
        py::arg("overwrite") = false, py::arg("resume") = false, py::arg("times") = py::none(),
        py::arg("variable") = "", py::arg("brick_size") = "auto", py::arg("spacing") = py::none(),
        "Encodes frames into the container `out` as `volreel encode` does (brick_size: \"auto\" "
        "or stored voxels per brick axis, a multiple of 6 in 12..66, as --brick-size; spacing: "
        "the voxel spacing (x, y, z) stored for readers such as ParaView, as --spacing); returns a "
        "dict of what it wrote and delivered. A psnr, bps or max_error target the container "
        "misses: a RuntimeWarning saying by how much, and \"targets_met\" false");
  m.def("train", &train, py::arg("frames"), py::arg("out"), py::kw_only(), py::arg("atoms") = 256,
        py::arg("psnr") = py::none(), py::arg("tolerance") = py::none(),
        py::arg("times") = py::none(), py::arg("overwrite") = false,
        "Trains a dictionary on frames (Algorithm 1 over a coreset hierarchy) into the file `out`");
  m.def("psnr", &psnr_of, py::arg("a"), py::arg("b"),
        "PSNR of b against the original a: 10 log10((max a - min a)^2 / MSE), in dB");
  m.def("ssim", &ssim_of, py::arg("a"), py::arg("b"),
        "SSIM of b against a (1, 2 or 3 D): Gaussian window sigma 1.5, as volreel compare");
}
