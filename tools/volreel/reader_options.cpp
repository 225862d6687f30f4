// reader_options.cpp: the command-line options that describe how to read a series, and the
// parsing of option values shared by several commands.
#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "commands.hpp"
#include "volreel/encoder/series_encoder.hpp"

namespace volreel::cli {

namespace {

/// The whole of text as a finite number, or std::nullopt.
std::optional<double> finite_number(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

}  // namespace

std::optional<double> positive_number(const std::string& text) {
  const std::optional<double> v = finite_number(text);
  return v && *v > 0 ? v : std::nullopt;
}

void refuse_unknown_command(const CLI::App& app, int argc, const char* const* argv) {
  const CLI::App* at = &app;
  std::string path = "volreel";
  for (int i = 1; i < argc; ++i) {
    const std::string word = argv[i];
    if (word.empty() || word[0] == '-') return;  // options: CLI11's to judge
    const std::vector<const CLI::App*> commands = at->get_subcommands({});
    if (commands.empty() || at->get_require_subcommand_min() == 0) return;
    const auto found = std::find_if(commands.begin(), commands.end(),
                                    [&](const CLI::App* c) { return c->check_name(word); });
    if (found == commands.end()) {
      std::string names;
      for (const CLI::App* c : commands) names += (names.empty() ? "" : ", ") + c->get_name();
      throw InputError("'" + word + "' is not a command of " + path + " (its commands: " + names +
                       "); run " + path + " --help");
    }
    at = *found;
    path += " " + at->get_name();
  }
}

CLI::Validator positive() {
  return CLI::Validator(
      [](const std::string& text) {
        return positive_number(text) ? std::string()
                                     : "expected a number > 0, found '" + text + "'";
      },
      "POSITIVE");
}

CLI::Validator non_negative() {
  return CLI::Validator(
      [](const std::string& text) {
        const std::optional<double> v = finite_number(text);
        return v && *v >= 0 ? std::string() : "expected a number >= 0, found '" + text + "'";
      },
      "NONNEGATIVE");
}

CLI::Validator in_range(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](const std::string& text) {
        const std::optional<double> v = finite_number(text);
        if (v && *v >= lo && *v <= hi) return std::string();
        char range[96];
        std::snprintf(range, sizeof range, "[%g, %g]", lo, hi);
        return "expected a number in " + std::string(range) + ", found '" + text + "'";
      },
      "RANGE");
}

CLI::Validator seed_number() {
  return CLI::Validator(
      [](const std::string& text) {
        std::uint64_t value = 0;
        const char* end = text.data() + text.size();
        const auto [ptr, ec] = std::from_chars(text.data(), end, value);
        return !text.empty() && text[0] != '-' && text[0] != '+' && ec == std::errc{} && ptr == end
                   ? std::string()
                   : "expected a seed, a whole number 0 .. 18446744073709551615, found '" + text +
                         "'";
      },
      "SEED");
}

const char* const series_inputs_help = R"(Series (SERIES):
  DIR or DIR/series.json  a raw series directory: series.json and one float32 file per frame
  FILE --dims XxYxZ       a raw file ([--dtype f32|f64|u8|u16] [--frames T back to back])
  'PATTERN' --dims XxYxZ  raw files a glob matches (*, ?, [...]; quote it), one frame each,
                          in natural order (p_2 before p_10)
  FILE.h5 --dataset NAME  HDF5: a 4D dataset [t][z][y][x], or 3D datasets by pattern
  FILE.nc [--variable V]  NetCDF: a variable (time, z, y, x) or (z, y, x), x the last; spacing
                          and times from CF coordinate variables, scale_factor/add_offset
                          applied, _FillValue/missing_value refused unless --replace-nan
  (an option of another kind of input is refused, not ignored)

series.json (every key required unless marked optional):
  "format": "volreel-raw-series"    "version": 1
  "dims": [x, y, z]                 "dtype": "f32" (little-endian, x fastest, no header)
  "frames": ["000000.f32", ...]     file names relative to the directory
  "timestamps": [t0, t1, ...]       one increasing number per frame
  "spacing": [sx, sy, sz]           optional, default [1, 1, 1]
  "variable": "pressure"            optional
  "generator": {...}                optional: how the series was made (kept, not read))";

