// series.cpp: dtype names, the open_series dispatcher and the raw series writer.
#include "volreel/datasets/series.hpp"

#include <algorithm>
#include <bit>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>

#include <unistd.h>

#include <cerrno>

#include "detail.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/json_input.hpp"
#include "volreel/format/source.hpp"

namespace volreel::datasets {

namespace fs = std::filesystem;

Dtype parse_dtype(const std::string& text) {
  if (text == "f32" || text == "float32" || text == "float") return Dtype::f32;
  if (text == "f64" || text == "float64" || text == "double") return Dtype::f64;
  if (text == "u8" || text == "uint8") return Dtype::u8;
  if (text == "u16" || text == "uint16") return Dtype::u16;
  throw InputError("unknown dtype '" + text + "': expected f32, f64, u8 or u16");
}

std::string to_string(Dtype dtype) {
  switch (dtype) {
    case Dtype::f32:
      return "f32";
    case Dtype::f64:
      return "f64";
    case Dtype::u8:
      return "u8";
    case Dtype::u16:
      return "u16";
  }
  return "?";
}

std::size_t dtype_size(Dtype dtype) {
  switch (dtype) {
    case Dtype::f32:
      return 4;
    case Dtype::f64:
      return 8;
    case Dtype::u8:
      return 1;
    case Dtype::u16:
      return 2;
  }
  return 0;
}

std::string raw_frame_name(std::size_t t) {
  char name[32];
  std::snprintf(name, sizeof name, "%06zu.f32", t);
  return name;
}

Volume SeriesReader::read_frame(std::size_t t) const {
  Volume volume(info_.dims);
  read_frame(t, volume.data);
  return volume;
}

void SeriesReader::read_frame(std::size_t t, std::span<float> out) const {
  if (out.size() != info_.dims.voxels()) throw InputError("read_frame: output has the wrong size");
  read_slab(t, 0, info_.dims.planes(), out);
}

void SeriesReader::read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                             std::span<float> out) const {
  detail::check_slab(info_, t, z_begin, z_end, out.size());
  const std::size_t plane = info_.dims.plane();
  if (z_begin == 0 && z_end == info_.dims.planes()) {
    read_frame(t, out);
    return;
  }
  std::vector<float> frame(info_.dims.voxels());
  read_frame(t, frame);
  std::copy(frame.begin() + static_cast<std::ptrdiff_t>(z_begin * plane),
            frame.begin() + static_cast<std::ptrdiff_t>(z_end * plane), out.begin());
}

namespace {

/// An input takes none of the options of the other kinds: they would be ignored, and a user who
/// gives them expects them to apply. `kind_name`: what the input is ("an HDF5 file").
void refuse_other_options(const fs::path& path, const OpenOptions& options, InputKind kind,
                          const char* kind_name) {
  const bool raw = kind == InputKind::raw;
  std::vector<std::string> raw_given, given;
  if (!raw && options.dims) raw_given.emplace_back("--dims");
  if (!raw && options.dtype) raw_given.emplace_back("--dtype");
  if (!raw && options.frames) raw_given.emplace_back("--frames");
  const auto names = [](const std::vector<std::string>& list) {
    std::string text;
    for (std::size_t i = 0; i < list.size(); ++i)
      text += (i == 0 ? "" : i + 1 == list.size() ? " and " : ", ") + list[i];
    return text;
  };
  if (kind != InputKind::hdf5 && !options.dataset.empty()) given.emplace_back("--dataset (HDF5)");
  if (kind != InputKind::netcdf && !options.variable.empty())
    given.emplace_back("--variable (NetCDF)");
  if (kind != InputKind::netcdf && !options.time_dimension.empty())
    given.emplace_back("--time-dim (NetCDF)");
  if (raw_given.empty() && given.empty()) return;
  // Every option at fault in one message, so that one run says all that is to leave out.
  std::string message = "'" + path.string() + "' is " + kind_name;
  if (!raw_given.empty())
    message += " that gives its own dimensions, type and frames: leave out " + names(raw_given) +
               " (options for raw files)";
  if (!given.empty())
    message += std::string(raw_given.empty() ? ": leave out " : "; and ") + names(given) +
               ", options for " +
               (given.size() == 1 ? "another kind of input" : "other kinds of input") +
               " (see Series in the command's --help)";
  throw InputError(message);
}

}  // namespace

