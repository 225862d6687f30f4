// container_series.cpp: a container read as a series.
#include "container_series.hpp"

namespace volreel::cli {

bool is_container(const std::filesystem::path& path) {
  return std::filesystem::is_directory(path) && std::filesystem::exists(path / "manifest.json");
}

ContainerSeries::ContainerSeries(const std::filesystem::path& dir)
    : container_(dir), steps_(container_) {
  const auto& m = container_.manifest();
  info_.dims = Dims{m.dims[0], m.dims[1], m.dims[2]};
  info_.frames = m.frames.size();
  info_.spacing = m.spacing;
  info_.timestamps = m.timestamps;
  info_.variable = m.variable;
  info_.source = "volreel container " + dir.string() + " (" +
                 (m.codec == format::Codec::ksvd ? "ksvd" : "zfp") + ")";
}

void ContainerSeries::read_frame(std::size_t t, std::span<float> out) const {
  if (out.size() != info_.dims.voxels()) throw InputError("read_frame: output of the wrong size");
  steps_.decode(t, container_.manifest().levels - 1, out);
}

}  // namespace volreel::cli
