// tour.cpp: parsing, validation, interpolation and the default of volreel's tours (tour.hpp).
#include "volreel/cpu_render/tour.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include "json_fields.hpp"
#include "volreel/datasets/prng.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/json_input.hpp"

namespace volreel::cpu_render {
namespace {

using detail::fail;
using detail::fail_text;
using detail::number;
using detail::number_in;

std::string num(double v) {
  return detail::format_number(v);
}

/// The last key with time ≤ t, interpolated towards the next one; holds outside the keys.
template <class Key, class Lerp>
auto interpolate(const std::vector<Key>& keys, double t, Lerp lerp) {
  const auto next = std::upper_bound(keys.begin(), keys.end(), t,
                                     [](double x, const Key& k) { return x < k.time; });
  if (next == keys.begin()) return lerp(keys.front(), keys.front(), 0.0);
  if (next == keys.end()) return lerp(keys.back(), keys.back(), 0.0);
  const Key& a = *(next - 1);
  const Key& b = *next;  // b.time > t ≥ a.time
  return lerp(a, b, (t - a.time) / (b.time - a.time));
}

/// "t" of a key: in [0, duration] and not before the previous key's.
double key_time(const nlohmann::json& key, double duration, double previous,
                const std::string& where) {
  if (!key.contains("t")) fail_text(where, "missing field \"t\" (seconds)");
  const double t = number_in(key["t"], 0, duration, where + ".t");
  if (t < previous)
    fail(where + ".t", "a time ≥ " + num(previous) + " (the previous key's)", key["t"]);
  return t;
}

const nlohmann::json& array_field(const nlohmann::json& json, const char* field,
                                  const std::string& where) {
  const auto& a = json[field];
  if (!a.is_array() || a.empty()) fail(where + "." + field, "a non-empty array", a);
  return a;
}

CameraKey framing_key(const TourContext& context) {
  const player::OrbitCamera c = player::OrbitCamera::framing(
      glm::dvec3(context.dims[0], context.dims[1], context.dims[2]), 512, 512);
  CameraKey k;
  k.azimuth = glm::degrees(c.azimuth);
  k.elevation = glm::degrees(c.elevation);
  k.distance = c.distance;
  k.target = c.target;
  k.fov = glm::degrees(c.fov_y);
  return k;
}

std::vector<CameraKey> parse_camera(const nlohmann::json& json, double duration,
                                    const TourContext& context, const std::string& where) {
  std::vector<CameraKey> keys;
  CameraKey previous = framing_key(context);
  if (!json.contains("camera")) return {previous};
  const auto& array = array_field(json, "camera", where);
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string at = where + ".camera[" + std::to_string(i) + "]";
    const auto& key = detail::object(array[i], at);
    detail::only_known_keys(key, {"t", "azimuth", "elevation", "distance", "target", "fov"}, at);
    CameraKey k = previous;
    k.time = key_time(key, duration, keys.empty() ? 0.0 : keys.back().time, at);
    if (key.contains("azimuth")) k.azimuth = number(key["azimuth"], at + ".azimuth");
    if (key.contains("elevation")) {
      k.elevation = number(key["elevation"], at + ".elevation");
      if (!(k.elevation > -90 && k.elevation < 90))
        fail(at + ".elevation", "degrees in (-90, 90)", key["elevation"]);
    }
    if (key.contains("distance")) {
      k.distance = number(key["distance"], at + ".distance");
      if (!(k.distance > 0)) fail(at + ".distance", "voxels > 0", key["distance"]);
    }
    if (key.contains("fov")) {
      k.fov = number(key["fov"], at + ".fov");
      if (!(k.fov > 0 && k.fov < 180)) fail(at + ".fov", "degrees in (0, 180)", key["fov"]);
    }
    if (key.contains("target")) {
      const auto& t = key["target"];
      if (!t.is_array() || t.size() != 3) fail(at + ".target", "[x, y, z] in voxels", t);
      for (int a = 0; a < 3; ++a)
        k.target[a] =
            number(t[static_cast<std::size_t>(a)], at + ".target[" + std::to_string(a) + "]");
    }
    keys.push_back(k);
    previous = k;
  }
  return keys;
}

std::vector<PlayheadKey> parse_playhead_keys(const nlohmann::json& json, double duration,
                                             double last, const std::string& where) {
  std::vector<PlayheadKey> keys;
  const auto& array = array_field(json, "playhead", where);
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string at = where + ".playhead[" + std::to_string(i) + "]";
    const auto& key = detail::object(array[i], at);
    detail::only_known_keys(key, {"t", "keyframe"}, at);
    PlayheadKey k;
    k.time = key_time(key, duration, keys.empty() ? 0.0 : keys.back().time, at);
    if (!key.contains("keyframe")) fail_text(at, "missing field \"keyframe\"");
    k.keyframe = number_in(key["keyframe"], 0, last, at + ".keyframe");
    keys.push_back(k);
  }
  return keys;
}