namespace {

bool is_hdf5_name(std::string ext) {
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".h5" || ext == ".hdf5" || ext == ".hdf" || ext == ".he5";
}

bool is_netcdf_name(std::string ext) {
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".nc" || ext == ".nc4" || ext == ".cdf" || ext == ".netcdf";
}

/// What a regular file's first bytes say it is: HDF5 (its signature at byte 0, or after a user
/// block at 512·2^k), which NetCDF-4 files are too, or classic NetCDF ("CDF" and version 1, 2
/// or 5); nothing for anything else, for what cannot be read, and for what is not a regular file
/// (a FIFO is never opened).
std::optional<InputKind> signature_kind(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return std::nullopt;
  std::ifstream in(path, std::ios::binary);
  const std::uint64_t size = fs::file_size(path, ec);
  if (!in || ec) return std::nullopt;
  char head[8] = {};
  static constexpr char hdf5[8] = {'\x89', 'H', 'D', 'F', '\r', '\n', '\x1a', '\n'};
  for (std::uint64_t at = 0; at + 8 <= size; at = at == 0 ? 512 : 2 * at) {
    in.seekg(static_cast<std::streamoff>(at));
    if (!in.read(head, 8)) return std::nullopt;
    if (std::memcmp(head, hdf5, 8) == 0) return InputKind::hdf5;
    if (at == 0 && head[0] == 'C' && head[1] == 'D' && head[2] == 'F' &&
        (head[3] == 1 || head[3] == 2 || head[3] == 5))
      return InputKind::netcdf;
  }
  return std::nullopt;
}

/// input_kind with the file's signature_kind already read.
InputKind kind_of(const fs::path& path, std::optional<InputKind> signature) {
  std::error_code ec;
  if (fs::is_directory(path, ec) || path.filename() == "series.json") return InputKind::raw_series;
  // The name first for NetCDF, whose version 4 files are HDF5 files; then what the bytes say,
  // then the name.
  if (is_netcdf_name(path.extension().string())) return InputKind::netcdf;
  if (signature) return *signature;
  if (is_hdf5_name(path.extension().string())) return InputKind::hdf5;
  return InputKind::raw;
}

}  // namespace

InputKind input_kind(const fs::path& path) {
  return kind_of(path, signature_kind(path));
}

bool describes_itself(const fs::path& path) {
  return input_kind(path) != InputKind::raw;
}

OpenOptions options_for(const fs::path& path, const OpenOptions& options, const fs::path* other) {
  OpenOptions side = options;
  const InputKind kind = input_kind(path);
  const auto other_takes = [&](InputKind k) {
    return other != nullptr && kind != k && input_kind(*other) == k;
  };
  if (other_takes(InputKind::raw)) side.dims.reset(), side.dtype.reset(), side.frames.reset();
  if (other_takes(InputKind::hdf5)) side.dataset.clear();
  if (other_takes(InputKind::netcdf)) side.variable.clear(), side.time_dimension.clear();
  return side;
}

