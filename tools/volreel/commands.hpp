// commands.hpp: the subcommands of the volreel program.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "volreel/datasets/series.hpp"

namespace volreel::cli {

/// The exit status of a command that wrote complete, valid output but missed a target asked of it
/// (encode's --psnr, --bps, --max-error), so that a script tells it from a failure (1).
inline constexpr int target_missed_status = 3;
/// Thrown by such a command after its output is written; main prints it and exits with
/// target_missed_status.
struct TargetMissed : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void add_gen_command(CLI::App& app);
void add_compare_command(CLI::App& app);
void add_bench_command(CLI::App& app);
void add_train_command(CLI::App& app);
/// `encode` (cmd_encode.cpp): a series into a NAME.vreel container.
void add_encode_command(CLI::App& app);
/// `info` (cmd_info.cpp): describe a container.
void add_info_command(CLI::App& app);
/// `verify` (cmd_verify.cpp): check a container's CRCs and structure.
void add_verify_command(CLI::App& app);
/// `decode` (cmd_decode.cpp): one frame at one level into a raw float32 file.
void add_decode_command(CLI::App& app);
/// `bench train` (cmd_bench_train.cpp), registered by add_bench_command under `bench`.
void add_bench_train_command(CLI::App& bench);
/// `bench decode` (cmd_bench_decode.cpp; needs the player's Vulkan decoder).
void add_bench_decode_command(CLI::App& bench);
/// `bench codes` (cmd_bench_codes.cpp): where a ksvd container's code bits go.
void add_bench_codes_command(CLI::App& bench);
/// `bench stream` (cmd_bench_stream.cpp; the stream scheduler and the CPU renderer).
void add_bench_stream_command(CLI::App& bench);
/// `bench index` (cmd_bench_index.cpp; the stream scheduler at scale, no renderer).
void add_bench_index_command(CLI::App& bench);
/// `play` (cmd_play.cpp; needs the player: a window, Vulkan, ImGui).
void add_play_command(CLI::App& app);
/// `render` (cmd_render.cpp; headless tours on the player's Vulkan renderer or the CPU).
void add_render_command(CLI::App& app);
/// `bench play` (cmd_bench_play.cpp; needs the player's Vulkan renderer).
void add_bench_play_command(CLI::App& bench);

/// The whole of text as a finite number > 0, or std::nullopt (empty, trailing characters, NaN,
/// infinite, zero or negative): for options CLI11's own checks let NaN through.
std::optional<double> positive_number(const std::string& text);
/// Option checks with plain messages ("expected a number > 0, found '0'"), for options CLI11's
/// PositiveNumber and NonNegativeNumber would check (they name a 309-digit bound and let NaN
/// through).
CLI::Validator positive();
CLI::Validator non_negative();
/// A seed: a whole number 0 .. 2^64 − 1 written in digits alone (CLI11 wraps "-1" to 2^64 − 1).
CLI::Validator seed_number();
/// A finite number in [lo, hi] ("expected a number in [1, 1000], found 'nan'"): CLI11's Range
/// lets NaN through, and for unsigned options "-1" wraps before it is checked.
CLI::Validator in_range(double lo, double hi);

/// Throws InputError naming the word when the command line's first word that is not an option,
/// or the next one under a command that takes subcommands (`volreel bench`, `volreel gen`), is
/// no command ("volreel encod ..."); CLI11 alone would only say that a command is required.
void refuse_unknown_command(const CLI::App& app, int argc, const char* const* argv);

/// Options that say how to read a series whose file does not describe itself; shared by every
/// command that reads one.
struct ReaderOptions {
  std::string dims, dtype, dataset, variable, time_dimension, spacing;
  std::size_t frames = 0;
  double replace_nan = 0;
  bool replace_nan_set = false;
  void add_to(CLI::App& command);
  /// --spacing SX,SY,SZ, for a command that writes what it reads (encode).
  void add_spacing_to(CLI::App& command);
  datasets::OpenOptions to_open_options() const;
  /// The options given, as "--dims, --frames" (empty: none).
  std::string given() const;
};

/// "CPU model, N cores; build type; volreel version" for benchmark headers.
std::string describe_machine();

/// The largest resident set this process has had (VmHWM), in bytes; 0 where /proc cannot say.
std::uint64_t peak_resident_bytes();

}  // namespace volreel::cli
