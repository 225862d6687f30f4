// detail.hpp: helpers shared by the series readers; not part of the public interface.
#pragma once

#include <cstddef>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "volreel/datasets/series.hpp"

namespace volreel::datasets::detail {

/// "(x, y, z)" of value i of a slab of planes from z_begin on.
std::string voxel_name(std::size_t i, Dims dims, std::size_t z_begin);

/// Throw InputError naming `what` and the first non-finite voxel (values: planes from z_begin
/// on), or replace every non-finite value when `replacement` is set.
void check_finite(std::span<float> values, Dims dims, const std::string& what,
                  std::optional<float> replacement, std::size_t z_begin = 0);

/// Throw InputError unless t is a frame of the series, [z_begin, z_end) a non-empty range of its
/// planes and out_size the slab's voxel count.
void check_slab(const SeriesInfo& info, std::size_t t, std::size_t z_begin, std::size_t z_end,
                std::size_t out_size);

/// Convert `count` little-endian values of `dtype` from `bytes` to float32.
void convert_to_float(const unsigned char* bytes, Dtype dtype, std::span<float> out);

/// Read exactly out.size_bytes() bytes at `offset` of `file`; InputError naming the file,
/// the offset and how many bytes were expected and found.
void read_exact(const std::filesystem::path& file, std::uint64_t offset,
                std::span<unsigned char> out);

std::unique_ptr<SeriesReader> open_raw_series(const std::filesystem::path& dir,
                                              const OpenOptions& options);
std::unique_ptr<SeriesReader> open_raw_file(const std::filesystem::path& file,
                                            const OpenOptions& options);
/// The files `pattern` (glob(3): *, ?, [...]) matches, one frame each, in natural order
/// ("p_2" before "p_10"); needs options.dims.
std::unique_ptr<SeriesReader> open_raw_glob(const std::string& pattern, const OpenOptions& options);
/// Whether `text` has a glob character (*, ? or [).
bool is_glob(const std::string& text);
/// The paths `pattern` matches in natural order; InputError when none does.
std::vector<std::filesystem::path> expand_glob(const std::string& pattern);
std::unique_ptr<SeriesReader> open_netcdf(const std::filesystem::path& file,
                                          const OpenOptions& options);
std::unique_ptr<SeriesReader> open_hdf5(const std::filesystem::path& file,
                                        const OpenOptions& options);

/// The most classic_values_end returns: 2^63 bytes, past any file.
constexpr long double classic_end_limit = 9223372036854775808.0L;
/// The byte of a classic-format NetCDF file (CDF-1, CDF-2, CDF-5, as "The NetCDF Classic Format
/// Specification" lays them out) that its variables' values end at, from the file's first bytes
/// `header`: the largest begin + size of a fixed-size variable, and begin + (records − 1)·record
/// size + size of a record variable, with each variable's begin offset read from the header (the
/// library exposes none), at most classic_end_limit. `variables`, `records`: the counts the
/// library reads. std::nullopt where the header cannot be walked (not classic, cut short, other
/// counts, an unknown type).
std::optional<long double> classic_values_end(const std::vector<unsigned char>& header,
                                              int variables, std::size_t records);

}  // namespace volreel::datasets::detail
