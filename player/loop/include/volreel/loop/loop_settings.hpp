// loop_settings.hpp: the streaming settings a user gives the programs that drive the frame loop
// (`volreel render`, `volreel bench play`, a windowed player) as text — "512x512", "20MB/s",
// "50ms" — parsed into FrameLoopOptions with errors that name the option and the text.
#pragma once

#include <cstdint>
#include <string>
#include <utility>

#include "volreel/loop/frame_loop.hpp"

namespace volreel::loop {

struct LoopSettings {
  std::string size;              ///< "WxH" (empty: keep the options' size)
  double atlas_mb = 256;         ///< atlas memory, MiB (16-bit voxels: S³·2 bytes per slot)
  std::string bandwidth = "0";   ///< "20MB/s", "500kB/s", "1GB/s", a number (MB/s); 0: unlimited
  std::string latency = "0";     ///< "50ms", "0.2s", a number (ms)
  double sse_target = 1.0;       ///< pixels per voxel at which a node is detailed enough
  double upload_budget_mb = 64;  ///< compressed bytes uploaded per frame at most, MiB
  double step = 0.5;             ///< ray step, finest voxels
  /// Coarse leaves step up to 2^this times longer (0: a fixed step).
  std::uint32_t max_step_doublings = 3;
  bool no_culling = false;      ///< no transfer-function culling
  std::string decode = "auto";  ///< "auto", "gpu" or "cpu" (FrameLoopOptions::Decode)
  /// Level-of-detail blending (stream::LodBlendSettings): the fades' seconds (in, out), spatial
  /// blending.
  double lod_fade = stream::LodBlendSettings{}.fade_s;
  double lod_fade_out = stream::LodBlendSettings{}.fade_out_s;
  bool spatial_blend = stream::LodBlendSettings{}.spatial;
  /// A restricted working set (stream::PrioritySettings::restricted).
  bool restricted = stream::PrioritySettings{}.restricted;
  /// Restricted drawing (stream::SelectionSettings::restricted).
  bool restricted_drawing = stream::SelectionSettings{}.restricted;
  /// Ray-guided feedback (stream::SchedulerSettings::ray_feedback).
  bool ray_feedback = stream::SchedulerSettings{}.ray_feedback;
};

/// "512x512" -> {512, 512} (1..16384 each). Throws std::invalid_argument naming `option`.
std::pair<int, int> parse_size(const std::string& text, const std::string& option = "--size");
/// "20MB/s" (also kB/s, GB/s, B/s, MiB/s; a bare number is MB/s) -> bytes per second (≥ 0).
double parse_bandwidth(const std::string& text, const std::string& option = "--bandwidth");
/// "auto", "gpu", "cpu" -> FrameLoopOptions::Decode. Throws std::invalid_argument naming `option`.
FrameLoopOptions::Decode parse_decode(const std::string& text,
                                      const std::string& option = "--decode");
/// "50ms", "0.2s", a bare number in ms -> seconds (≥ 0).
double parse_latency(const std::string& text, const std::string& option = "--latency");

/// Applies the settings to `options` (size, atlas, loader, SSE target, upload budget, step,
/// culling, level-of-detail blending, ray-guided feedback). Throws std::invalid_argument naming the
/// option on a bad value.
void apply(const LoopSettings& settings, FrameLoopOptions& options);

}  // namespace volreel::loop