namespace {

std::unique_ptr<SeriesReader> open_any(const fs::path& path, const OpenOptions& options) {
  std::error_code ec;
  if (!fs::exists(path, ec) && detail::is_glob(path.string())) {
    refuse_other_options(path, options, InputKind::raw, "a pattern of raw files");
    return detail::open_raw_glob(path.string(), options);
  }
  if (const std::string s = path.string(); s.starts_with("http://") || s.starts_with("https://"))
    throw InputError(s + ": a URL, where this reads series and containers on this machine (" +
                     format::url_readers + ")");
  if (!fs::exists(path, ec)) throw InputError("'" + path.string() + "' does not exist");
  if (fs::is_directory(path, ec) || path.filename() == "series.json") {
    // A folder without series.json: the reader says what it lacks.
    if (fs::exists(fs::is_directory(path, ec) ? path / "series.json" : path, ec))
      refuse_other_options(path, options, InputKind::raw_series,
                           "a series directory (series.json)");
    return detail::open_raw_series(fs::is_directory(path, ec) ? path : path.parent_path(), options);
  }
  // Never hand a FIFO or a device to a reader that would block on it or read it forever.
  const fs::file_type type = fs::status(path, ec).type();
  if (type != fs::file_type::regular)
    throw InputError("'" + path.string() + "' is " + format::detail::file_kind(type) +
                     ", expected a regular file (raw, HDF5 or NetCDF) or a series directory");
  const std::optional<InputKind> signature = signature_kind(path);
  const InputKind kind = kind_of(path, signature);
  if (kind == InputKind::hdf5) {
    // Named as one, but without HDF5's signature: not taken for HDF5 (nor for raw data).
    if (!signature)
      throw InputError("'" + path.string() + "' is named as an HDF5 file but is not one (it " +
                       "lacks HDF5's signature): a raw file named so needs another name, an " +
                       "HDF5 file may be damaged, and a .hdf file may be HDF4, which volreel " +
                       "does not read");
    refuse_other_options(path, options, InputKind::hdf5, "an HDF5 file");
    return detail::open_hdf5(path, options);
  }
  if (kind == InputKind::netcdf) {
    // Named as one, but with neither classic NetCDF's nor NetCDF-4's (HDF5's) signature.
    if (!signature)
      throw InputError("'" + path.string() + "' is named as a NetCDF file but is not one (it " +
                       "lacks the signature of classic NetCDF, \"CDF\", and of NetCDF-4): a raw " +
                       "file named so needs another name, and a NetCDF file may be damaged");
    refuse_other_options(path, options, InputKind::netcdf, "a NetCDF file");
    return detail::open_netcdf(path, options);
  }
  refuse_other_options(path, options, InputKind::raw, "a raw file");
  return detail::open_raw_file(path, options);
}

}  // namespace

bool input_includes(const fs::path& path, const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(file, ec)) return false;
  if (detail::is_glob(path.string()) && !fs::exists(path, ec)) {
    try {
      for (const fs::path& matched : detail::expand_glob(path.string()))
        if (fs::equivalent(matched, file, ec)) return true;
    } catch (const InputError&) {  // no match: nothing of the input to replace
    }
    return false;
  }
  // A series directory named by its series.json: the directory, and the frames its series.json
  // lists (which may lie elsewhere, "../frame.f32").
  const fs::path whole = path.filename() == "series.json"
                             ? (path.has_parent_path() ? path.parent_path() : fs::path("."))
                             : path;
  if (fs::is_directory(whole, ec)) {
    if (path_within(whole, file)) return true;
    try {
      const auto json = format::read_json_file(whole / "series.json");
      if (json.contains("frames") && json["frames"].is_array())
        for (const auto& name : json["frames"])
          if (name.is_string() && fs::equivalent(whole / name.get<std::string>(), file, ec))
            return true;
    } catch (const std::exception&) {  // no series.json, or not one: the reader will say
    }
    return false;
  }
  return fs::equivalent(path, file, ec);
}

bool path_within(const fs::path& dir, const fs::path& path) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return false;
  const fs::path d = fs::canonical(dir, ec);
  const fs::path target = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) return false;
  for (fs::path p = target; !p.empty(); p = p.parent_path()) {
    if (p == d) return true;
    if (p == p.parent_path()) break;
  }
  return false;
}

