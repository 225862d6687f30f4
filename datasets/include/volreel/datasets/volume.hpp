// volume.hpp: dimensions and dense float32 volumes, the currency of datasets/ and tools/.
#pragma once

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace volreel {

/// Thrown for bad input: the message names the file or value and what was wrong.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Size of a rectilinear grid in voxels; x varies fastest in memory.
struct Dims {
  std::int64_t x = 0, y = 0, z = 0;

  constexpr std::size_t voxels() const noexcept {
    return static_cast<std::size_t>(x) * static_cast<std::size_t>(y) * static_cast<std::size_t>(z);
  }
  /// Voxels of one plane (constant z).
  constexpr std::size_t plane() const noexcept {
    return static_cast<std::size_t>(x) * static_cast<std::size_t>(y);
  }
  constexpr std::size_t planes() const noexcept { return static_cast<std::size_t>(z); }
  constexpr std::size_t index(std::int64_t i, std::int64_t j, std::int64_t k) const noexcept {
    return static_cast<std::size_t>(i + x * (j + y * k));
  }
  friend constexpr bool operator==(const Dims&, const Dims&) = default;
};

/// The most voxels a frame may have (2^48: a frame's byte count never overflows).
inline constexpr std::uint64_t max_frame_voxels = std::uint64_t{1} << 48;
/// Throws InputError "WHAT: expected at most 2^48 voxels a frame, found ..." for a larger frame.
void check_frame_voxels(const Dims& dims, const std::string& what);

/// "256x256x128" -> Dims; throws InputError naming the text when it does not parse.
Dims parse_dims(const std::string& text);
std::string to_string(const Dims& dims);

/// A dense float32 volume, x fastest.
struct Volume {
  Dims dims;
  std::vector<float> data;

  Volume() = default;
  explicit Volume(Dims d) : dims(d), data(d.voxels(), 0.0f) {}
  float& at(std::int64_t i, std::int64_t j, std::int64_t k) { return data[dims.index(i, j, k)]; }
  float at(std::int64_t i, std::int64_t j, std::int64_t k) const {
    return data[dims.index(i, j, k)];
  }
};

/// Progress of long work: done out of total units, plus a short status text (may be empty).
/// Libraries call it; the command line draws the bar. Must be cheap; may be empty.
struct ProgressUpdate {
  double done = 0;
  double total = 0;
  std::string status;
};
using ProgressCallback = void (*)(const ProgressUpdate&, void* user);
struct Progress {
  ProgressCallback callback = nullptr;
  void* user = nullptr;
  void report(double done, double total, std::string status = {}) const {
    if (callback) callback(ProgressUpdate{done, total, std::move(status)}, user);
  }
};

}  // namespace volreel
