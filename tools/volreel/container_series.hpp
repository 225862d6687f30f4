// container_series.hpp: a NAME.vreel container read as a series (frames decoded at full
// resolution by the CPU reference decoder, interpolated nodes as the player draws them), so that
// `compare` and friends accept it.
#pragma once

#include <filesystem>
#include <memory>

#include "volreel/datasets/series.hpp"
#include "volreel/format/container.hpp"
#include "volreel/format/time_step.hpp"

namespace volreel::cli {

/// True if path is a directory holding a manifest.json.
bool is_container(const std::filesystem::path& path);

class ContainerSeries : public datasets::SeriesReader {
 public:
  explicit ContainerSeries(const std::filesystem::path& dir);
  void read_frame(std::size_t t, std::span<float> out) const override;
  using datasets::SeriesReader::read_frame;
  const format::Container& container() const { return container_; }

 private:
  format::Container container_;
  mutable format::TimeStepDecoder steps_;  ///< time steps as the player draws them
};

}  // namespace volreel::cli
