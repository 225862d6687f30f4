// auto_transfer.cpp: a transfer function at quantiles of the data (see auto_transfer.hpp).
#include "volreel/loop/auto_transfer.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "volreel/datasets/volume.hpp"
#include "volreel/format/decoder.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/json_input.hpp"

namespace volreel::loop {

namespace {

/// The frames quantile_transfer tries, from the middle one outwards, before it falls back to the
/// value range alone.
constexpr std::size_t max_frames_sampled = 3;

/// Values of up to `max_bricks` finest-level bricks of frame t, evenly spread.
std::vector<float> finest_brick_values(const format::Container& container, std::size_t t,
                                       std::size_t max_bricks) {
  const format::FrameFile file = container.open_frame_index(t);
  const format::FrameView& view = file.view();
  std::vector<std::uint32_t> bricks;
  for (std::uint32_t i = 0; i < view.node_count(); ++i) {
    const format::Node node = view.node(i);
    if (node.brick != format::no_brick && view.position(i).level + 1 == view.level_count())
      bricks.push_back(node.brick);
  }
  const std::size_t take = std::min(std::max<std::size_t>(max_bricks, 1), bricks.size());
  const format::AtomTable atoms = container.atoms();
  const std::size_t brick_voxels = view.shape().voxels();
  std::vector<float> values(take * brick_voxels);
  for (std::size_t k = 0; k < take; ++k) {
    const std::uint32_t b = bricks[k * bricks.size() / take];
    format::decode_payload(container.read_brick(view, b), view.codec(),
                           view.header().codec_parameter, atoms, view.shape(),
                           {values.data() + k * brick_voxels, brick_voxels}, view.name(),
                           view.brick_offset(b));
  }
  return values;
}

}  // namespace

cpu_render::TransferFunction quantile_transfer(const format::Container& container,
                                               std::size_t max_bricks) {
  const format::Manifest& m = container.manifest();
  const auto lo = static_cast<float>(m.value_min), hi = static_cast<float>(m.value_max);
  if (!(hi > lo)) return cpu_render::TransferFunction::preset("cool-warm", lo, lo + 1);
  // 1. Values of the finest bricks of the middle frame (a sample of them on big volumes); if that
  //    frame is damaged, the nearest readable one of two more (the player reports damaged frames
  //    itself). Over HTTP the middle frame alone: a server that fails its reads (each after its
  //    tries) would fail the next frame's too, and the view waits for this.
  const std::size_t frames = container.frame_count(), middle = frames / 2;
  const std::size_t candidates =
      std::min<std::size_t>(frames, container.source().local_directory() ? max_frames_sampled : 1);
  std::vector<float> values;
  for (std::size_t k = 0; k < candidates && values.empty(); ++k) {
    const std::size_t t = k % 2 == 0 ? middle + k / 2 : middle - (k + 1) / 2;
    if (t >= frames) continue;
    try {
      values = finest_brick_values(container, t, max_bricks);
    } catch (const format::FormatError&) {
      values.clear();
    }
  }
  // 2. Colour and opacity at quantiles of those values, for rays about as long as the volume's
  //    mean side.
  const double path = (double(m.dims[0]) + double(m.dims[1]) + double(m.dims[2])) / 3.0;
  return cpu_render::TransferFunction::from_quantiles(std::move(values), lo, hi, path);
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
  if (!std::filesystem::exists(spec)) {
    std::string names = "auto";
    for (const std::string& p : presets) names += ", " + p;
    const bool path_like = spec.find('/') != std::string::npos || spec.ends_with(".json");
    throw InputError(option + " " + spec +
                     (path_like ? ": no such file (a transfer function is a JSON file or a "
                                  "preset: " +
                                      names + ")"
                                : ": not a preset (" + names + ") nor a JSON file"));
  }
  nlohmann::json json;
  try {
    json = format::read_json_file(spec);
  } catch (const format::FormatError& e) {
    throw InputError(option + " " + e.what());
  }
  return cpu_render::TransferFunction::from_json(json, range, spec);
}

}  // namespace volreel::loop
