// auto_transfer.cpp: a transfer function at quantiles of the data (see auto_transfer.hpp).
#include "volreel/vulkan_render/auto_transfer.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/datasets/volume.hpp"
#include "volreel/format/decoder.hpp"

namespace volreel::vulkan_render {

cpu_render::TransferFunction quantile_transfer(const format::Container& container,
                                               std::size_t max_bricks) {
  const format::Manifest& m = container.manifest();
  const auto lo = static_cast<float>(m.value_min), hi = static_cast<float>(m.value_max);
  if (!(hi > lo)) return cpu_render::TransferFunction::preset("cool-warm", lo, lo + 1);
  // 1. Values of the finest bricks of the middle frame (a sample of them on big volumes).
  const format::FrameFile file = container.open_frame(container.frame_count() / 2);
  const format::FrameView& view = file.view();
  std::vector<std::uint32_t> bricks;
  for (std::uint32_t i = 0; i < view.node_count(); ++i) {
    const format::Node node = view.node(i);
    if (node.brick != format::no_brick && view.position(i).level + 1 == view.level_count())
      bricks.push_back(node.brick);
  }
  if (bricks.empty()) return cpu_render::TransferFunction::preset("cool-warm", lo, hi);
  const std::size_t take = std::min(std::max<std::size_t>(max_bricks, 1), bricks.size());
  const format::AtomTable atoms = container.atoms();
  std::vector<float> values(take * format::brick_voxels);
  for (std::size_t k = 0; k < take; ++k)
    format::decode_brick(view, bricks[k * bricks.size() / take], atoms,
                         {values.data() + k * format::brick_voxels, format::brick_voxels});
  // 2. Quantiles (clamped into the range and made non-decreasing).
  std::sort(values.begin(), values.end());
  const auto q = [&](double p) {
    const auto i = static_cast<std::size_t>(p * static_cast<double>(values.size() - 1));
    return std::clamp(values[i], lo, hi);
  };
  // 3. Colours: Moreland's cool-warm ends, clear in between; opacity per voxel of ray.
  std::vector<cpu_render::ControlPoint> points = {
      {lo, 0.10f, 0.20f, 0.80f, 0.70f},          {q(0.001), 0.15f, 0.35f, 0.95f, 0.45f},
      {q(0.01), 0.35f, 0.65f, 1.00f, 0.12f},     {q(0.04), 0.60f, 0.80f, 1.00f, 0.0f},
      {q(0.96), 1.00f, 0.80f, 0.60f, 0.0f},      {q(0.99), 1.00f, 0.55f, 0.25f, 0.05f},
      {q(0.999), 0.90f, 0.20f, 0.10f, 0.25f},    {hi, 0.70f, 0.02f, 0.15f, 0.50f}};
  for (std::size_t i = 1; i < points.size(); ++i)
    points[i].value = std::max(points[i].value, points[i - 1].value);
  return cpu_render::TransferFunction(points, lo, hi, 256);
}

cpu_render::TransferFunction transfer_from_spec(const std::string& spec,
                                                const format::Container& container,
                                                const std::string& option) {
  const format::Manifest& m = container.manifest();
  const std::array<float, 2> range = {static_cast<float>(m.value_min),
                                      static_cast<float>(m.value_max)};
  if (spec == "auto") return quantile_transfer(container);
  const auto& presets = cpu_render::TransferFunction::preset_names();
  if (std::find(presets.begin(), presets.end(), spec) != presets.end())
    return cpu_render::TransferFunction::preset(spec, range[0], range[1]);
  if (!std::filesystem::is_regular_file(spec)) {
    std::string names = "auto";
    for (const std::string& p : presets) names += ", " + p;
    throw InputError(option + " " + spec + ": not a preset (" + names + ") nor a JSON file");
  }
  std::ifstream in(spec);
  std::stringstream text;
  text << in.rdbuf();
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(text.str());
  } catch (const nlohmann::json::exception& e) {
    throw InputError(option + " " + spec + ": " + e.what());
  }
  return cpu_render::TransferFunction::from_json(json, range, spec);
}

}  // namespace volreel::vulkan_render
