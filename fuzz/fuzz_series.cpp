// fuzz_series.cpp: series.json of a raw series directory (written to a directory of this process,
// next to two small frame files) opened as `volreel encode` opens it, and its first frame read.
// Every outcome is an InputError or a valid series.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "volreel/datasets/series.hpp"

namespace fs = std::filesystem;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const fs::path dir = [] {
    const fs::path d =
        fs::temp_directory_path() / ("volreel-fuzz-series-" + std::to_string(getpid()));
    fs::create_directories(d);
    const std::vector<float> frame(8, 1.5f);
    for (const char* name : {"000000.f32", "000001.f32"})
      std::ofstream(d / name, std::ios::binary)
          .write(reinterpret_cast<const char*>(frame.data()), 32);
    return d;
  }();
  std::ofstream(dir / "series.json", std::ios::binary)
      .write(reinterpret_cast<const char*>(data), static_cast<std::streamsize>(size));
  try {
    const auto series = volreel::datasets::open_series(dir);
    if (series->info().dims.voxels() <= 4096) series->read_frame(0);
  } catch (const volreel::InputError&) {
  }
  return 0;
}