void ReaderOptions::add_to(CLI::App& command) {
  command.footer(series_inputs_help);
  command.add_option("--dims", dims,
                     "Raw file or pattern: volume size XxYxZ (x fastest), e.g. 256x256x128");
  command.add_option("--dtype", dtype,
                     "Raw file or pattern: f32 (default), f64, u8 or u16, little-endian");
  command.add_option("--frames", frames, "Raw file: frames stored back to back (default 1)")
      ->check(in_range(1, 1e8));
  command.add_option("--dataset", dataset,
                     "HDF5: a 4D dataset [t][z][y][x], or one 3D dataset per step by pattern: "
                     "'Pressure_####' (# = a digit) or 'Pressure_*'");
  command.add_option("--variable", variable,
                     "NetCDF: the variable to read (default: the only one of 3 or 4 dimensions)");
  command.add_option("--time-dim", time_dimension,
                     "NetCDF: the time dimension (default: the unlimited one, or one named time "
                     "or t)");
  command
      .add_option("--replace-nan", replace_nan,
                  "Substitute NaN/Inf values with this value instead of refusing the input")
      ->check(CLI::Validator(
          [](const std::string& text) {
            const std::optional<double> v = finite_number(text);
            return v && std::abs(*v) <= encoder::max_input_magnitude
                       ? std::string()
                       : "expected a finite number of magnitude at most 1e33 (the largest "
                         "volreel encodes), found '" +
                             text + "'";
          },
          "FINITE"))
      ->each([this](const std::string&) { replace_nan_set = true; });
}

namespace {

/// "SX,SY,SZ" as three positive finite numbers, or std::nullopt.
std::optional<std::array<double, 3>> parse_spacing(const std::string& text) {
  std::array<double, 3> spacing{};
  std::size_t start = 0;
  for (std::size_t a = 0; a < 3; ++a) {
    const std::size_t comma = a < 2 ? text.find(',', start) : text.size();
    if (comma == std::string::npos) return std::nullopt;
    const std::optional<double> v = positive_number(text.substr(start, comma - start));
    if (!v) return std::nullopt;
    spacing[a] = *v;
    start = comma + 1;
  }
  return spacing;
}

}  // namespace

void ReaderOptions::add_spacing_to(CLI::App& command) {
  command
      .add_option("--spacing", spacing,
                  "Voxel spacing SX,SY,SZ (e.g. 1,1,4 for planes four times as far apart as "
                  "voxels along x), stored in the container\nfor readers such as ParaView; "
                  "replaces series.json's or NetCDF's (default: theirs, else 1,1,1)")
      ->check(CLI::Validator(
          [](const std::string& text) {
            return parse_spacing(text)
                       ? std::string()
                       : "expected three positive numbers SX,SY,SZ, found '" + text + "'";
          },
          "SX,SY,SZ"));
}

std::string ReaderOptions::given() const {
  std::string names;
  const auto add = [&](bool set, const char* name) {
    if (set) names += (names.empty() ? "" : ", ") + std::string(name);
  };
  add(!dims.empty(), "--dims");
  add(!dtype.empty(), "--dtype");
  add(frames != 0, "--frames");
  add(!dataset.empty(), "--dataset");
  add(!variable.empty(), "--variable");
  add(!time_dimension.empty(), "--time-dim");
  add(replace_nan_set, "--replace-nan");
  return names;
}

datasets::OpenOptions ReaderOptions::to_open_options() const {
  datasets::OpenOptions o;
  if (!dims.empty()) o.dims = parse_dims(dims);
  if (!dtype.empty()) o.dtype = datasets::parse_dtype(dtype);
  if (frames) o.frames = frames;
  o.dataset = dataset;
  o.variable = variable;
  o.time_dimension = time_dimension;
  if (replace_nan_set) o.replace_nan = static_cast<float>(replace_nan);
  if (!spacing.empty()) o.spacing = parse_spacing(spacing);
  return o;
}

}  // namespace volreel::cli
