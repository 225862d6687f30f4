// cpu_atlas.hpp: the CPU copy of the brick atlas (atlas_layout.h): slot s holds one stored brick
// of S³ float values (x fastest, S the bricks' size) at s·S³, filled from decoded bricks or
// straight from a brick payload with the CPU reference decoder. The CPU reference renderer
// samples it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "volreel/format/decoder.hpp"
#include "volreel/player/atlas_layout.h"

namespace volreel::cpu_render {

class CpuAtlas {
 public:
  /// slot_count slots for bricks of `shape`, every value 0.
  explicit CpuAtlas(std::uint32_t slot_count, format::BrickShape shape = {});

  std::uint32_t slot_count() const { return slot_count_; }
  format::BrickShape shape() const { return shape_; }
  /// Values of a slot: shape().voxels().
  std::size_t slot_values() const { return slot_values_; }

  /// Copies a decoded brick (S³ values, x fastest) into slot `slot`. Throws std::out_of_range on
  /// a bad slot and std::invalid_argument on a brick of the wrong size.
  void store(std::uint32_t slot, std::span<const float> brick);
  /// Decodes a brick payload (format::decode_payload: constant, ksvd with `atoms`, or zfp with
  /// `zfp_accuracy`) into slot `slot`. `name` and `offset` identify the payload in errors.
  /// Throws format::FormatError on a bad payload (the slot is then unspecified).
  void decode_into(std::uint32_t slot, std::span<const std::byte> payload, format::Codec codec,
                   double zfp_accuracy, const format::AtomTable& atoms,
                   const std::filesystem::path& name = "brick", std::uint64_t offset = 0);

  /// The S³ values of a slot.
  std::span<const float> slot(std::uint32_t slot) const;
  std::span<float> slot(std::uint32_t slot);

  /// Trilinear sample of slot `slot` at stored-voxel coordinates (x, y, z) in texel units with
  /// texel centres at +0.5 (vr_svo_slot_coord), clamped to the slot's edge texels — what a 3D
  /// texture with a linear sampler and clamp-to-edge returns. No bounds check on `slot`.
  float sample(std::uint32_t slot, float x, float y, float z) const;

 private:
  std::uint32_t slot_count_ = 0;
  format::BrickShape shape_;
  std::size_t slot_values_ = 0;
  struct Free {
    void operator()(float* p) const;
  };
  /// Zeroed by calloc: a large block comes from fresh pages the kernel zeroes when first touched,
  /// so an atlas of hundreds of MiB costs nothing until its slots are used (a std::vector would
  /// write every byte up front, seconds before the first frame).
  std::unique_ptr<float[], Free> values_;
};

}  // namespace volreel::cpu_render
