// raw_reader.cpp: readers for raw series directories (series.json + one float32 file per frame)
// and for single raw files described on the command line (--dims, --dtype, --frames).
#include <cmath>
#include <vector>

#include "detail.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/json_input.hpp"

namespace volreel::datasets::detail {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

class RawSeriesReader final : public SeriesReader {
 public:
  RawSeriesReader(fs::path dir, const OpenOptions& options)
      : dir_(std::move(dir)), replace_nan_(options.replace_nan) {
    const fs::path manifest = dir_ / "series.json";
    std::error_code ec;
    if (!fs::exists(manifest, ec))
      throw InputError("'" + dir_.string() +
                       "' has no series.json: not a raw series directory (for a single raw file "
                       "pass the file and --dims)");
    json j;
    try {
      j = format::read_json_file(manifest);
    } catch (const format::FormatError& e) {
      throw InputError(std::string(e.what()) +
                       " (series.json's fields: see volreel encode --help)");
    }
    const auto fail = [&](const std::string& what) {
      throw InputError("'" + manifest.string() + "': " + what);
    };
    // Each field by name, with what was expected and what was found.
    const auto field = [&](const char* name, bool required) -> const json* {
      if (!j.is_object()) fail("expected a JSON object, found " + format::describe_json(j));
      const auto it = j.find(name);
      if (it == j.end()) {
        if (required) fail("field \"" + std::string(name) + "\" is missing");
        return nullptr;
      }
      return &*it;
    };
    const auto wrong = [&](const char* name, const std::string& expected, const json& found) {
      fail("field \"" + std::string(name) + "\": expected " + expected + ", found " +
           format::describe_json(found));
    };
    const json& fmt = *field("format", true);
    if (fmt != "volreel-raw-series") wrong("format", "\"volreel-raw-series\"", fmt);
    const json& version = *field("version", true);
    if (version != 1) wrong("version", "1 (the version this volreel reads)", version);
    const json& d = *field("dims", true);
    if (!d.is_array() || d.size() != 3) wrong("dims", "[x, y, z]", d);
    std::int64_t dims[3];
    for (std::size_t a = 0; a < 3; ++a) {
      if (!d[a].is_number_integer() || d[a].get<std::int64_t>() <= 0 ||
          d[a].get<std::int64_t>() > (std::int64_t{1} << 24))
        wrong("dims", "three integers in 1..16777216", d[a]);
      dims[a] = d[a].get<std::int64_t>();
    }
    info_.dims = Dims{dims[0], dims[1], dims[2]};
    const json& dtype = *field("dtype", true);
    if (dtype != "f32") wrong("dtype", "\"f32\" (32-bit floats, little-endian)", dtype);
    const json& frames = *field("frames", true);
    if (!frames.is_array() || frames.empty())
      wrong("frames", "a non-empty array of file names", frames);
    for (const json& f : frames) {
      if (!f.is_string() || f.get_ref<const std::string&>().empty())
        wrong("frames", "file names (strings)", f);
      frame_files_.push_back(f.get<std::string>());
    }
    const json& times = *field("timestamps", true);
    if (!times.is_array() || times.size() != frames.size())
      wrong("timestamps",
            "an array of " + std::to_string(frames.size()) + " numbers (one per frame)", times);
    for (const json& t : times) {
      if (!t.is_number() || !std::isfinite(t.get<double>()))
        wrong("timestamps", "finite numbers", t);
      if (!info_.timestamps.empty() && !(t.get<double>() > info_.timestamps.back()))
        wrong("timestamps",
              "increasing numbers (after " + std::to_string(info_.timestamps.back()) + ")", t);
      info_.timestamps.push_back(t.get<double>());
    }
    if (const json* spacing = field("spacing", false)) {
      if (!spacing->is_array() || spacing->size() != 3) wrong("spacing", "[sx, sy, sz]", *spacing);
      for (std::size_t a = 0; a < 3; ++a) {
        const json& v = (*spacing)[a];
        if (!v.is_number() || !(v.get<double>() > 0) || !std::isfinite(v.get<double>()))
          wrong("spacing", "three positive finite numbers", v);
        info_.spacing[a] = v.get<double>();
      }
    }
    if (const json* variable = field("variable", false)) {
      if (!variable->is_string()) wrong("variable", "a string", *variable);
      info_.variable = variable->get<std::string>();
    }
    if (const json* generator = field("generator", false)) info_.generator = *generator;
    info_.frames = frame_files_.size();
    info_.source = "raw series " + dir_.string();
    // Every frame must be there with the right size before anything is read.
    const std::uintmax_t expected = info_.dims.voxels() * sizeof(float);
    for (std::size_t t = 0; t < frame_files_.size(); ++t) {
      const fs::path file = dir_ / frame_files_[t];
      const fs::file_status status = fs::status(file, ec);
      if (!fs::exists(status))
        fail("frame " + std::to_string(t) + ": '" + file.string() + "' is missing");
      if (!fs::is_regular_file(status))
        fail("frame " + std::to_string(t) + ": '" + file.string() + "' is " +
             format::detail::file_kind(status.type()) + ", expected a regular file");
      const auto size = fs::file_size(file, ec);
      if (ec)
        fail("frame " + std::to_string(t) + ": cannot read the size of '" + file.string() +
             "': " + ec.message());
      if (size != expected)
        fail("frame " + std::to_string(t) + ": '" + file.string() + "' is " + std::to_string(size) +
             " bytes, expected " + std::to_string(expected) + " (" + to_string(info_.dims) +
             " float32)");
    }
  }

