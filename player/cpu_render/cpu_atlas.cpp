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

CpuAtlas::CpuAtlas(std::uint32_t slot_count)
    : slot_count_(slot_count),
      values_(static_cast<float*>(
          std::calloc(std::max<std::size_t>(slot_count, 1), slot_values * sizeof(float)))) {
  if (!values_) throw std::bad_alloc();
}

void CpuAtlas::Free::operator()(float* p) const {
  std::free(p);
}

std::span<const float> CpuAtlas::slot(std::uint32_t slot) const {
  if (slot >= slot_count_)
    throw std::out_of_range("CpuAtlas: slot " + std::to_string(slot) + " of " +
                            std::to_string(slot_count_));
  return {values_.get() + std::size_t{slot} * slot_values, slot_values};
}

std::span<float> CpuAtlas::slot(std::uint32_t slot) {
  if (slot >= slot_count_)
    throw std::out_of_range("CpuAtlas: slot " + std::to_string(slot) + " of " +
                            std::to_string(slot_count_));
  return {values_.get() + std::size_t{slot} * slot_values, slot_values};
}

void CpuAtlas::store(std::uint32_t slot, std::span<const float> brick) {
  if (brick.size() != slot_values)
    throw std::invalid_argument("CpuAtlas::store: expected " + std::to_string(slot_values) +
                                " values, found " + std::to_string(brick.size()));
  std::ranges::copy(brick, this->slot(slot).begin());
}

void CpuAtlas::decode_into(std::uint32_t slot, std::span<const std::byte> payload,
                           format::Codec codec, double zfp_accuracy, const format::AtomTable& atoms,
                           const std::filesystem::path& name, std::uint64_t offset) {
  format::decode_payload(payload, codec, zfp_accuracy, atoms, this->slot(slot), name, offset);
}

float CpuAtlas::sample(std::uint32_t slot, float x, float y, float z) const {
  constexpr std::uint32_t n = VR_ATLAS_SLOT_SIZE;
  return detail::trilinear(values_.get() + std::size_t{slot} * slot_values, n, n, n, x - 0.5f,
                           y - 0.5f, z - 0.5f);
}

}  // namespace volreel::cpu_render
