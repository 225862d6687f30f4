// cmd_decode.cpp: `volreel decode` — one frame at any level -> a raw float32 file, by the CPU
// reference decoder (format/decoder.hpp), timed as the best of --repeat runs.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>
#include <string>

#include "commands.hpp"
#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel::cli {

namespace {

using Clock = std::chrono::steady_clock;

struct DecodeOptions {
  std::string dir, out;
  std::size_t frame = 0;
  int level = -1;
  int repeat = 1;
};

namespace fs = std::filesystem;

void run_decode(const DecodeOptions& o) {
  // The output: a regular file (a link to one is written through), a new name, or a character
  // device such as /dev/null; a FIFO would block the write until a reader comes.
  std::error_code ec;
  const fs::file_status status = fs::status(o.out, ec);
  const bool device = fs::is_character_file(status);
  if (fs::exists(status) && !fs::is_regular_file(status) && !device)
    throw InputError("--out '" + o.out + "' is " + format::detail::file_kind(status.type()) +
                     ": expected a regular file, a new name or a character device");
  const fs::path out = fs::exists(status) ? fs::canonical(o.out, ec) : fs::path(o.out);
  if (!device) format::detail::check_writable(out, "--out");
  if (datasets::input_includes(o.dir, out))
    throw InputError("--out '" + o.out + "' is a file of the container '" + o.dir +
                     "': decoding would write over it; choose another --out");
  const format::Container c(o.dir);
  format::TimeStepDecoder steps(c);
  if (o.frame >= c.frame_count())
    throw InputError("--frame " + std::to_string(o.frame) + ": the container has frames 0.." +
                     std::to_string(c.frame_count() - 1));
  const format::FrameView& f = steps.frame(o.frame);
  const std::uint32_t levels = f.level_count();
  const std::int64_t wanted = o.level < 0 ? std::int64_t{levels} + o.level : o.level;
  if (wanted < 0 || wanted >= std::int64_t{levels})
    throw InputError("--level " + std::to_string(o.level) + ": the frame has levels 0.." +
                     std::to_string(levels - 1) + " (negative levels count from the finest, -1)");
  const auto level = static_cast<std::uint32_t>(wanted);
  format::LevelVolume v;
  const auto& e = f.level(level);
  v.dims = {e.dims[0], e.dims[1], e.dims[2]};
  v.data.resize(std::size_t{e.dims[0]} * e.dims[1] * e.dims[2]);
  // Timed: decoding into the allocated volume, the best of --repeat runs.
  double seconds = 1e30;
  for (int r = 0; r < std::max(1, o.repeat); ++r) {
    const auto start = Clock::now();
    steps.decode(o.frame, level, v.data);
    seconds = std::min(seconds, std::chrono::duration<double>(Clock::now() - start).count());
  }
  const auto bytes = std::as_bytes(std::span<const float>(v.data.data(), v.data.size()));
  if (device) {
    std::ofstream stream(out, std::ios::binary);
    stream.write(reinterpret_cast<const char*>(bytes.data()),
                 static_cast<std::streamsize>(bytes.size()));
    if (!stream) throw InputError("cannot write '" + o.out + "'");
  } else {
    format::detail::write_file_atomically(out, bytes);
  }
  std::printf(
      "wrote %s: frame %zu level %u, %ux%ux%u float32 (x fastest); decoded in %.4f s (%.1f "
      "MVoxel/s of output; best of %d, %d threads)\n",
      o.out.c_str(), o.frame, level, v.dims[0], v.dims[1], v.dims[2], seconds,
      static_cast<double>(v.data.size()) / 1e6 / seconds, std::max(1, o.repeat),
      omp_get_max_threads());
}

}  // namespace

void add_decode_command(CLI::App& app) {
  auto d = std::make_shared<DecodeOptions>();
  CLI::App* decode = app.add_subcommand(
      "decode",
      "Decode one frame at one level with the CPU reference decoder into a raw float32 file");
  decode->add_option("CONTAINER", d->dir, "NAME.vreel directory")->required();
  decode->add_option("--frame", d->frame, "Time step")
      ->check(non_negative())
      ->capture_default_str();
  decode->add_option("--level", d->level,
                     "Octree level: 0 = root (one brick) ... levels-1 = full resolution; negative "
                     "from the finest: -1 (the default) full resolution, -2 the level above, ...");
  decode->add_option("--out", d->out, "Output .f32 file")->required();
  decode
      ->add_option("--repeat", d->repeat,
                   "Decode this many times and report the fastest (a benchmark)")
      ->check(CLI::Range(1, 1000000))
      ->capture_default_str();
  decode->callback([d] { run_decode(*d); });
}

}  // namespace volreel::cli