  void read_frame(std::size_t t, std::span<float> out) const override {
    if (t >= info_.frames)
      throw InputError("frame " + std::to_string(t) + " is out of range: " + info_.source +
                       " has " + std::to_string(info_.frames) + " frames");
    if (out.size() != info_.dims.voxels())
      throw InputError("read_frame: output has the wrong size");
    const fs::path file = dir_ / frame_files_[t];
    read_exact(file, 0, {reinterpret_cast<unsigned char*>(out.data()), out.size_bytes()});
    check_finite(out, info_.dims, "'" + file.string() + "'", replace_nan_);
  }

 private:
  fs::path dir_;
  std::vector<std::string> frame_files_;
  std::optional<float> replace_nan_;
};

class RawFileReader final : public SeriesReader {
 public:
  RawFileReader(fs::path file, const OpenOptions& options)
      : file_(std::move(file)),
        dtype_(options.dtype.value_or(Dtype::f32)),
        replace_nan_(options.replace_nan) {
    if (!options.dims)
      throw InputError("'" + file_.string() +
                       "' is a raw file: say its size with --dims XxYxZ (and --dtype, --frames if "
                       "not f32 and 1)");
    info_.dims = *options.dims;
    info_.frames = options.frames.value_or(1);
    if (info_.frames == 0) throw InputError("--frames must be at least 1");
    frame_bytes_ = info_.dims.voxels() * dtype_size(dtype_);
    std::error_code ec;
    const auto size = fs::file_size(file_, ec);
    if (ec) throw InputError("cannot read the size of '" + file_.string() + "': " + ec.message());
    if (size != frame_bytes_ * info_.frames)
      throw InputError(
          "'" + file_.string() + "' is " + std::to_string(size) + " bytes, but --dims " +
          to_string(info_.dims) + " --dtype " + to_string(dtype_) + " --frames " +
          std::to_string(info_.frames) + " needs " + std::to_string(frame_bytes_ * info_.frames) +
          (size % frame_bytes_ == 0 ? " (it holds " + std::to_string(size / frame_bytes_) +
                                          " such frames: pass --frames)"
                                    : ""));
    for (std::size_t t = 0; t < info_.frames; ++t)
      info_.timestamps.push_back(static_cast<double>(t));
    info_.source = "raw file " + file_.string() + " (" + to_string(dtype_) + ")";
  }

  void read_frame(std::size_t t, std::span<float> out) const override {
    if (t >= info_.frames)
      throw InputError("frame " + std::to_string(t) + " is out of range: " + info_.source +
                       " has " + std::to_string(info_.frames) + " frames");
    if (out.size() != info_.dims.voxels())
      throw InputError("read_frame: output has the wrong size");
    std::vector<unsigned char> bytes(frame_bytes_);
    read_exact(file_, t * frame_bytes_, bytes);
    convert_to_float(bytes.data(), dtype_, out);
    check_finite(out, info_.dims, "'" + file_.string() + "' frame " + std::to_string(t),
                 replace_nan_);
  }

 private:
  fs::path file_;
  Dtype dtype_;
  std::size_t frame_bytes_ = 0;
  std::optional<float> replace_nan_;
};

}  // namespace

std::unique_ptr<SeriesReader> open_raw_series(const fs::path& dir, const OpenOptions& options) {
  return std::make_unique<RawSeriesReader>(dir, options);
}

std::unique_ptr<SeriesReader> open_raw_file(const fs::path& file, const OpenOptions& options) {
  return std::make_unique<RawFileReader>(file, options);
}

}  // namespace volreel::datasets::detail
