// series.hpp: time series of volumes on disk — the raw series format written by `volreel gen`,
// single raw files, and HDF5 files — behind one reader interface.
//
// Raw series format (a directory):
//   series.json        {"format":"volreel-raw-series","version":1,"dims":[x,y,z],"dtype":"f32",
//                       "spacing":[sx,sy,sz],"variable":"pressure","timestamps":[t0,...],
//                       "frames":["000000.f32",...],"generator":{...how it was made...}}
//   000000.f32 ...     one little-endian float32 volume per frame, x fastest, no header.
#pragma once

#include <array>
#include <cstddef>
#include <filesystem>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/datasets/volume.hpp"

namespace volreel::datasets {

enum class Dtype { f32, f64, u8, u16 };
/// "f32" | "f64" | "u8" | "u16" (also "float32", "float64", "uint8", "uint16").
Dtype parse_dtype(const std::string& text);
std::string to_string(Dtype dtype);
std::size_t dtype_size(Dtype dtype);

/// What every reader knows about its series.
struct SeriesInfo {
  Dims dims;
  std::size_t frames = 0;
  std::array<double, 3> spacing{1.0, 1.0, 1.0};
  std::vector<double> timestamps;  ///< one per frame
  std::string variable;            ///< e.g. "pressure"
  std::string source;              ///< human-readable description of where it came from
  nlohmann::json generator;        ///< how it was made (raw series only; may be null)
};

/// How to open a series whose file does not describe itself.
struct OpenOptions {
  std::optional<Dims> dims;           ///< raw file: required
  std::optional<Dtype> dtype;         ///< raw file: default f32
  std::optional<std::size_t> frames;  ///< raw file: frames stored back to back (default 1)
  std::string dataset;                ///< HDF5: a 4D dataset name, or a pattern with one
                                      ///< run of '#' (e.g. "Pressure_####") or '*'
  std::string variable;              ///< NetCDF: the variable (default: the only one of 3–4 dims)
  std::string time_dimension;        ///< NetCDF: the time dimension (default: the unlimited one,
                                     ///< or one named time or t)
  std::optional<float> replace_nan;  ///< substitute NaN/Inf with this value instead of failing
  /// Voxel spacing (x, y, z), three positive finite numbers: replaces what the input says
  /// (series.json's, NetCDF's coordinates) or the default 1, 1, 1 (raw files, HDF5).
  std::optional<std::array<double, 3>> spacing;
};

/// Reads frames of a series. Implementations are safe to call from several threads at once.
class SeriesReader {
 public:
  virtual ~SeriesReader() = default;
  const SeriesInfo& info() const { return info_; }
  /// Replaces the spacing the input gave; InputError unless three positive finite numbers.
  void set_spacing(const std::array<double, 3>& spacing);

  /// Read frame t (0-based) into out (size dims.voxels()), converting to float32.
  /// Throws InputError naming the file on a missing frame, a short file, an I/O error, or a
  /// NaN/Inf value (unless OpenOptions::replace_nan is set). The default reads the slab of every
  /// plane (read_slab); a reader overrides at least one of the two.
  virtual void read_frame(std::size_t t, std::span<float> out) const;
  Volume read_frame(std::size_t t) const;
  /// Read planes [z_begin, z_end) of frame t into out (size dims.x·dims.y·(z_end − z_begin)),
  /// as read_frame would deliver them; a voxel named in an error has its z within the frame.
  /// The raw, HDF5 and NetCDF readers read only those planes (by file offset, hyperslab or
  /// vara), so a frame larger than memory can be worked through in pieces; the default reads
  /// the whole frame and copies the planes.
  virtual void read_slab(std::size_t t, std::size_t z_begin, std::size_t z_end,
                         std::span<float> out) const;

