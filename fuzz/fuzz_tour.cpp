// fuzz_tour.cpp: a tour file (`volreel render --tour`), parsed and sampled over its duration. Every
// outcome is an InputError or a valid tour.
#include <cstddef>
#include <cstdint>
#include <string>

#include "volreel/cpu_render/tour.hpp"
#include "volreel/datasets/volume.hpp"

using namespace volreel;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  cpu_render::TourContext context;
  context.dims = {64, 48, 40};
  context.keyframes = 5;
  context.value_range = {-1.0f, 2.0f};
  try {
    const auto tour = cpu_render::Tour::parse(
        std::string(reinterpret_cast<const char*>(data), size), context, "tour.json");
    for (double f : {0.0, 0.37, 1.0}) (void)tour.at(f * tour.duration());
    (void)cpu_render::Tour::from_json(tour.to_json(), context, "tour.json");
  } catch (const InputError&) {
  }
  return 0;
}
