// rate_distortion.hpp: the rate-distortion harness. Every codec — zfp now, volreel's own codecs
// later — implements FrameCodec and lands in the same table, CSV and plot. Comparisons are read
// at equal bps, never at equal tolerance (docs/design.md, "Metrics").
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "volreel/datasets/series.hpp"

namespace volreel::psnr {

/// One codec at one setting (e.g. zfp fixed accuracy at tolerance 1e-3).
class FrameCodec {
 public:
  virtual ~FrameCodec() = default;
  /// Family shown in the table and the plot legend, e.g. "zfp fixed-accuracy".
  virtual std::string family() const = 0;
  /// The setting within the family, e.g. "tol=1.2e-03".
  virtual std::string setting() const = 0;
  /// Compress one frame into stream (replacing its contents).
  virtual void compress(Dims dims, std::span<const float> frame,
                        std::vector<std::uint8_t>& stream) = 0;
  /// Reconstruct the frame from stream into out (dims.voxels() values).
  virtual void decompress(Dims dims, std::span<const std::uint8_t> stream,
                          std::span<float> out) = 0;
  /// Bytes stored once for the whole sequence (e.g. a dictionary); counted in bps.
  virtual std::size_t shared_bytes() const { return 0; }
};

/// Builds the codecs of a sweep once the series' value range is known.
using CodecFactory = std::vector<std::unique_ptr<FrameCodec>> (*)(double value_range);

struct RdPoint {
  std::string family, setting;
  std::size_t frames = 0;
  std::uint64_t bytes = 0;        ///< all frame streams + shared bytes
  double bps = 0;                 ///< 8·bytes / (voxels per frame · frames)
  double psnr = 0, psnr_zfp = 0;  ///< over the whole sequence (range of all original frames)
  double rmse = 0, max_abs_error = 0;
  double ssim = 0;  ///< mean 3D SSIM over the sampled frames
  std::size_t ssim_frames = 0;
  double compress_mvoxels_per_s = 0;  ///< per thread
  double decompress_mvoxels_per_s = 0;
};

struct RdOptions {
  std::size_t max_frames = 0;   ///< 0: every frame; else the first max_frames
  std::size_t ssim_frames = 4;  ///< SSIM on this many evenly spaced frames (0: none)
};

/// Value range (min, max) of the frames the harness will use; reads every such frame once.
std::pair<double, double> series_range(const datasets::SeriesReader& series,
                                       const RdOptions& options, const Progress& progress = {});

/// Run every codec on every frame (frames read once; codecs in parallel, each on one thread).
std::vector<RdPoint> run_rate_distortion(const datasets::SeriesReader& series,
                                         std::span<const std::unique_ptr<FrameCodec>> codecs,
                                         const RdOptions& options, const Progress& progress = {});

/// A codec whose time steps depend on each other (volreel's container with sparse keyframes) is
/// run over the whole series by its caller; this measures the series it decoded against the
/// original as run_rate_distortion measures a FrameCodec. `point` comes with family, setting,
/// bytes and compress_mvoxels_per_s set; frames, bps, the errors, SSIM and the decoding speed
/// (reading `decoded`) are filled in.
void measure_decoded_series(const datasets::SeriesReader& original,
                            const datasets::SeriesReader& decoded, const RdOptions& options,
                            RdPoint& point, const Progress& progress = {});

/// zfp fixed-accuracy at tolerances range·2^-k, k = −1, 0, 1, …, 12 (zfp rounds a tolerance down
/// to a power of two, so no finer steps exist; k = −1 reaches below 0.3 bps on turbulence), and
/// fixed-rate at 0.125, 0.25, 0.5, 1, 2, 4, 8 bits per value: 21 settings, about 0.1 to 10 bps.
std::vector<std::unique_ptr<FrameCodec>> make_zfp_sweep(double value_range);
std::unique_ptr<FrameCodec> make_zfp_accuracy(double tolerance);
std::unique_ptr<FrameCodec> make_zfp_rate(double bits_per_value);

/// PSNR of one family at a bps, linear in bps between the two measured settings of the family
/// that bracket it (settings sorted by bps; non-finite PSNRs skipped). std::nullopt outside the
/// family's measured span: a curve is never extrapolated.
std::optional<double> psnr_at_bps(std::span<const RdPoint> points, const std::string& family,
                                  double bps);

/// Every family's PSNR at the same bps values, for reading comparisons at equal bps.
struct EqualBpsTable {
  std::vector<std::string> families;  ///< in order of first appearance in the points
  std::string reference;              ///< the family the others are compared with ("" for none)
  std::vector<double> bps;
  std::vector<std::vector<std::optional<double>>> psnr;  ///< [bps row][family]
};

/// The family compared with is `reference` when the points have it, else none.
EqualBpsTable equal_bps_table(std::span<const RdPoint> points, std::span<const double> bps,
                              const std::string& reference = "volreel variable-rate");

void print_rd_table(std::ostream& out, std::span<const RdPoint> points);
/// One row per bps: each family's PSNR and, for the others, reference − family.
void print_equal_bps_table(std::ostream& out, const EqualBpsTable& table);
/// Long form: bps, family, PSNR and reference − family (empty where not measured).
void write_equal_bps_csv(const std::filesystem::path& path, const EqualBpsTable& table);
void write_rd_csv(const std::filesystem::path& path, std::span<const RdPoint> points);
/// PSNR vs bps, one line per family, via gnuplot (pngcairo). Throws InputError with an
/// installation hint when gnuplot is not on PATH.
void write_rd_plot(const std::filesystem::path& png, std::span<const RdPoint> points,
                   const std::string& title);

}  // namespace volreel::psnr
