// raw_reader.cpp: readers for raw series directories (series.json + one float32 file per frame)
// and for single raw files described on the command line (--dims, --dtype, --frames).
#include <glob.h>

#include <algorithm>
#include <cctype>
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
    check_frame_voxels(info_.dims, "'" + manifest.string() + "': field \"dims\"");
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
              "increasing numbers (after " + format::number_text(info_.timestamps.back()) + ")", t);
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

  void read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                 std::span<float> out) const override {
    check_slab(info_, t, z_begin, z_end, out.size());
    const fs::path file = dir_ / frame_files_[t];
    read_exact(file, z_begin * info_.dims.plane() * sizeof(float),
               {reinterpret_cast<unsigned char*>(out.data()), out.size_bytes()});
    check_finite(out, info_.dims, "'" + file.string() + "'", replace_nan_, z_begin);
  }

 private:
  fs::path dir_;
  std::vector<std::string> frame_files_;
  std::optional<float> replace_nan_;
};

/// Raw files described on the command line: one file holding --frames frames back to back, or
/// the files a glob matched, one frame each, in natural order.
class RawFileReader final : public SeriesReader {
 public:
  /// `pattern`: what matched the files (a glob), or empty for one file; `described`: how errors
  /// name the input.
  RawFileReader(std::vector<fs::path> files, std::size_t frames_per_file,
                const std::string& pattern, const std::string& described,
                const OpenOptions& options)
      : files_(std::move(files)),
        frames_per_file_(frames_per_file),
        dtype_(options.dtype.value_or(Dtype::f32)),
        replace_nan_(options.replace_nan) {
    if (!options.dims)
      throw InputError(described +
                       " is raw: say the size of a frame with --dims XxYxZ (and --dtype if not "
                       "f32)");
    info_.dims = *options.dims;
    info_.frames = files_.size() * frames_per_file_;
    if (info_.frames == 0) throw InputError("--frames must be at least 1");
    // Every byte count below fits (voxels <= 2^48 from parse_dims): f64 frames of one file.
    if (static_cast<long double>(info_.dims.voxels()) * 8.0L *
            static_cast<long double>(frames_per_file_) >
        0x1p62L)
      throw InputError(described + ": " + std::to_string(frames_per_file_) + " frames of " +
                       to_string(info_.dims) + " voxels are more bytes than a file can hold");
    frame_bytes_ = info_.dims.voxels() * dtype_size(dtype_);
    for (const fs::path& file : files_) {
      std::error_code ec;
      const fs::file_type type = fs::status(file, ec).type();
      if (type != fs::file_type::regular)
        throw InputError("'" + file.string() + "' is " + format::detail::file_kind(type) +
                         ", expected a regular raw file");
      const auto size = fs::file_size(file, ec);
      if (ec) throw InputError("cannot read the size of '" + file.string() + "': " + ec.message());
      if (size == frame_bytes_ * frames_per_file_) continue;
      const std::string needs = "--dims " + to_string(info_.dims) + " --dtype " +
                                to_string(dtype_) +
                                (files_.size() == 1 ? " --frames " + std::to_string(info_.frames)
                                                    : std::string(" (one frame per file)")) +
                                " needs " + std::to_string(frame_bytes_ * frames_per_file_);
      throw InputError("'" + file.string() + "' is " + std::to_string(size) + " bytes, but " +
                       needs + size_hint(size));
    }
    for (std::size_t t = 0; t < info_.frames; ++t)
      info_.timestamps.push_back(static_cast<double>(t));
    info_.source = files_.size() == 1
                       ? "raw file " + files_.front().string() + " (" + to_string(dtype_) + ")"
                       : "raw files " + pattern + " (" + std::to_string(files_.size()) +
                             " files, " + to_string(dtype_) + ")";
  }

  void read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                 std::span<float> out) const override {
    check_slab(info_, t, z_begin, z_end, out.size());
    const fs::path& file = files_[t / frames_per_file_];
    const std::size_t within = t % frames_per_file_;
    const std::size_t plane_bytes = info_.dims.plane() * dtype_size(dtype_);
    std::vector<unsigned char> bytes(plane_bytes * (z_end - z_begin));
    read_exact(file, within * frame_bytes_ + z_begin * plane_bytes, bytes);
    convert_to_float(bytes.data(), dtype_, out);
    check_finite(out, info_.dims,
                 "'" + file.string() + "'" +
                     (frames_per_file_ > 1 ? " frame " + std::to_string(within) : std::string()),
                 replace_nan_, z_begin);
  }

 private:
  std::vector<fs::path> files_;
  std::size_t frames_per_file_ = 1;
  Dtype dtype_;
  std::size_t frame_bytes_ = 0;
  std::optional<float> replace_nan_;

  /// What a file of `size` bytes (not the size expected) could be instead, " (...)", or "".
  std::string size_hint(std::uintmax_t size) const {
    if (size == 0) return " (it is empty)";
    const std::uintmax_t voxels = info_.dims.voxels();
    std::vector<std::string> could;
    if (files_.size() == 1 && size % frame_bytes_ == 0)
      could.push_back("it holds " + std::to_string(size / frame_bytes_) +
                      " such frames: pass --frames " + std::to_string(size / frame_bytes_));
    for (const Dtype d : {Dtype::f32, Dtype::f64, Dtype::u8, Dtype::u16})
      if (d != dtype_ && size == voxels * dtype_size(d) * frames_per_file_)
        could.push_back("it is the size of --dtype " + to_string(d));
    if (could.empty() && files_.size() == 1)
      for (const Dtype d : {Dtype::f32, Dtype::f64, Dtype::u8, Dtype::u16})
        if (d != dtype_ && size % (voxels * dtype_size(d)) == 0)
          could.push_back("it holds " + std::to_string(size / (voxels * dtype_size(d))) +
                          " frames of --dtype " + to_string(d));
    std::string hint;
    for (const std::string& c : could) hint += (hint.empty() ? " (" : "; or ") + c;
    return hint.empty() ? hint : hint + ")";
  }
};

