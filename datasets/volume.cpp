// volume.cpp: parsing and printing of grid dimensions.
#include "volreel/datasets/volume.hpp"

#include <charconv>

namespace volreel {

Dims parse_dims(const std::string& text) {
  std::int64_t values[3] = {0, 0, 0};
  const char* p = text.data();
  const char* end = text.data() + text.size();
  for (int axis = 0; axis < 3; ++axis) {
    auto [next, ec] = std::from_chars(p, end, values[axis]);
    const bool separator_ok =
        axis == 2 ? next == end : (next != end && (*next == 'x' || *next == 'X'));
    if (ec != std::errc() || !separator_ok || values[axis] <= 0 || values[axis] > (1 << 20))
      throw InputError("dimensions '" + text +
                       "' are not of the form XxYxZ with positive integers (e.g. 256x256x128)");
    p = next + (axis == 2 ? 0 : 1);
  }
  return Dims{values[0], values[1], values[2]};
}

std::string to_string(const Dims& dims) {
  return std::to_string(dims.x) + "x" + std::to_string(dims.y) + "x" + std::to_string(dims.z);
}

}  // namespace volreel
