// cmd_bench_codes.cpp: `volreel bench codes NAME.vreel` — where a ksvd container's brick bytes
// go, level by level (headers, block entries, atom gaps, magnitudes, signs), and how far the
// Rice codes of the gaps and magnitudes are from the empirical conditional entropy of the same
// values in simple contexts (format/code_statistics.hpp): the most a better entropy coder of the
// same codes could save.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "commands.hpp"
#include "progress.hpp"
#include "volreel/format/code_statistics.hpp"
#include "volreel/format/container.hpp"

namespace volreel::cli {

namespace {

struct BenchCodesOptions {
  std::string container;
  std::size_t frames = 0;
};

double share(std::uint64_t part, std::uint64_t whole) {
  return whole > 0 ? 100.0 * static_cast<double>(part) / static_cast<double>(whole) : 0.0;
}
double per(std::uint64_t part, std::uint64_t count) {
  return count > 0 ? static_cast<double>(part) / static_cast<double>(count) : 0.0;
}

void print_row(const char* name, const format::CodeStatistics& s) {
  const double gap_bound = s.gaps.entropy_bits(), magnitude_bound = s.magnitudes.entropy_bits();
  const double saved =
      static_cast<double>(s.gap_bits + s.magnitude_bits) - gap_bound - magnitude_bound;
  std::printf(
      "%-7s %7llu %9.1f %8.1f %8.1f %8.1f | %6.2f %6.2f %6.2f %6.2f %7.3f | %6.2f %6.2f | "
      "%7.1f %7.1f\n",
      name, static_cast<unsigned long long>(s.bricks), per(s.codes, s.blocks),
      share(s.header_bits, s.payload_bits), share(s.entry_bits, s.payload_bits),
      share(s.code_bits, s.payload_bits), per(s.code_bits, s.codes), per(s.gap_bits, s.codes),
      per(s.magnitude_bits, s.codes), per(s.sign_bits, s.codes), 100.0 * per(s.escapes, s.codes),
      s.codes > 0 ? gap_bound / static_cast<double>(s.codes) : 0.0,
      s.codes > 0 ? magnitude_bound / static_cast<double>(s.codes) : 0.0,
      s.code_bits > 0 ? 100.0 * saved / static_cast<double>(s.code_bits) : 0.0,
      s.payload_bits > 0 ? 100.0 * saved / static_cast<double>(s.payload_bits) : 0.0);
}

void run_bench_codes(const BenchCodesOptions& o) {
  const format::Container container(o.container);
  const format::Manifest& m = container.manifest();
  if (m.codec != format::Codec::ksvd)
    throw InputError(o.container + ": bench codes reads ksvd containers; this one is coded by zfp");
  const std::size_t frames =
      o.frames == 0 ? container.frame_count() : std::min(o.frames, container.frame_count());
  std::vector<format::CodeStatistics> levels;
  std::uint64_t constant_bricks = 0;
  ProgressBar bar("reading codes", "frames");
  for (std::size_t t = 0; t < frames; ++t) {
    const format::FrameFile file = container.open_frame(t);
    const format::FrameView& view = file.view();
    if (levels.size() < view.level_count()) levels.resize(view.level_count());
    for (std::uint32_t node = 0; node < view.node_count(); ++node) {
      if (!view.has_brick(node)) continue;
      const std::uint32_t brick = view.node(node).brick;
      const std::vector<std::byte> payload = container.read_brick(view, brick);
      if (payload.size() == 4) {
        ++constant_bricks;
        continue;
      }
      levels[view.position(node).level].add(payload, container.atoms().count, view.shape(),
                                            view.name(), 0);
    }
    bar.update({static_cast<double>(t + 1), static_cast<double>(frames), {}});
  }
  bar.finish();
  std::printf(
      "input:   %s: %ux%ux%u, %zu of %zu frames, bricks of %u^3, %zu atoms; %llu constant "
      "bricks not counted\n",
      o.container.c_str(), m.dims[0], m.dims[1], m.dims[2], frames, container.frame_count(),
      m.brick_size, static_cast<std::size_t>(container.atoms().count),
      static_cast<unsigned long long>(constant_bricks));
  std::printf(
      "                                payload share (%%) |         bits per code             "
      "   | entropy bound   | could save (%%)\n"
      "level    bricks codes/blk  headers  entries    codes |  total    gap    mag   sign escape%% "
      "|    gap    mag |   codes payload\n");
  format::CodeStatistics all;
  for (std::size_t l = 0; l < levels.size(); ++l) {
    print_row(std::to_string(l).c_str(), levels[l]);
    all.merge(levels[l]);
  }
  print_row("all", all);
  std::printf(
      "Entropy bound: the empirical conditional entropy of the atom gaps given (floor(log2(s+1)), "
      "floor(log2(previous atom+2))) and of the magnitudes given (atom band, floor(log2(s+1))), "
      "s the block's codes: the fewest bits a static code per context could spend on them, its "
      "tables not counted. 'could save': the Rice codes' excess over it, of the code bits and of "
      "the payload bits. Level 0 is the root; the finest level is the last.\n");
}

}  // namespace

void add_bench_codes_command(CLI::App& bench) {
  auto o = std::make_shared<BenchCodesOptions>();
  CLI::App* cmd = bench.add_subcommand(
      "codes",
      "Where a ksvd container's brick bytes go, level by level: headers, block entries and the\n"
      "code stream, its bits per code split into atom gap, magnitude and sign, the share of\n"
      "escapes, and the entropy bound of the gaps and magnitudes in simple contexts: the most a\n"
      "better entropy coder of the same codes could save.");
  cmd->add_option("CONTAINER", o->container, "Container directory NAME.vreel")->required();
  cmd->add_option("--frames", o->frames, "Read the first N frames (0: all)")->capture_default_str();
  cmd->callback([o] { run_bench_codes(*o); });
}

}  // namespace volreel::cli