/// Segments -> playhead keys: one key per segment end, one more where play or reverse reaches
/// an end of the timeline and holds there, and a second key at the same time for a seek (a cut).
std::vector<PlayheadKey> parse_segments(const nlohmann::json& json, double last,
                                        const std::string& where) {
  double time = 0, playhead = 0;
  if (json.contains("start")) playhead = number_in(json["start"], 0, last, where + ".start");
  std::vector<PlayheadKey> keys = {{0, playhead}};
  const auto& array = array_field(json, "segments", where);
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string at = where + ".segments[" + std::to_string(i) + "]";
    const auto& seg = detail::object(array[i], at);
    detail::only_known_keys(seg, {"play", "reverse", "pause", "seek", "speed"}, at);
    int kinds = 0;
    for (const char* k : {"play", "reverse", "pause", "seek"}) kinds += seg.contains(k) ? 1 : 0;
    if (kinds != 1)
      fail_text(at, "expected exactly one of \"play\", \"reverse\", \"pause\", \"seek\"");
    if (seg.contains("speed") && !(seg.contains("play") || seg.contains("reverse")))
      fail_text(at, "\"speed\" applies to \"play\" and \"reverse\" only");
    if (seg.contains("seek")) {
      playhead = number_in(seg["seek"], 0, last, at + ".seek");
      keys.push_back({time, playhead});
      continue;
    }
    const char* kind = seg.contains("play")      ? "play"
                       : seg.contains("reverse") ? "reverse"
                                                 : "pause";
    const double seconds = number(seg[kind], at + "." + kind);
    if (!(seconds > 0)) fail(at + "." + kind, "seconds > 0", seg[kind]);
    if (kind == std::string("pause")) {
      time += seconds;
      keys.push_back({time, playhead});
      continue;
    }
    double speed = 1;
    if (seg.contains("speed")) {
      speed = number(seg["speed"], at + ".speed");
      if (!(speed > 0)) fail(at + ".speed", "keyframes per second > 0", seg["speed"]);
    }
    const double direction = kind == std::string("play") ? 1.0 : -1.0;
    const double end = direction > 0 ? last : 0.0;
    const double reach = std::abs(end - playhead) / speed;  // seconds until the timeline's end
    if (reach < seconds) {
      if (reach > 0) keys.push_back({time + reach, end});
      playhead = end;
    } else {
      playhead += direction * speed * seconds;
    }
    time += seconds;
    keys.push_back({time, playhead});
  }
  return keys;
}

std::vector<TransferKey> parse_transfer(const nlohmann::json& json, double duration,
                                        const TourContext& context, const std::string& where) {
  if (!json.contains("transfer"))
    return {
        {0, TransferFunction::preset("cool-warm", context.value_range[0], context.value_range[1])}};
  std::vector<TransferKey> keys;
  const auto& array = array_field(json, "transfer", where);
  for (std::size_t i = 0; i < array.size(); ++i) {
    const std::string at = where + ".transfer[" + std::to_string(i) + "]";
    const auto& key = detail::object(array[i], at);
    TransferKey k;
    k.time = key_time(key, duration, keys.empty() ? 0.0 : keys.back().time, at);
    nlohmann::json rest = key;
    rest.erase("t");
    k.transfer = TransferFunction::from_json(rest, context.value_range, at);
    keys.push_back(std::move(k));
  }
  return keys;
}

}  // namespace

