// atlas.hpp: the brick atlas on the GPU — one 3D image of 16-bit voxels holding a fixed number of
// S³ slots (a brick with its apron, S the container's brick size), laid out as
// player/atlas_layout.h says. The decoder writes
// slots as a storage image; the renderer samples it with a linear sampler. The image stays in
// VK_IMAGE_LAYOUT_GENERAL (AtlasDecoder's buffer-copy kernel and read_slots leave it only for the
// span of their copies).
//
// Format: R16_UNORM with the value range stored (v = lo + (hi − lo)·n, n in [0, 1]) is the
// default, chosen by measurement (docs/benchmarks.md, "Atlas format"). UNORM's error is uniform
// over the range, at most (hi − lo)/131070; SFLOAT keeps 11 significant bits, so its error grows
// with |v|. UNORM also filters linearly on every device. R16_SFLOAT remains an option for data of
// huge dynamic range around 0.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "volreel/vulkan/context.hpp"
#include "volreel/vulkan/resources.hpp"

namespace volreel::vulkan {

enum class AtlasFormat { r16_unorm, r16_sfloat };

const char* atlas_format_name(AtlasFormat format);

struct AtlasOptions {
  AtlasFormat format = AtlasFormat::r16_unorm;
  /// Voxels per slot axis: the container's brick size (format::BrickShape::size).
  std::uint32_t slot_size = 36;
  /// Bytes the atlas image may take (2 bytes per voxel: 93 312 bytes per 36³ slot).
  std::uint64_t memory_budget_bytes = std::uint64_t{256} << 20;
  /// At most this many slots (0: as many as the budget and the device allow).
  std::uint32_t max_slots = 0;
  /// The value range mapped to [0, 1] by r16_unorm (values outside are clamped); unused by
  /// r16_sfloat. Give the dataset's range with a small margin: decoded values may overshoot it.
  float value_min = 0.0f, value_max = 1.0f;
};

/// Slots per axis of the atlas grid.
struct AtlasGrid {
  std::uint32_t x = 1, y = 1, z = 1;
  std::uint32_t slots() const { return x * y * z; }
};

/// The grid for at most `max_slots` slots of `slot_size`³ voxels with no axis longer than
/// `max_image_dimension_3d` voxels: as close to a cube as possible, the largest slot count not
/// above max_slots that such a grid holds (at least 1 slot). Pure arithmetic, for tests.
AtlasGrid choose_atlas_grid(std::uint64_t max_slots, std::uint32_t max_image_dimension_3d,
                            std::uint32_t slot_size = 36);

/// The 16-bit texel value that `value` becomes in the atlas (the GPU's conversion up to the last
/// unit), and back; for tests and error measurements on the CPU.
std::uint16_t float_to_half(float value);
float half_to_float(std::uint16_t half);

class Atlas {
 public:
  /// Creates the image (usage STORAGE | SAMPLED | TRANSFER_SRC | TRANSFER_DST), cleared to zero,
  /// in GENERAL layout. Throws Error if the format lacks storage-image, sampled-image or
  /// linear-filter support on this device, or the budget holds no slot.
  Atlas(const Context& context, const AtlasOptions& options);

  const Image& image() const { return image_; }
  VkImageView view() const { return image_.view(); }
  VkFormat vk_format() const { return image_.desc().format; }
  AtlasFormat format() const { return options_.format; }
  const AtlasGrid& grid() const { return grid_; }
  std::uint32_t slot_count() const { return grid_.slots(); }
  /// Voxels per slot axis (AtlasOptions::slot_size).
  std::uint32_t slot_size() const { return options_.slot_size; }
  float value_min() const { return options_.value_min; }
  float value_max() const { return options_.value_max; }
  /// First voxel of slot s in the image.
  VkOffset3D slot_origin(std::uint32_t slot) const;
  /// A texel read back from the image as a value.
  float texel_to_value(std::uint16_t texel) const;
  /// The texel that `value` is stored as (round to nearest; r16_unorm clamps to the range).
  std::uint16_t value_to_texel(float value) const;
  /// value_to_texel of each value, into out[0 .. values.size()).
  void values_to_texels(std::span<const float> values, std::uint16_t* out) const;
  /// The value a voxel of `value` reads back as (the format's rounding, round-to-nearest).
  float round_trip(float value) const;
  /// Largest |round_trip(v) − v| for v of magnitude ≤ |value| (half a unit of the format, for
  /// tolerances in tests).
  float rounding_bound(float value) const;

 private:
  AtlasOptions options_;
  AtlasGrid grid_;
  Image image_;
};

}  // namespace volreel::vulkan