void check_spacing(const std::array<double, 3>& spacing) {
  for (const double s : spacing)
    if (!(std::isfinite(s) && s > 0))
      throw InputError("spacing: expected three positive finite numbers (x, y, z), found " +
                       format::number_text(spacing[0]) + ", " + format::number_text(spacing[1]) +
                       ", " + format::number_text(spacing[2]));
}

void SeriesReader::set_spacing(const std::array<double, 3>& spacing) {
  check_spacing(spacing);
  info_.spacing = spacing;
}

std::unique_ptr<SeriesReader> open_series(const fs::path& path, const OpenOptions& options) {
  auto reader = open_any(path, options);
  if (options.spacing) reader->set_spacing(*options.spacing);
  // A reader hands out frames of voxels: a dataset or variable of none is refused here, once.
  const SeriesInfo& info = reader->info();
  check_frame_voxels(info.dims, info.source);
  if (info.frames == 0) throw InputError(info.source + ": 0 time steps (nothing to read)");
  if (info.dims.voxels() == 0)
    throw InputError(info.source + ": frames of " + to_string(info.dims) + " voxels (none)");
  return reader;
}

namespace detail {

void check_slab(const SeriesInfo& info, std::size_t t, std::size_t z_begin, std::size_t z_end,
                std::size_t out_size) {
  if (t >= info.frames)
    throw InputError("frame " + std::to_string(t) + " is out of range: " + info.source + " has " +
                     std::to_string(info.frames) + " frames");
  if (z_begin >= z_end || z_end > info.dims.planes())
    throw InputError("planes [" + std::to_string(z_begin) + ", " + std::to_string(z_end) +
                     ") are not a slab of " + info.source + ", whose frames have " +
                     std::to_string(info.dims.planes()) + " planes");
  if (out_size != info.dims.plane() * (z_end - z_begin))
    throw InputError("read_slab: output has the wrong size");
}

std::string voxel_name(std::size_t i, Dims dims, std::size_t z_begin) {
  const auto x = static_cast<std::int64_t>(i) % dims.x;
  const auto y = static_cast<std::int64_t>(i) / dims.x % dims.y;
  const auto z = i / dims.plane() + z_begin;
  return "(" + std::to_string(x) + ", " + std::to_string(y) + ", " + std::to_string(z) + ")";
}

void check_finite(std::span<float> values, Dims dims, const std::string& what,
                  std::optional<float> replacement, std::size_t z_begin) {
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (std::isfinite(values[i])) continue;
    if (replacement) {
      values[i] = *replacement;
      continue;
    }
    throw InputError(what + ": value " + format::number_text(values[i]) + " at voxel " +
                     voxel_name(i, dims, z_begin) + " is not finite" +
                     (std::isinf(values[i])
                          ? " (or, in data of a wider type, beyond float32's range of 3.4e38: "
                            "scale the data)"
                          : std::string()) +
                     "; use --replace-nan V to substitute a value");
  }
}

void read_exact(const fs::path& file, std::uint64_t offset, std::span<unsigned char> out) {
  int fd = -1;
  std::uint64_t size = 0;
  try {
    fd = format::detail::open_regular_file(file, size);
  } catch (const format::FormatError& e) {
    throw InputError(e.what());
  }
  std::size_t got = 0;
  int error = 0;
  while (got < out.size()) {
    const ssize_t n =
        ::pread(fd, out.data() + got, out.size() - got, static_cast<off_t>(offset + got));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) error = errno;
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
  }
  ::close(fd);
  if (got != out.size())
    throw InputError("'" + file.string() + "': expected " + std::to_string(out.size()) +
                     " bytes at offset " + std::to_string(offset) + ", " +
                     (error != 0 ? std::string("read error (") + std::strerror(error) + ") after "
                                 : "file ends after ") +
                     std::to_string(got));
}

