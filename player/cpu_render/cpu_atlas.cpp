// cpu_atlas.cpp: the CPU copy of the brick atlas and its trilinear sampler.
#include "volreel/cpu_render/cpu_atlas.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <new>
#include <stdexcept>
#include <string>

#include "trilinear.hpp"

namespace volreel::cpu_render {

CpuAtlas::CpuAtlas(std::uint32_t slot_count, format::BrickShape shape)
    : slot_count_(slot_count),
      shape_(shape),
      slot_values_(shape.voxels()),
      values_(static_cast<float*>(
          std::calloc(std::max<std::size_t>(slot_count, 1), slot_values_ * sizeof(float)))) {
  if (!format::valid_brick_size(shape.size))
    throw std::invalid_argument("CpuAtlas: bricks of " + std::to_string(shape.size) +
                                "^3 (a brick size is a multiple of 6 in 12..66)");
  if (!values_) throw std::bad_alloc();
}

void CpuAtlas::Free::operator()(float* p) const {
  std::free(p);
}

std::span<const float> CpuAtlas::slot(std::uint32_t slot) const {
  if (slot >= slot_count_)
    throw std::out_of_range("CpuAtlas: slot " + std::to_string(slot) + " of " +
                            std::to_string(slot_count_));
  return {values_.get() + std::size_t{slot} * slot_values_, slot_values_};
}

std::span<float> CpuAtlas::slot(std::uint32_t slot) {
  if (slot >= slot_count_)
    throw std::out_of_range("CpuAtlas: slot " + std::to_string(slot) + " of " +
                            std::to_string(slot_count_));
  return {values_.get() + std::size_t{slot} * slot_values_, slot_values_};
}

void CpuAtlas::store(std::uint32_t slot, std::span<const float> brick) {
  if (brick.size() != slot_values_)
    throw std::invalid_argument("CpuAtlas::store: expected " + std::to_string(slot_values_) +
                                " values, found " + std::to_string(brick.size()));
  std::ranges::copy(brick, this->slot(slot).begin());
}

void CpuAtlas::decode_into(std::uint32_t slot, std::span<const std::byte> payload,
                           format::Codec codec, double zfp_accuracy, const format::AtomTable& atoms,
                           const std::filesystem::path& name, std::uint64_t offset) {
  format::decode_payload(payload, codec, zfp_accuracy, atoms, shape_, this->slot(slot), name,
                         offset);
}

float CpuAtlas::sample(std::uint32_t slot, float x, float y, float z) const {
  const std::uint32_t n = shape_.size;
  return detail::trilinear(values_.get() + std::size_t{slot} * slot_values_, n, n, n, x - 0.5f,
                           y - 0.5f, z - 0.5f);
}

}  // namespace volreel::cpu_render
