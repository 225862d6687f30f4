// raw_reader.cpp: readers for raw series directories (series.json + one float32 file per frame)
// and for single raw files described on the command line (--dims, --dtype, --frames).
#include <fstream>
#include <vector>

#include "detail.hpp"

namespace volreel::datasets::detail {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

class RawSeriesReader final : public SeriesReader {
 public:
  RawSeriesReader(fs::path dir, const OpenOptions& options)
      : dir_(std::move(dir)), replace_nan_(options.replace_nan) {
    const fs::path manifest = dir_ / "series.json";
    std::ifstream in(manifest);
    if (!in)
      throw InputError("'" + dir_.string() +
                       "' has no series.json: not a raw series directory (for a single raw file "
                       "pass the file and --dims)");
    json j;
    try {
      j = json::parse(in);
    } catch (const json::exception& e) {
      throw InputError("'" + manifest.string() + "' is not valid JSON: " + e.what());
    }
    const auto fail = [&](const std::string& what) {
      throw InputError("'" + manifest.string() + "': " + what);
    };
    try {
      if (j.value("format", "") != "volreel-raw-series")
        fail("\"format\" is not \"volreel-raw-series\"");
      if (j.value("version", 0) != 1)
        fail("unsupported \"version\" (this volreel reads version 1)");
      const auto& d = j.at("dims");
      if (!d.is_array() || d.size() != 3) fail("\"dims\" must be [x, y, z]");
      info_.dims =
          Dims{d[0].get<std::int64_t>(), d[1].get<std::int64_t>(), d[2].get<std::int64_t>()};
      if (info_.dims.x <= 0 || info_.dims.y <= 0 || info_.dims.z <= 0)
        fail("\"dims\" must be positive");
      if (j.value("dtype", "f32") != "f32") fail("\"dtype\" must be \"f32\"");
      frame_files_ = j.at("frames").get<std::vector<std::string>>();
      info_.timestamps = j.at("timestamps").get<std::vector<double>>();
      if (frame_files_.empty()) fail("\"frames\" is empty");
      if (info_.timestamps.size() != frame_files_.size())
        fail("\"timestamps\" has " + std::to_string(info_.timestamps.size()) +
             " entries but \"frames\" has " + std::to_string(frame_files_.size()));
      if (j.contains("spacing")) info_.spacing = j.at("spacing").get<std::array<double, 3>>();
      info_.variable = j.value("variable", "");
      if (j.contains("generator")) info_.generator = j.at("generator");
    } catch (const json::exception& e) {
      fail(std::string("missing or malformed field: ") + e.what());
    }
    info_.frames = frame_files_.size();
    info_.source = "raw series " + dir_.string();
    // Every frame must be there with the right size before anything is read.
    const std::uintmax_t expected = info_.dims.voxels() * sizeof(float);
    for (std::size_t t = 0; t < frame_files_.size(); ++t) {
      const fs::path file = dir_ / frame_files_[t];
      std::error_code ec;
      const auto size = fs::file_size(file, ec);
      if (ec) fail("frame " + std::to_string(t) + ": '" + file.string() + "' is missing");
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