void convert_to_float(const unsigned char* bytes, Dtype dtype, std::span<float> out) {
  static_assert(std::endian::native == std::endian::little, "volreel assumes a little-endian host");
  const std::size_t n = out.size();
  switch (dtype) {
    case Dtype::f32:
      std::memcpy(out.data(), bytes, n * 4);
      break;
    case Dtype::f64:
      for (std::size_t i = 0; i < n; ++i) {
        double v;
        std::memcpy(&v, bytes + 8 * i, 8);
        out[i] = static_cast<float>(v);
      }
      break;
    case Dtype::u8:
      for (std::size_t i = 0; i < n; ++i) out[i] = bytes[i];
      break;
    case Dtype::u16:
      for (std::size_t i = 0; i < n; ++i) {
        std::uint16_t v;
        std::memcpy(&v, bytes + 2 * i, 2);
        out[i] = v;
      }
      break;
  }
}

}  // namespace detail

RawSeriesWriter::RawSeriesWriter(fs::path dir, Dims dims, std::string variable, bool overwrite)
    : dir_(std::move(dir)), dims_(dims), variable_(std::move(variable)) {
  if (dims_.voxels() == 0) throw InputError("cannot write a series with empty dimensions");
  std::error_code ec;
  const fs::path manifest = dir_ / "series.json";
  if (fs::exists(manifest, ec) && !overwrite)
    throw InputError("'" + dir_.string() +
                     "' already holds a series; choose another --out or pass --overwrite");
  // A folder of other files (the user's data, a container) is never written into: its files
  // could be replaced. Hidden names and a mount point's lost+found aside. Frame files alone
  // (NNNNNN.f32, no series.json) are what an interrupted writer leaves: replaced with overwrite.
  std::size_t interrupted_frames = 0;
  if (fs::is_directory(dir_, ec) && !fs::exists(manifest, ec)) {
    for (const auto& entry : fs::directory_iterator(dir_, ec)) {
      const std::string name = entry.path().filename().string();
      if (name.starts_with('.') || name == "lost+found") continue;
      const bool frame = name.size() == 10 && name.ends_with(".f32") &&
                         std::all_of(name.begin(), name.begin() + 6,
                                     [](unsigned char c) { return std::isdigit(c) != 0; });
      if (!frame)
        throw InputError("'" + dir_.string() + "' holds '" + name +
                         "' but no series.json: a series is written into a new or empty folder "
                         "(or over a series, with --overwrite); choose another --out");
      interrupted_frames = std::max(interrupted_frames, std::stoul(name.substr(0, 6)) + 1);
    }
    if (interrupted_frames > 0 && !overwrite)
      throw InputError("'" + dir_.string() +
                       "' holds frame files but no series.json, as an interrupted run leaves "
                       "them: pass --overwrite to replace them, or choose another --out");
    stale_frames_ = interrupted_frames;
  } else if (fs::exists(dir_, ec) && !fs::is_directory(dir_, ec)) {
    throw InputError("'" + dir_.string() + "' is " +
                     format::detail::file_kind(fs::status(dir_, ec).type()) +
                     ", not a folder: choose another --out");
  }
  // The directories this writer makes, deepest first (removed again without finish).
  for (fs::path d = fs::absolute(dir_, ec);
       !d.empty() && !fs::exists(d, ec) && d != d.parent_path(); d = d.parent_path())
    created_.push_back(d);
  fs::create_directories(dir_, ec);
  if (ec) throw InputError("cannot create directory '" + dir_.string() + "': " + ec.message());
  if (overwrite && fs::exists(manifest, ec)) {
    // The new frames go to a folder of their own until finish() moves them in, so that a run
    // that fails or is stopped leaves the old series whole.
    staging_ = dir_ / format::detail::replacement_folder_name;
    fs::remove_all(staging_, ec);  // what an interrupted replacement left
    fs::create_directory(staging_, ec);
    if (ec)
      throw InputError("cannot create directory '" + staging_.string() + "': " + ec.message());
    // A series this writer's kind wrote (it has a generator): its frames that the new one does
    // not write are removed by finish(), so that a shorter series leaves none behind. Files of a
    // series written by other means are never touched.
    try {
      const auto old = format::read_json_file(manifest);
      if (old.is_object() && old.contains("generator") && old.contains("frames") &&
          old["frames"].is_array())
        for (std::size_t t = 0; t < old["frames"].size(); ++t)
          if (old["frames"][t] == raw_frame_name(t)) stale_frames_ = t + 1;
    } catch (const std::exception&) {
    }
  }
}