 protected:
  SeriesInfo info_;
};

/// The kinds of input open_series reads, each with its OpenOptions: dims, dtype and frames for
/// raw files (one, or a pattern), dataset for HDF5, variable and time_dimension for NetCDF; a
/// series directory takes none.
enum class InputKind { raw, raw_series, hdf5, netcdf };
/// The kind of input `path` names, by what it is or its extension (raw: anything else).
InputKind input_kind(const std::filesystem::path& path);

/// Whether `path` names a series that gives its own dimensions, type and frames (a series
/// directory or its series.json, an HDF5 or NetCDF file): open_series refuses OpenOptions' dims,
/// dtype and frames for it.
bool describes_itself(const std::filesystem::path& path);

/// `options` without those that `path`'s kind does not take but `other`'s does, so that one set
/// of options can describe two inputs of different kinds (compare A B); those neither takes stay,
/// for open_series to refuse. other: null when the other input is not a series (a container).
OpenOptions options_for(const std::filesystem::path& path, const OpenOptions& options,
                        const std::filesystem::path* other);

/// Whether `path` (existing or not) is the directory `dir` or lies inside it, links resolved.
/// False when `dir` is not a directory.
bool path_within(const std::filesystem::path& dir, const std::filesystem::path& path);

/// Whether writing `file` would replace part of the input `path`: `path` itself (a file), a file
/// its pattern matches, or an existing file inside it (a series directory, a container). False
/// when `file` does not exist.
bool input_includes(const std::filesystem::path& path, const std::filesystem::path& file);

/// Open a series: a raw series directory (or its series.json), an HDF5 file (.h5, .hdf5, .hdf),
/// a NetCDF file (.nc, .nc4, .cdf),
/// a single raw file, or a glob pattern (*, ?, [...]) of raw files with one frame each in
/// natural order (raw input needs options.dims). Throws InputError with a clear message.
std::unique_ptr<SeriesReader> open_series(const std::filesystem::path& path,
                                          const OpenOptions& options = {});

/// Writes a raw series directory. Each frame goes to a temporary name and is renamed when
/// complete; series.json is written last by finish(), so an interrupted run leaves no series.json
/// that claims frames which are not there.
class RawSeriesWriter {
 public:
  /// Creates dir (and parents). Throws InputError if dir exists and holds a series.json unless
  /// overwrite is set. With overwrite the new frames are written to dir/.volreel-new, and
  /// finish() moves them over the old ones, writes the new series.json and removes the frames
  /// 000000.f32 … of an old series a generator wrote that the new one does not replace; until
  /// then the old series stays whole.
  RawSeriesWriter(std::filesystem::path dir, Dims dims, std::string variable,
                  bool overwrite = false);
  /// Without finish (an error on the way): removes the frames written (with overwrite, the
  /// folder they went to) and the directory if this writer created it, so that a failed run
  /// leaves nothing half-written and an old series as it was.
  ~RawSeriesWriter();
  RawSeriesWriter(const RawSeriesWriter&) = delete;
  RawSeriesWriter& operator=(const RawSeriesWriter&) = delete;

  const std::filesystem::path& directory() const { return dir_; }
  Dims dims() const { return dims_; }

  /// Write frame t with simulated time `timestamp`. Frames may arrive in any order.
  void write_frame(std::size_t t, double timestamp, std::span<const float> data);
  /// Extra description stored under "generator" in series.json.
  void set_generator(nlohmann::json generator) { generator_ = std::move(generator); }
  void set_spacing(std::array<double, 3> spacing) { spacing_ = spacing; }
  /// Write series.json; every frame 0..n-1 must have been written.
  void finish();

 private:
  std::filesystem::path dir_;
  Dims dims_;
  std::string variable_;
  std::array<double, 3> spacing_{1.0, 1.0, 1.0};
  std::vector<std::optional<double>> timestamps_;
  nlohmann::json generator_;
  std::vector<std::filesystem::path> created_;  ///< what to remove without finish: dirs last
  std::filesystem::path staging_;  ///< overwrite of a series: where the new frames go first
  std::size_t stale_frames_ = 0;   ///< overwrite: the frame count of the old generated series
  bool finished_ = false;
};

/// Throws InputError unless `spacing` is three positive finite numbers.
void check_spacing(const std::array<double, 3>& spacing);

/// Name of frame t's file inside a raw series directory: "000017.f32".
std::string raw_frame_name(std::size_t t);

}  // namespace volreel::datasets
