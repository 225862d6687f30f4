// volume.cpp: parsing and printing of grid dimensions.
#include "volreel/datasets/volume.hpp"

#include <charconv>
#include <cstdio>

namespace volreel {

Dims parse_dims(const std::string& text) {
  std::int64_t values[3] = {0, 0, 0};
  const char* p = text.data();
  const char* end = text.data() + text.size();
  for (int axis = 0; axis < 3; ++axis) {
    auto [next, ec] = std::from_chars(p, end, values[axis]);
    const bool separator_ok =
        axis == 2 ? next == end : (next != end && (*next == 'x' || *next == 'X'));
    if (ec != std::errc() || !separator_ok || values[axis] <= 0)
      throw InputError("dimensions '" + text +
                       "' are not of the form XxYxZ with positive integers (e.g. 256x256x128)");
    if (values[axis] > (1 << 20))
      throw InputError("dimensions '" + text +
                       "': expected at most 1048576 voxels an axis, found " +
                       std::to_string(values[axis]));
    p = next + (axis == 2 ? 0 : 1);
  }
  const Dims dims{values[0], values[1], values[2]};
  check_frame_voxels(dims, "dimensions '" + text + "'");
  return dims;
}

void check_frame_voxels(const Dims& dims, const std::string& what) {
  const long double voxels = static_cast<long double>(dims.x) * static_cast<long double>(dims.y) *
                             static_cast<long double>(dims.z);
  if (voxels > static_cast<long double>(max_frame_voxels)) {
    char found[64];
    std::snprintf(found, sizeof found, "%.3g", static_cast<double>(voxels));
    throw InputError(what + ": expected at most 2^48 voxels a frame, found " + to_string(dims) +
                     " = " + found);
  }
}

std::string to_string(const Dims& dims) {
  return std::to_string(dims.x) + "x" + std::to_string(dims.y) + "x" + std::to_string(dims.z);
}

}  // namespace volreel