TourContext TourContext::of(const format::Manifest& manifest) {
  TourContext c;
  c.dims = manifest.dims;
  c.keyframes = std::max<std::size_t>(manifest.frames.size(), 1);
  c.value_range = {static_cast<float>(manifest.value_min), static_cast<float>(manifest.value_max)};
  if (!(c.value_range[0] < c.value_range[1]))
    c.value_range = {c.value_range[0] - 0.5f, c.value_range[0] + 0.5f};
  return c;
}

Tour Tour::from_json(const nlohmann::json& json, const TourContext& context,
                     const std::string& name) {
  detail::object(json, name);
  detail::only_known_keys(
      json, {"duration", "fps", "size", "camera", "playhead", "segments", "start", "transfer"},
      name);
  if (context.keyframes < 1) fail_text(name, "the container has no keyframes");
  if (context.dims[0] == 0 || context.dims[1] == 0 || context.dims[2] == 0)
    fail_text(name, "the container's dims are empty");
  if (!(context.value_range[0] < context.value_range[1]))
    fail_text(name, "the container's value range is empty");
  Tour tour;
  if (!json.contains("duration")) fail_text(name, "missing field \"duration\" (seconds)");
  tour.duration_ = number(json["duration"], name + ".duration");
  if (!(tour.duration_ > 0 && tour.duration_ <= 1e6))
    fail(name + ".duration", "seconds in (0, 1e6]", json["duration"]);
  if (json.contains("fps")) {
    tour.fps_ = number(json["fps"], name + ".fps");
    if (!(tour.fps_ > 0 && tour.fps_ <= 1000))
      fail(name + ".fps", "a rate in (0, 1000]", json["fps"]);
  }
  if (json.contains("size")) {
    const auto& s = json["size"];
    if (!s.is_array() || s.size() != 2) fail(name + ".size", "[width, height]", s);
    for (std::size_t a = 0; a < 2; ++a) {
      const std::string at = name + ".size[" + std::to_string(a) + "]";
      const double v = number_in(s[a], 1, 16384, at);
      if (v != std::floor(v)) fail(at, "a whole number of pixels", s[a]);
      (a == 0 ? tour.width_ : tour.height_) = static_cast<int>(v);
    }
  }
  const double last = static_cast<double>(context.keyframes - 1);
  if (json.contains("playhead") && json.contains("segments"))
    fail_text(name, "give either \"playhead\" keys or \"segments\", not both");
  if (json.contains("start") && !json.contains("segments"))
    fail_text(name, "\"start\" applies to \"segments\" only");
  tour.camera_ = parse_camera(json, tour.duration_, context, name);
  if (json.contains("playhead"))
    tour.playhead_ = parse_playhead_keys(json, tour.duration_, last, name);
  else if (json.contains("segments"))
    tour.playhead_ = parse_segments(json, last, name);
  else
    tour.playhead_ = {{0, 0}};
  tour.transfer_ = parse_transfer(json, tour.duration_, context, name);
  return tour;
}

Tour Tour::parse(const std::string& text, const TourContext& context, const std::string& name) {
  nlohmann::json json;
  try {
    json = format::parse_json_document(text, name);
  } catch (const format::FormatError& e) {
    throw InputError(e.what());
  }
  return from_json(json, context, name);
}

Tour Tour::load(const std::filesystem::path& path, const TourContext& context) {
  std::vector<std::byte> bytes;
  try {
    bytes = format::detail::read_whole_file(path, format::detail::max_json_bytes);
  } catch (const format::FormatError& e) {
    throw InputError(std::string(e.what()) + " (the tour file)");
  }
  return parse(std::string(reinterpret_cast<const char*>(bytes.data()), bytes.size()), context,
               path.string());
}

