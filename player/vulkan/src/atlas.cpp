// atlas.cpp: the brick atlas image, its grid and the 16-bit conversions (see atlas.hpp).
#include "volreel/vulkan/atlas.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <string>
#include <vector>

#include "volreel/player/atlas_layout.h"

namespace volreel::vulkan {

const char* atlas_format_name(AtlasFormat format) {
  return format == AtlasFormat::r16_unorm ? "R16_UNORM" : "R16_SFLOAT";
}

AtlasGrid choose_atlas_grid(std::uint64_t max_slots, std::uint32_t max_image_dimension_3d,
                            std::uint32_t slot_size) {
  const std::uint32_t cap =
      std::max<std::uint32_t>(1, max_image_dimension_3d / std::max<std::uint32_t>(1, slot_size));
  const std::uint64_t n = std::clamp<std::uint64_t>(max_slots, 1, std::uint64_t{cap} * cap * cap);
  // 1. Every grid x ≥ y ≥ z within the caps and n slots; the most slots any of them holds.
  struct Candidate {
    AtlasGrid grid;
    std::uint64_t slots;
    std::uint32_t spread;  // longest − shortest axis
  };
  std::vector<Candidate> candidates;
  std::uint64_t most = 0;
  for (std::uint32_t x = 1; x <= cap && x <= n; ++x)
    for (std::uint32_t y = 1; y <= x && std::uint64_t{x} * y <= n; ++y) {
      const auto z =
          static_cast<std::uint32_t>(std::min<std::uint64_t>({cap, y, n / (std::uint64_t{x} * y)}));
      if (z == 0) continue;
      const std::uint64_t slots = std::uint64_t{x} * y * z;
      candidates.push_back({{x, y, z}, slots, x - z});
      most = std::max(most, slots);
    }
  // 2. Among those within 3 % of the most, the most cube-like (texture caches, sampling
  //    locality), then the one with more slots.
  const Candidate* best = nullptr;
  for (const Candidate& c : candidates) {
    if (c.slots * 100 < most * 97) continue;
    if (!best || c.spread < best->spread || (c.spread == best->spread && c.slots > best->slots))
      best = &c;
  }
  return best ? best->grid : AtlasGrid{};
}

std::uint16_t float_to_half(float value) {
  const auto bits = std::bit_cast<std::uint32_t>(value);
  const auto sign = static_cast<std::uint16_t>((bits >> 16) & 0x8000u);
  std::uint32_t magnitude = bits & 0x7FFFFFFFu;
  if (magnitude >= 0x7F800000u)  // infinity or NaN
    return static_cast<std::uint16_t>(sign | 0x7C00u | (magnitude > 0x7F800000u ? 0x200u : 0u));
  if (magnitude >= 0x477FF000u) return static_cast<std::uint16_t>(sign | 0x7C00u);  // ≥ 65520
  if (magnitude < 0x38800000u) {  // below 2^-14: a subnormal half, in units of 2^-24
    const float units = std::nearbyint(std::bit_cast<float>(magnitude) * 16777216.0f);
    return static_cast<std::uint16_t>(sign | static_cast<std::uint32_t>(units));
  }
  // Rebias the exponent (127 → 15) and round the 13 dropped mantissa bits to nearest even.
  magnitude += 0xC8000FFFu + ((magnitude >> 13) & 1u);
  return static_cast<std::uint16_t>(sign | (magnitude >> 13));
}

float half_to_float(std::uint16_t half) {
  const std::uint32_t sign = std::uint32_t{half & 0x8000u} << 16;
  const std::uint32_t exponent = (half >> 10) & 0x1Fu, mantissa = half & 0x3FFu;
  if (exponent == 0) {
    const float v = std::ldexp(static_cast<float>(mantissa), -24);
    return sign ? -v : v;
  }
  if (exponent == 31) return std::bit_cast<float>(sign | 0x7F800000u | (mantissa << 13));
  return std::bit_cast<float>(sign | ((exponent + 112u) << 23) | (mantissa << 13));
}

Atlas::Atlas(const Context& context, const AtlasOptions& options) : options_(options) {
  const VkFormat vk_format =
      options.format == AtlasFormat::r16_unorm ? VK_FORMAT_R16_UNORM : VK_FORMAT_R16_SFLOAT;
  // 1. The format must be writable from a compute shader and filterable by the renderer.
  const VkFormatFeatureFlags needed =
      VK_FORMAT_FEATURE_STORAGE_IMAGE_BIT | VK_FORMAT_FEATURE_SAMPLED_IMAGE_BIT |
      VK_FORMAT_FEATURE_SAMPLED_IMAGE_FILTER_LINEAR_BIT | VK_FORMAT_FEATURE_TRANSFER_SRC_BIT |
      VK_FORMAT_FEATURE_TRANSFER_DST_BIT;
  if ((context.optimal_format_features(vk_format) & needed) != needed)
    throw Error(std::string("vkGetPhysicalDeviceFormatProperties: ") +
                    atlas_format_name(options.format) +
                    " lacks storage-image, sampled-image, linear-filter or transfer support on " +
                    context.device_name(),
                VK_ERROR_FORMAT_NOT_SUPPORTED);
  if (!context.enabled_features().shaderStorageImageExtendedFormats)
    throw Error(
        "vkCreateDevice: shaderStorageImageExtendedFormats (16-bit storage images) is not "
        "supported by " +
            context.device_name(),
        VK_ERROR_FEATURE_NOT_PRESENT);
  if (options.format == AtlasFormat::r16_unorm && !(options.value_max > options.value_min))
    throw Error("Atlas: R16_UNORM needs value_max > value_min", VK_ERROR_INITIALIZATION_FAILED);
  // 2. Grid from the memory budget, the slot cap and the largest 3D image.
  const std::uint32_t n = options.slot_size;
  if (n == 0 || n % 6 != 0 || n > 66)
    throw Error("Atlas: slots of " + std::to_string(n) +
                    "^3 voxels (a brick size: 12..66, a "
                    "multiple of 6)",
                VK_ERROR_INITIALIZATION_FAILED);
  const std::uint64_t slot_bytes = 2 * std::uint64_t{n} * n * n;
  std::uint64_t slots = options.memory_budget_bytes / slot_bytes;
  if (options.max_slots) slots = std::min<std::uint64_t>(slots, options.max_slots);
  if (slots == 0)
    throw Error("Atlas: a memory budget of " + std::to_string(options.memory_budget_bytes) +
                    " bytes holds no " + std::to_string(n) + "^3 slot (" +
                    std::to_string(slot_bytes) + " bytes)",
                VK_ERROR_OUT_OF_DEVICE_MEMORY);
  grid_ = choose_atlas_grid(slots, context.limits().maxImageDimension3D, n);
  // 3. The image, cleared to zero and left in GENERAL for storage writes, sampling and copies.
  ImageDesc desc;
  desc.type = VK_IMAGE_TYPE_3D;
  desc.format = vk_format;
  desc.extent = {grid_.x * n, grid_.y * n, grid_.z * n};
  desc.usage = VK_IMAGE_USAGE_STORAGE_BIT | VK_IMAGE_USAGE_SAMPLED_BIT |
               VK_IMAGE_USAGE_TRANSFER_SRC_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT;
  image_ = Image(context, desc);
  context.submit_and_wait([&](VkCommandBuffer commands) {
    image_barrier(commands, image_.handle(), VK_IMAGE_LAYOUT_UNDEFINED, VK_IMAGE_LAYOUT_GENERAL,
                  VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, 0, VK_PIPELINE_STAGE_TRANSFER_BIT,
                  VK_ACCESS_TRANSFER_WRITE_BIT);
    const VkClearColorValue zero{};
    const VkImageSubresourceRange range{VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1};
    vkCmdClearColorImage(commands, image_.handle(), VK_IMAGE_LAYOUT_GENERAL, &zero, 1, &range);
    memory_barrier(
        commands, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
        VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
        VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT);
  });
}

VkOffset3D Atlas::slot_origin(std::uint32_t slot) const {
  const std::uint32_t n = options_.slot_size;
  return {static_cast<std::int32_t>(vr_atlas_cell_x(slot, grid_.x) * n),
          static_cast<std::int32_t>(vr_atlas_cell_y(slot, grid_.x, grid_.y) * n),
          static_cast<std::int32_t>(vr_atlas_cell_z(slot, grid_.x, grid_.y) * n)};
}

float Atlas::texel_to_value(std::uint16_t texel) const {
  if (options_.format == AtlasFormat::r16_sfloat) return half_to_float(texel);
  return options_.value_min +
         (options_.value_max - options_.value_min) * (static_cast<float>(texel) / 65535.0f);
}

std::uint16_t Atlas::value_to_texel(float value) const {
  std::uint16_t texel = 0;
  values_to_texels({&value, 1}, &texel);
  return texel;
}

void Atlas::values_to_texels(std::span<const float> values, std::uint16_t* out) const {
  if (options_.format == AtlasFormat::r16_sfloat) {
    for (std::size_t i = 0; i < values.size(); ++i) out[i] = float_to_half(values[i]);
    return;
  }
  // The same arithmetic as value_to_texel, in a loop the compiler vectorizes.
  const float lo = options_.value_min, inv = 1.0f / (options_.value_max - options_.value_min);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const float x = (values[i] - lo) * inv;
    const float n = x > 0.0f ? (x < 1.0f ? x : 1.0f) : 0.0f;   // NaN: the lowest value
    out[i] = static_cast<std::uint16_t>(n * 65535.0f + 0.5f);  // n ≥ 0: round to nearest
  }
}

float Atlas::round_trip(float value) const {
  return texel_to_value(value_to_texel(value));
}

float Atlas::rounding_bound(float value) const {
  if (options_.format == AtlasFormat::r16_unorm)
    return 0.5f * (options_.value_max - options_.value_min) / 65535.0f;
  const float magnitude = std::fabs(value);
  if (magnitude < 6.103515625e-05f) return 0x1p-25f;  // subnormal halves: units of 2^-24
  int exponent = 0;
  std::frexp(magnitude, &exponent);  // magnitude in [2^(e−1), 2^e)
  return std::ldexp(1.0f, exponent - 1 - 11);
}

}  // namespace volreel::vulkan