RawSeriesWriter::~RawSeriesWriter() {
  if (finished_) return;
  std::error_code ec;
  if (!staging_.empty()) {
    fs::remove_all(staging_, ec);
    return;
  }
  for (std::size_t t = 0; t < timestamps_.size(); ++t)
    if (timestamps_[t]) fs::remove(dir_ / raw_frame_name(t), ec);
  for (const fs::path& d : created_) fs::remove(d, ec);  // only if empty
}

namespace {

void write_atomically(const fs::path& path, const void* data, std::size_t size) {
  format::detail::write_file_atomically(path, {static_cast<const std::byte*>(data), size});
}

}  // namespace

void RawSeriesWriter::write_frame(std::size_t t, double timestamp, std::span<const float> data) {
  if (data.size() != dims_.voxels())
    throw InputError("frame " + std::to_string(t) + " has " + std::to_string(data.size()) +
                     " values, expected " + std::to_string(dims_.voxels()));
  write_atomically((staging_.empty() ? dir_ : staging_) / raw_frame_name(t), data.data(),
                   data.size_bytes());
  if (timestamps_.size() <= t) timestamps_.resize(t + 1);
  timestamps_[t] = timestamp;
}

void RawSeriesWriter::finish() {
  nlohmann::json j;
  j["format"] = "volreel-raw-series";
  j["version"] = 1;
  j["dims"] = {dims_.x, dims_.y, dims_.z};
  j["dtype"] = "f32";
  j["spacing"] = spacing_;
  j["variable"] = variable_;
  nlohmann::json times = nlohmann::json::array(), names = nlohmann::json::array();
  for (std::size_t t = 0; t < timestamps_.size(); ++t) {
    if (!timestamps_[t])
      throw InputError("series '" + dir_.string() + "': frame " + std::to_string(t) +
                       " was never written");
    times.push_back(*timestamps_[t]);
    names.push_back(raw_frame_name(t));
  }
  if (timestamps_.empty())
    throw InputError("series '" + dir_.string() + "': no frames were written");
  j["timestamps"] = times;
  j["frames"] = names;
  if (!generator_.is_null()) j["generator"] = generator_;
  const std::string text = j.dump(2) + "\n";
  std::error_code ec;
  if (!staging_.empty()) {
    // The old series' manifest goes first, so that no series.json names a mix of frames. Should
    // a move fail, the frames not moved yet stay where they are (not removed by the destructor),
    // and the message says where.
    try {
      fs::remove(dir_ / "series.json");
      for (std::size_t t = 0; t < timestamps_.size(); ++t)
        fs::rename(staging_ / raw_frame_name(t), dir_ / raw_frame_name(t));
    } catch (const fs::filesystem_error& e) {
      finished_ = true;
      throw InputError("moving the frames written to " + staging_.string() + " into " +
                       dir_.string() + " failed (" + e.code().message() +
                       "): the frames not moved are still there, and " + dir_.string() +
                       " holds no series.json");
    }
  }
  write_atomically(dir_ / "series.json", text.data(), text.size());
  finished_ = true;
  if (!staging_.empty()) fs::remove_all(staging_, ec);
  for (std::size_t t = timestamps_.size(); t < stale_frames_; ++t)
    fs::remove(dir_ / raw_frame_name(t), ec);
}

}  // namespace volreel::datasets
