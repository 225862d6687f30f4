// fuzz_netcdf.cpp: the walk of a classic NetCDF header (datasets/netcdf_reader.cpp), which finds
// where a file's values end from the header's own offsets, on any bytes: the first byte picks the
// variable count the library would report (0..15), the next two the records (0..65535), the rest
// is the header. Every outcome is no end (a header it cannot walk) or an end past the bytes it
// walked and at most classic_end_limit.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "detail.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 3) return 0;
  const int variables = data[0] & 0xF;
  const std::size_t records = std::size_t{data[1]} << 8 | data[2];
  const std::vector<unsigned char> header(data + 3, data + size);
  const auto end = volreel::datasets::detail::classic_values_end(header, variables, records);
  if (end &&
      !(std::isfinite(*end) && *end >= 4 && *end <= volreel::datasets::detail::classic_end_limit))
    std::abort();
  return 0;
}
