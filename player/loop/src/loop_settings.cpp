// loop_settings.cpp: parsing of the frame loop's user settings (see loop_settings.hpp).
#include "volreel/loop/loop_settings.hpp"
#include "volreel/format/error.hpp"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace volreel::loop {
namespace {

[[noreturn]] void bad(const std::string& option, const std::string& expected,
                      const std::string& text) {
  throw std::invalid_argument(option + ": expected " + expected + ", found '" + text + "'");
}

/// The leading number of `text` and the rest (lower case, spaces dropped); false if none.
bool split_number(const std::string& text, double& value, std::string& unit) {
  const char* begin = text.c_str();
  char* end = nullptr;
  value = std::strtod(begin, &end);
  if (end == begin || !std::isfinite(value)) return false;
  unit.clear();
  for (const char* c = end; *c; ++c)
    if (!std::isspace(static_cast<unsigned char>(*c)))
      unit.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(*c))));
  return true;
}

}  // namespace

std::pair<int, int> parse_size(const std::string& text, const std::string& option) {
  const auto x = text.find_first_of("xX");
  const std::string expected = "WIDTHxHEIGHT such as 512x512 (1 to 16384 each)";
  if (x == std::string::npos) bad(option, expected, text);
  char* end = nullptr;
  const long w = std::strtol(text.c_str(), &end, 10);
  if (end != text.c_str() + x) bad(option, expected, text);
  const long h = std::strtol(text.c_str() + x + 1, &end, 10);
  if (*end != '\0' || end == text.c_str() + x + 1) bad(option, expected, text);
  if (w < 1 || h < 1 || w > 16384 || h > 16384) bad(option, expected, text);
  return {static_cast<int>(w), static_cast<int>(h)};
}

double parse_bandwidth(const std::string& text, const std::string& option) {
  double v = 0;
  std::string unit;
  const std::string expected = "a rate such as 20MB/s, 500kB/s or 1GB/s (0: unlimited)";
  if (!split_number(text, v, unit) || v < 0) bad(option, expected, text);
  if (unit.size() >= 2 && unit.substr(unit.size() - 2) == "/s") unit.resize(unit.size() - 2);
  double scale = 0;
  if (unit.empty() || unit == "mb")
    scale = 1e6;
  else if (unit == "b")
    scale = 1;
  else if (unit == "kb")
    scale = 1e3;
  else if (unit == "gb")
    scale = 1e9;
  else if (unit == "kib")
    scale = 1024.0;
  else if (unit == "mib")
    scale = 1048576.0;
  else if (unit == "gib")
    scale = 1073741824.0;
  else
    bad(option, expected, text);
  return v * scale;
}

double parse_latency(const std::string& text, const std::string& option) {
  double v = 0;
  std::string unit;
  const std::string expected = "a duration such as 50ms or 0.2s";
  if (!split_number(text, v, unit) || v < 0) bad(option, expected, text);
  if (unit.empty() || unit == "ms") return v * 1e-3;
  if (unit == "s") return v;
  if (unit == "us") return v * 1e-6;
  bad(option, expected, text);
}

FrameLoopOptions::Decode parse_decode(const std::string& text, const std::string& option) {
  if (text == "auto") return FrameLoopOptions::Decode::automatic;
  if (text == "gpu") return FrameLoopOptions::Decode::gpu;
  if (text == "cpu") return FrameLoopOptions::Decode::cpu;
  bad(option, "auto, gpu or cpu", text);
}

void apply(const LoopSettings& s, FrameLoopOptions& o) {
  if (!s.size.empty()) {
    const auto [w, h] = parse_size(s.size);
    o.width = w;
    o.height = h;
  }
  if (!(s.atlas_mb > 0) || s.atlas_mb > 1e6)
    bad("--atlas-mb", "a size in MiB in (0, 1e6]", format::number_text(s.atlas_mb));
  o.atlas_bytes = static_cast<std::uint64_t>(s.atlas_mb * 1048576.0);
  o.scheduler.loader.bandwidth_bytes_per_s = parse_bandwidth(s.bandwidth);
  o.scheduler.loader.latency_s = parse_latency(s.latency);
  if (!(s.sse_target > 0) || !std::isfinite(s.sse_target))
    bad("--sse-target", "pixels per voxel > 0", format::number_text(s.sse_target));
  o.scheduler.priority.sse_target = s.sse_target;
  if (!(s.upload_budget_mb > 0) || s.upload_budget_mb > 1e6)
    bad("--upload-budget", "a size in MiB in (0, 1e6]", format::number_text(s.upload_budget_mb));
  o.scheduler.upload_budget_bytes = static_cast<std::uint64_t>(s.upload_budget_mb * 1048576.0);
  if (!(s.step > 0) || !std::isfinite(s.step))
    bad("--step", "a ray step in voxels > 0", format::number_text(s.step));
  o.render.step = s.step;
  if (s.max_step_doublings > 16)
    bad("--max-step-doublings", "0..16", std::to_string(s.max_step_doublings));
  o.render.max_step_doublings = s.max_step_doublings;
  o.transfer_culling = !s.no_culling;
  o.gpu.decode = parse_decode(s.decode);
  if (!(s.lod_fade >= 0) || s.lod_fade > 60)
    bad("--lod-fade", "seconds in [0, 60]", format::number_text(s.lod_fade));
  o.scheduler.lod_blend.fade_s = s.lod_fade;
  if (!(s.lod_fade_out >= 0) || s.lod_fade_out > 60)
    bad("--lod-fade-out", "seconds in [0, 60]", format::number_text(s.lod_fade_out));
  o.scheduler.lod_blend.fade_out_s = s.lod_fade_out;
  o.scheduler.lod_blend.spatial = s.spatial_blend;
  o.scheduler.priority.restricted = s.restricted;
  o.scheduler.selection.restricted = s.restricted_drawing;
  o.scheduler.ray_feedback = s.ray_feedback;
}

}  // namespace volreel::loop
