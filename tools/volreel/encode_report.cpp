// encode_report.cpp: what `volreel encode` prints about its tolerance and its result.
#include "encode_report.hpp"

#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>

#include "volreel/encoder/tolerance.hpp"
#include "volreel/format/brick_decode.h"

namespace volreel::cli {

namespace {

/// Where the frame files' bytes went, and the atoms per block (ksvd).
void print_breakdown(const encoder::EncodeSummary& s) {
  const encoder::ByteBreakdown& b = s.breakdown;
  const double total = static_cast<double>(b.total());
  if (!(total > 0)) return;
  const auto share = [&](double bytes) { return 100.0 * bytes / total; };
  std::printf("frame bytes (%zu frames encoded): ", s.encoded);
  const std::pair<const char*, std::size_t> parts[] = {{"frame tables", b.frame_tables},
                                                       {"constant bricks", b.constant_bricks},
                                                       {"brick headers", b.brick_headers},
                                                       {"block means+counts", b.block_entries},
                                                       {"codes", b.codes},
                                                       {"alignment", b.alignment},
                                                       {"zfp streams", b.zfp_streams}};
  bool first = true;
  for (const auto& [name, bytes] : parts) {
    if (bytes == 0) continue;
    std::printf("%s%s %.1f%%", first ? "" : ", ", name, share(static_cast<double>(bytes)));
    first = false;
  }
  std::printf("; coarse levels %.1f%%, aprons and padding about %.1f%% (of all frame bytes)\n",
              share(static_cast<double>(b.coarse_levels)), share(b.aprons_and_padding));
  if (b.codes > 0) {
    std::printf(
        "codes of the finest level's own voxels (interior, inside the volume): %.1f%% of the frame "
        "bytes",
        share(b.finest_owned_codes));
    if (const auto bps = s.finest_owned_codes_bps()) std::printf(", %.4f bps", *bps);
    std::printf("\n");
  }
  std::size_t blocks = 0, codes = 0, most = 0;
  for (std::size_t k = 0; k < s.sparsity_histogram.size(); ++k) {
    blocks += s.sparsity_histogram[k], codes += k * s.sparsity_histogram[k];
    if (s.sparsity_histogram[k] > 0) most = k;
  }
  if (blocks == 0) return;
  std::printf(
      "atoms per block: mean %.2f, most %zu; blocks with 0, 1-3, 4-7, 8-15, 16-31, 32-63, "
      "64+ atoms (%%):",
      static_cast<double>(codes) / static_cast<double>(blocks), most);
  for (std::size_t lo : {0u, 1u, 4u, 8u, 16u, 32u, 64u}) {
    const std::size_t hi = lo == 0    ? 1
                           : lo == 1  ? 4
                           : lo == 64 ? s.sparsity_histogram.size()
                                      : 2 * lo;
    std::size_t count = 0;
    for (std::size_t k = lo; k < hi; ++k) count += s.sparsity_histogram[k];
    std::printf(" %.1f", 100.0 * static_cast<double>(count) / static_cast<double>(blocks));
  }
  std::size_t coded_bricks = 0, coef_bits = 0;
  for (std::size_t k = 0; k < s.coef_bits_histogram.size(); ++k)
    coded_bricks += s.coef_bits_histogram[k], coef_bits += k * s.coef_bits_histogram[k];
  std::printf(
      "\nbits per code (atom gap, magnitude and sign): mean %.2f; magnitude bits per brick: mean "
      "%.2f",
      static_cast<double>(s.code_bits) / static_cast<double>(std::max<std::size_t>(codes, 1)),
      static_cast<double>(coef_bits) / static_cast<double>(std::max<std::size_t>(coded_bricks, 1)));
  std::size_t bricks = 0, bits = 0;
  for (std::size_t k = 0; k < s.mean_bits_histogram.size(); ++k)
    bricks += s.mean_bits_histogram[k], bits += k * s.mean_bits_histogram[k];
  const double brick_count = static_cast<double>(std::max<std::size_t>(bricks, 1));
  std::printf("\nmean bits per brick: mean %.2f; bricks with 0..%zu bits (%%):",
              static_cast<double>(bits) / brick_count, s.mean_bits_histogram.size() - 1);
  for (std::size_t count : s.mean_bits_histogram)
    std::printf(" %.1f", 100.0 * static_cast<double>(count) / brick_count);
  if (s.split_bricks > 0)
    std::printf(
        "\ncoded with the DCT basis alone (the learned atoms did not pay): %zu of %zu bricks",
        s.split_bricks, bricks);
  if (s.split_bricks > 0 && s.split_bricks == bricks)
    std::printf(
        "\nnote: no brick used the dictionary's learned atoms, which the container stores all the "
        "same: --dictionary dct leaves them out");
  std::printf("\n");
}

}  // namespace

void print_tolerance_choice(const encoder::ToleranceChoice& e, const encoder::CodingSettings& c,
                            double target_bps, double range, std::uint32_t atoms) {
  using Source = encoder::ToleranceSource;
  if (e.source == Source::fixed_rate)
    std::printf("fixed rate: %d atoms per block\n", c.fixed_sparsity);
  if (e.source == Source::bps)
    std::printf(
        "rate control: eps %.4g gives an estimated %.4f bps (target %.4f) after %d trial encodes "
        "of %zu frames\n",
        e.rate_search.tolerance, e.rate_search.estimated_bps, target_bps, e.rate_search.iterations,
        e.rate_search.sample_frames);
  if (e.source == Source::bps && !c.learned_pursuit)
    std::printf(
        "learned atoms: kept in none of the %zu bricks of those frames at this eps; every brick "
        "is coded with the DCT basis alone (the whole dictionary's pursuit skipped)\n",
        e.rate_search.sample_bricks);
  if (e.source == Source::dictionary_training)
    std::printf("tolerance from the dictionary's training: ");
  if (c.fixed_sparsity == 0 && c.rule == encoder::VariableRateRule::tolerance)
    std::printf(
        "tolerance eps %.4g, eps rule (PSNR >= %.2f dB before quantization if every block meets "
        "it), K = %u\n",
        c.tolerance, dictionary::psnr_for_tolerance(c.tolerance, range), atoms);
  else if (c.fixed_sparsity == 0)
    std::printf(
        "tolerance eps %.4g, Lagrangian rule: a block keeps an atom if it lowers its squared "
        "error by >= %.3g (%g*216*eps^2; 20*log10(range/eps) = %.2f dB, not a prediction: the "
        "delivered PSNR is measured below), K = %u\n",
        c.tolerance, c.lagrangian_factor * 216 * c.tolerance * c.tolerance, c.lagrangian_factor,
        dictionary::psnr_for_tolerance(c.tolerance, range), atoms);
}

bool print_encode_summary(const encoder::EncodeSummary& s, const encoder::CodingSettings& c,
                          const std::string& out, double psnr_target, double bps_target) {
  const encoder::MissedTargets missed = encoder::missed_targets(s, psnr_target, bps_target);
  if (c.max_error > 0) {
    if (!missed.max_error)
      std::printf("pointwise bound: every coded block within %.4g of the original\n", c.max_error);
    else
      std::fprintf(stderr,
                   "warning: %zu blocks miss the pointwise bound %.4g even at the finest steps a "
                   "payload holds (coefficients to 2^-%u of the brick's largest, block means to "
                   "%u bits): volreel compare prints the largest error; for a bound this tight "
                   "against the values, --codec zfp --zfp-accuracy %.4g holds it\n",
                   s.blocks_over_bound, c.max_error, VR_MAX_COEF_BITS, VR_MEAN_BITS, c.max_error);
  }
  // Frames side by side: each frame's parts, summed, against the threads' seconds.
  const double parts = s.seconds_pyramid + s.seconds_bricks + s.seconds_omp + s.seconds_quantize;
  const std::string at_once = s.frames_at_once > 1
                                  ? " (" + std::to_string(s.frames_at_once) +
                                        " frames at once, side by side: each frame's parts summed)"
                                  : "";
  std::printf(
      "encoding time%s%s: pyramid %.2f s, brick extraction + histograms %.2f s, batch-OMP %.2f s, "
      "quantization %.2f s, other (reading excluded%s) %.2f s\n",
      s.processes > 1 ? " (summed over the processes)" : "", at_once.c_str(), s.seconds_pyramid,
      s.seconds_bricks, s.seconds_omp, s.seconds_quantize,
      s.frames_at_once > 1 ? ", idle threads included" : "",
      std::max(0.0, s.process_seconds * static_cast<double>(s.frames_at_once) - parts));
  // A loss below 0: the quantized codes lie closer to the data than the approximation they were
  // quantized from (the refit, or bricks coded again with a finer step under --max-error).
  if (s.unquantized_squared_error > 0)
    std::printf(
        "quantization: %.3f dB %s the unquantized sparse approximation (squared error over all "
        "coded blocks, every level; refit %s, pursuit extension %s)\n",
        std::abs(s.quantization_loss_db()),
        s.quantization_loss_db() >= 0 ? "lost against" : "gained over",
        c.refit_quantization ? "on" : "off",
        c.extend_pursuit && c.fixed_sparsity == 0 && c.rule == encoder::VariableRateRule::tolerance
            ? "on"
            : "off");
  print_breakdown(s);
  std::printf(
      "wrote %s: %zu frames (%zu encoded, %zu already there), %ju bytes, %.4f bps; encoding %.1f "
      "s, %.2f MVoxel/s on %s%d threads%s\n",
      out.c_str(), s.frames, s.encoded, s.skipped, static_cast<std::uintmax_t>(s.container_bytes),
      s.bps, s.seconds, s.mvoxels_per_s,
      s.processes > 1 ? (std::to_string(s.processes) + " processes x ").c_str() : "",
      omp_get_max_threads(),
      s.team_size > 1
          ? (", each frame coded by " + std::to_string(s.team_size) + " processes together").c_str()
          : "");
  if (missed.bps) {
    const bool under = s.bps < bps_target;
    std::fflush(stdout);
    // The search's smallest eps asks for more precision than the payload's fields hold (a
    // brick's coefficients to 2^-16 of its largest, block means to 2^-15 of their span): no eps
    // spends more.
    if (under && c.tolerance <= 1e-7 * (c.value_max - c.value_min))
      std::fprintf(stderr,
                   "warning: target %.4f bps missed: the container is %.4f bps (%+.1f %%) at eps "
                   "%.4g, where every brick is coded as finely as the format allows (coefficients "
                   "to 2^-%u of the brick's largest, block means to %u bits); no tolerance makes "
                   "it larger: ask for fewer bps\n",
                   bps_target, s.bps, 100.0 * (s.bps / bps_target - 1), c.tolerance,
                   VR_MAX_COEF_BITS, VR_MEAN_BITS);
    else if (!under && c.tolerance >= 0.999 * encoder::tolerance_range(c.value_min, c.value_max))
      // The search's largest eps, the value range: every block holds little more than its mean.
      std::fprintf(stderr,
                   "warning: target %.4f bps missed: the container is %.4f bps (%+.1f %%) at eps "
                   "%.4g, the value range, where blocks keep little more than their means; no "
                   "tolerance makes it smaller: ask for more bps\n",
                   bps_target, s.bps, 100.0 * (s.bps / bps_target - 1), c.tolerance);
    else
      std::fprintf(stderr,
                   "warning: target %.4f bps missed: the container is %.4f bps (%+.1f %%) at eps "
                   "%.4g; the rate search's sample frames cost %s than the sequence's average: "
                   "encode again with a larger --rate-sample-frames, or with a %s --tolerance\n",
                   bps_target, s.bps, 100.0 * (s.bps / bps_target - 1), c.tolerance,
                   under ? "more" : "less", under ? "smaller" : "larger");
  }
  const std::size_t node_steps = s.bricks_stored + s.nodes_interpolated;
  if (s.nodes_interpolated > 0)
    std::printf(
        "keyframes: %zu of %zu node-steps store a brick (%.1f %%); the other %zu are drawn by "
        "interpolating their node's keyframes\n",
        s.bricks_stored, node_steps,
        100.0 * static_cast<double>(s.bricks_stored) / static_cast<double>(node_steps),
        s.nodes_interpolated);
  const encoder::DeliveredQuality& q = s.delivered;
  if (q.frames == 0) return missed.any();
  const double range = c.value_max - c.value_min;
  std::printf(
      "delivered (finest level of the %zu time steps encoded, decoded as the player draws them and "
      "compared): PSNR %.2f dB over "
      "the sequence, worst frame %zu at %.2f dB, largest error %.4g\n",
      q.frames, q.sequence_psnr(range), q.worst_frame, q.worst_frame_psnr, q.max_abs_error);
  if (psnr_target > 0 && c.codec == format::Codec::ksvd && c.fixed_sparsity == 0) {
    std::printf(
        "%zu frames coded again at a smaller eps for the PSNR target (smallest eps %.4g, "
        "%.3g of the first)\n",
        q.frames_coded_again, c.tolerance * q.tolerance_scale, q.tolerance_scale);
    if (!missed.psnr) {
      std::printf("target PSNR %.2f dB met by every frame\n", psnr_target);
    } else {
      std::fflush(stdout);
      if (q.frames_at_finest > 0)
        std::fprintf(stderr,
                     "warning: target PSNR %.2f dB missed: frame %zu reached %.2f dB, and in %zu "
                     "frames no smaller eps could raise the PSNR: every brick is coded as finely "
                     "as the format allows (coefficients to 2^-%u of the brick's largest, block "
                     "means to %u bits), or eps is at its floor (2^-40 of the range); for a "
                     "higher PSNR, --codec zfp with a small --zfp-accuracy\n",
                     psnr_target, q.worst_frame, q.worst_frame_psnr, q.frames_at_finest,
                     VR_MAX_COEF_BITS, VR_MEAN_BITS);
      else
        std::fprintf(stderr,
                     "warning: target PSNR %.2f dB missed: frame %zu reached %.2f dB after %d "
                     "smaller tolerances: encode again with --tolerance %.4g or smaller\n",
                     psnr_target, q.worst_frame, q.worst_frame_psnr, encoder::max_tolerance_retries,
                     c.tolerance * q.tolerance_scale *
                         std::pow(10.0, -(psnr_target - q.worst_frame_psnr) / 20));
    }
  }
  return missed.any();
}

}  // namespace volreel::cli
