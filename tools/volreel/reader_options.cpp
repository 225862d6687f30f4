// reader_options.cpp: the command-line options that describe how to read a series, and the
// parsing of option values shared by several commands.
#include <cmath>
#include <cstdlib>

#include "commands.hpp"

namespace volreel::cli {

std::optional<double> positive_number(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(v) || !(v > 0))
    return std::nullopt;
  return v;
}

void ReaderOptions::add_to(CLI::App& command) {
  command.add_option("--dims", dims, "Raw file: volume size XxYxZ (x fastest), e.g. 256x256x128");
  command.add_option("--dtype", dtype, "Raw file: f32 (default), f64, u8 or u16, little-endian");
  command.add_option("--frames", frames, "Raw file: frames stored back to back (default 1)");
  command.add_option("--dataset", dataset,
                     "HDF5: a 4D dataset [t][z][y][x], or one 3D dataset per step by pattern: "
                     "'Pressure_####' (# = a digit) or 'Pressure_*'");
  command
      .add_option("--replace-nan", replace_nan,
                  "Substitute NaN/Inf values with this value instead of refusing the input")
      ->each([this](const std::string&) { replace_nan_set = true; });
}

datasets::OpenOptions ReaderOptions::to_open_options() const {
  datasets::OpenOptions o;
  if (!dims.empty()) o.dims = parse_dims(dims);
  if (!dtype.empty()) o.dtype = datasets::parse_dtype(dtype);
  if (frames) o.frames = frames;
  o.dataset = dataset;
  if (replace_nan_set) o.replace_nan = static_cast<float>(replace_nan);
  return o;
}

}  // namespace volreel::cli
