// cmd_info.cpp: `volreel info` — describe a NAME.vreel container: the volume, the codec and its
// parameters, the share of node-steps that store a brick (keyframes), the levels of frame 0, the
// size and bps; or all of it as JSON.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "remote_options.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/container.hpp"

namespace volreel::cli {

namespace {

void run_info(const std::string& dir, bool json, const RemoteCli& remote) {
  const format::Container c(open_container_source(dir, remote), true);
  const auto& m = c.manifest();
  const double voxels = static_cast<double>(m.dims[0]) * m.dims[1] * m.dims[2];
  std::size_t written = 0;
  for (const auto& f : m.frames) written += f ? 1u : 0u;
  const std::uint64_t bytes = c.total_bytes();
  // bps over the frames written; none written yet (an interrupted encode's start): no figure.
  const double bps =
      written > 0 ? 8.0 * static_cast<double>(bytes) / (voxels * static_cast<double>(written))
                  : std::nan("");
  // Keyframes: the nodes of the frames' trees that store a brick at their step. A frame whose
  // index cannot be read is left out of the figures; the first such error ends the command after
  // they are printed (volreel verify lists them all).
  std::uint64_t nodes = 0, bricks = 0;
  std::size_t unreadable = 0;
  std::string first_error;
  nlohmann::json levels = nlohmann::json::array();
  std::vector<std::size_t> written_frames;
  for (std::size_t t = 0; t < m.frames.size(); ++t)
    if (m.frames[t]) written_frames.push_back(t);
  format::for_each_frame_index(
      c, written_frames, [&](std::size_t t, const format::FrameFile* f, const std::string& error) {
        if (!f) {
          if (unreadable++ == 0) first_error = error;
          return;
        }
        nodes += f->view().node_count();
        bricks += f->view().brick_count();
        for (std::uint32_t l = 0; t == 0 && l < f->view().level_count(); ++l) {
          const auto& e = f->view().level(l);
          levels.push_back({{"level", l},
                            {"dims", e.dims},
                            {"grid", e.grid},
                            {"nodes", e.node_count},
                            {"payload_bytes", f->view().payload_end_for_depth(l + 1) -
                                                  f->view().payload_end_for_depth(l)}});
        }
      });
  const auto end_with_unreadable = [&] {
    if (unreadable > 0)
      throw InputError(std::to_string(unreadable) + " of the " + std::to_string(written) +
                       " frames written could not be read, left out of the figures above (volreel "
                       "verify lists every problem); the first: " +
                       first_error);
  };
  const double kept = nodes > 0 ? static_cast<double>(bricks) / static_cast<double>(nodes) : 1.0;
  if (json) {
    nlohmann::json j = format::manifest_to_json(m);
    j["node_steps"] = nodes;
    j["bricks_stored"] = bricks;
    j["total_bytes"] = bytes;
    j["bps"] = std::isfinite(bps) ? nlohmann::json(bps) : nlohmann::json(nullptr);
    j["frames_unreadable"] = unreadable;
    j["frames_written"] = written;
    j["frame0_levels"] = levels;
    std::cout << j.dump(2) << '\n';
    end_with_unreadable();
    return;
  }
  std::printf("%s: volreel container, format version %u, written by volreel %s%s\n",
              remote::without_credentials(dir).c_str(), m.format_version, m.program_version.c_str(),
              m.complete ? "" : " (INCOMPLETE: resume with volreel encode --resume)");
  std::printf("volume   %ux%ux%u, spacing %g %g %g, variable '%s', %zu frames (%zu written)\n",
              m.dims[0], m.dims[1], m.dims[2], m.spacing[0], m.spacing[1], m.spacing[2],
              m.variable.c_str(), m.frames.size(), written);
  std::printf("octree   %u levels, bricks of %u^3 (%u interior + %u apron)\n", m.levels,
              m.brick_size, m.brick_size - 2 * m.brick_apron, m.brick_apron);
  if (m.codec == format::Codec::ksvd) {
    std::printf("codec    ksvd (sparse coding, blocks of %u^3), ", m.block_size);
    if (m.fixed_sparsity)
      std::printf("fixed rate S = %u\n", m.fixed_sparsity);
    else
      std::printf("variable rate, eps = %.6g\n", m.tolerance);
    // The DCT basis's M³ − 1 atoms follow the learned ones where the dictionary has them.
    const std::uint32_t dct =
        c.atoms().dct_basis ? m.block_size * m.block_size * m.block_size - 1 : 0;
    if (dct > 0 && m.dictionary->atom_count > dct)
      std::printf("dictionary %s: %u atoms (%u learned and the %u of the DCT basis), %ju bytes\n",
                  m.dictionary->file.c_str(), m.dictionary->atom_count,
                  m.dictionary->atom_count - dct, dct,
                  static_cast<std::uintmax_t>(m.dictionary->bytes));
    else if (dct > 0)
      std::printf("dictionary %s: the DCT basis alone (%u atoms), %ju bytes\n",
                  m.dictionary->file.c_str(), m.dictionary->atom_count,
                  static_cast<std::uintmax_t>(m.dictionary->bytes));
    else
      std::printf("dictionary %s: %u atoms, %ju bytes\n", m.dictionary->file.c_str(),
                  m.dictionary->atom_count, static_cast<std::uintmax_t>(m.dictionary->bytes));
  } else {
    std::printf("codec    zfp fixed accuracy %.6g\n", m.zfp_accuracy);
  }
  std::printf("values   [%.6g, %.6g]\n", m.value_min, m.value_max);
  if (nodes > 0)
    std::printf(
        "keyframes max gap %u time steps; %ju of %ju node-steps store a brick (%.1f %%)%s\n",
        m.max_keyframe_gap, static_cast<std::uintmax_t>(bricks), static_cast<std::uintmax_t>(nodes),
        100.0 * kept, bricks < nodes ? ", the rest are interpolated" : "");
  else
    std::printf("keyframes max gap %u time steps (no frame index read)\n", m.max_keyframe_gap);
  if (written > 0)
    std::printf("size     %ju bytes, %.4f bps (all files, over the %zu frames written)\n",
                static_cast<std::uintmax_t>(bytes), bps, written);
  else
    std::printf("size     %ju bytes (no frame written yet)\n", static_cast<std::uintmax_t>(bytes));
  for (const auto& l : levels)
    std::printf("frame 0 level %d: %s voxels, %d nodes, %ju payload bytes\n", l["level"].get<int>(),
                l["dims"].dump().c_str(), l["nodes"].get<int>(),
                static_cast<std::uintmax_t>(l["payload_bytes"].get<std::uint64_t>()));
  print_remote_summary(c.source(), "info");
  end_with_unreadable();
}

}  // namespace

void add_info_command(CLI::App& app) {
  auto info_dir = std::make_shared<std::string>();
  auto info_json = std::make_shared<bool>(false);
  CLI::App* info = app.add_subcommand(
      "info", "Describe a NAME.vreel container: volume, codec, levels, sizes and bps");
  auto remote = std::make_shared<RemoteCli>();
  info->add_option("CONTAINER", *info_dir, container_argument_help)->required();
  info->add_flag("--json", *info_json, "Print JSON (the manifest plus totals)");
  add_remote_options(*info, *remote);
  info->callback([info_dir, info_json, remote] { run_info(*info_dir, *info_json, *remote); });
}

}  // namespace volreel::cli