Tour Tour::default_for(const TourContext& context, std::uint64_t seed) {
  const double last = static_cast<double>(std::max<std::size_t>(context.keyframes, 1) - 1);
  SplitMix64 rng(seed);
  const double seek = std::round(rng.uniform(0, last) * 4) / 4;  // quarter keyframes
  const double speed = std::max(last / 4, 0.25);
  nlohmann::json segments = nlohmann::json::array({
      {{"play", 4}, {"speed", speed}},
      {{"reverse", 2}, {"speed", speed}},
      {{"seek", seek}},
      {{"pause", 1}},
      {{"play", 2}, {"speed", 0.25}},
  });
  const CameraKey f = framing_key(context);
  nlohmann::json camera = nlohmann::json::array();
  for (int i = 0; i <= 4; ++i) {
    const double elevation = f.elevation + (i % 2 == 1 ? 12.0 : 0.0) - (i == 2 ? 24.0 : 0.0);
    camera.push_back({{"t", 3.0 * i},
                      {"azimuth", f.azimuth + 90.0 * i},
                      {"elevation", elevation},
                      {"distance", f.distance},
                      {"target", {f.target.x, f.target.y, f.target.z}},
                      {"fov", f.fov}});
  }
  const nlohmann::json json = {
      {"duration", 12},       {"fps", 30},
      {"size", {512, 512}},   {"camera", camera},
      {"segments", segments}, {"transfer", {{{"t", 0}, {"preset", "cool-warm"}}}}};
  return from_json(json, context, "default tour");
}

nlohmann::json Tour::to_json() const {
  nlohmann::json camera = nlohmann::json::array(), playhead = nlohmann::json::array(),
                 transfer = nlohmann::json::array();
  for (const CameraKey& k : camera_)
    camera.push_back({{"t", k.time},
                      {"azimuth", k.azimuth},
                      {"elevation", k.elevation},
                      {"distance", k.distance},
                      {"target", {k.target.x, k.target.y, k.target.z}},
                      {"fov", k.fov}});
  for (const PlayheadKey& k : playhead_)
    playhead.push_back({{"t", k.time}, {"keyframe", k.keyframe}});
  for (const TransferKey& k : transfer_) {
    nlohmann::json j = k.transfer.to_json();
    j["t"] = k.time;
    transfer.push_back(j);
  }
  return {{"duration", duration_}, {"fps", fps_},          {"size", {width_, height_}},
          {"camera", camera},      {"playhead", playhead}, {"transfer", transfer}};
}

std::size_t Tour::frame_count() const {
  // A whole number of frames up to float noise (12 s at 30 fps is 360 frames, not 361).
  return std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(duration_ * fps_ - 1e-9)));
}

TourFrame Tour::at(double seconds) const {
  const double t = std::clamp(seconds, 0.0, duration_);
  TourFrame frame;
  const CameraKey k = interpolate(camera_, t, [](const CameraKey& a, const CameraKey& b, double w) {
    CameraKey c;
    c.time = a.time + (b.time - a.time) * w;
    c.azimuth = a.azimuth + (b.azimuth - a.azimuth) * w;
    c.elevation = a.elevation + (b.elevation - a.elevation) * w;
    c.distance = a.distance + (b.distance - a.distance) * w;
    c.target = a.target + (b.target - a.target) * w;
    c.fov = a.fov + (b.fov - a.fov) * w;
    return c;
  });
  frame.camera.target = k.target;
  frame.camera.distance = k.distance;
  frame.camera.azimuth = glm::radians(k.azimuth);
  frame.camera.elevation = glm::radians(k.elevation);
  frame.camera.fov_y = glm::radians(k.fov);
  frame.camera.width = width_;
  frame.camera.height = height_;
  frame.playhead =
      interpolate(playhead_, t, [](const PlayheadKey& a, const PlayheadKey& b, double w) {
        return a.keyframe + (b.keyframe - a.keyframe) * w;
      });
  frame.transfer =
      interpolate(transfer_, t, [](const TransferKey& a, const TransferKey& b, double w) {
        return TransferFunction::blend(a.transfer, b.transfer, static_cast<float>(w));
      });
  return frame;
}

}  // namespace volreel::cpu_render