/// The end of the fraction digits after a run of digits ending at `i` ("2.5": the '5'), or `i`
/// when no '.' and digit follow.
std::size_t fraction_end(const std::string& s, std::size_t i) {
  if (i + 1 >= s.size() || s[i] != '.' || !std::isdigit(static_cast<unsigned char>(s[i + 1])))
    return i;
  ++i;
  while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i;
  return i;
}

/// Natural order: numbers compare by value ("p_2" before "p_10"), decimal fractions included
/// ("t_0.125" before "t_0.25" before "t_0.5" before "t_1": simulation times in file names), the
/// rest bytewise.
bool natural_less(const std::string& a, const std::string& b) {
  std::size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])) != 0;
    const bool db = std::isdigit(static_cast<unsigned char>(b[j])) != 0;
    if (da && db) {
      std::size_t ie = i, je = j;
      while (ie < a.size() && std::isdigit(static_cast<unsigned char>(a[ie]))) ++ie;
      while (je < b.size() && std::isdigit(static_cast<unsigned char>(b[je]))) ++je;
      // Without leading zeros, the longer run is the larger number.
      std::size_t is = i, js = j;
      while (is + 1 < ie && a[is] == '0') ++is;
      while (js + 1 < je && b[js] == '0') ++js;
      if (ie - is != je - js) return ie - is < je - js;
      const int c = a.compare(is, ie - is, b, js, je - js);
      if (c != 0) return c < 0;
      // The same whole number: the fractions digit by digit, a missing digit being 0.
      const std::size_t fa = fraction_end(a, ie), fb = fraction_end(b, je);
      const std::size_t la = fa > ie ? fa - ie - 1 : 0, lb = fb > je ? fb - je - 1 : 0;
      for (std::size_t k = 0; k < std::max(la, lb); ++k) {
        const char x = k < la ? a[ie + 1 + k] : '0', y = k < lb ? b[je + 1 + k] : '0';
        if (x != y) return x < y;
      }
      if (ie - i != je - j) return ie - i < je - j;  // "07" after "7"
      if (la != lb) return la < lb;                  // "0.5" before "0.50"
      i = fa;
      j = fb;
      continue;
    }
    if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
    ++i;
    ++j;
  }
  return a.size() - i < b.size() - j;
}

}  // namespace

bool is_glob(const std::string& text) {
  return text.find_first_of("*?[") != std::string::npos;
}

std::vector<fs::path> expand_glob(const std::string& pattern) {
  ::glob_t g{};
  const int rc = ::glob(pattern.c_str(), GLOB_ERR, nullptr, &g);
  std::vector<std::string> names;
  for (std::size_t i = 0; rc == 0 && i < g.gl_pathc; ++i) names.emplace_back(g.gl_pathv[i]);
  ::globfree(&g);
  if (rc == GLOB_NOMATCH)
    throw InputError("'" + pattern + "' matches no file (quote the pattern so that the shell " +
                     "leaves it to volreel)");
  if (rc != 0) throw InputError("'" + pattern + "': cannot list the files it names");
  std::sort(names.begin(), names.end(), natural_less);
  return {names.begin(), names.end()};
}

std::unique_ptr<SeriesReader> open_raw_series(const fs::path& dir, const OpenOptions& options) {
  return std::make_unique<RawSeriesReader>(dir, options);
}

std::unique_ptr<SeriesReader> open_raw_file(const fs::path& file, const OpenOptions& options) {
  return std::make_unique<RawFileReader>(std::vector<fs::path>{file}, options.frames.value_or(1),
                                         "", "'" + file.string() + "'", options);
}

std::unique_ptr<SeriesReader> open_raw_glob(const std::string& pattern,
                                            const OpenOptions& options) {
  if (options.frames && *options.frames != 1)
    throw InputError("'" + pattern +
                     "': a pattern reads one frame per file; --frames applies to a single file");
  std::vector<fs::path> files = expand_glob(pattern);
  const std::string described =
      "'" + pattern + "' (" + std::to_string(files.size()) + " files, " + files.front().string() +
      (files.size() > 1 ? " ... " + files.back().string() : std::string()) + ")";
  return std::make_unique<RawFileReader>(std::move(files), 1, pattern, described, options);
}

}  // namespace volreel::datasets::detail
