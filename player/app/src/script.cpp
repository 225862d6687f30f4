// script.cpp: parsing of the player's test scripts (script.hpp).
#include "volreel/app/script.hpp"

#include <GLFW/glfw3.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <map>
#include <sstream>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/stream/playhead.hpp"

namespace volreel::app {

namespace {

std::string trim(const std::string& s) {
  std::size_t b = 0, e = s.size();
  while (b < e && std::isspace(static_cast<unsigned char>(s[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(s[e - 1]))) --e;
  return s.substr(b, e - b);
}

/// A finite number, the whole of s (from_chars alone takes "nan" and "inf").
bool parse_double(const std::string& s, double& out) {
  const char* end = s.data() + s.size();
  auto [ptr, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc{} && ptr == end && std::isfinite(out);
}

/// The largest frame number a script may name (far past any container, and exact in a double).
constexpr double max_script_frame = 1e12;

}  // namespace

std::string screenshot_path_problem(const std::string& path) {
  const std::filesystem::path shot = path;
  std::string extension = shot.extension().string();
  for (char& c : extension) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  std::error_code ec;
  if (std::filesystem::is_directory(shot, ec))
    return "is a folder; give the PNG file's name (e.g. " + (shot / "shot.png").string() + ")";
  if (extension != ".png") return "the screenshot is a PNG image; give a name ending in .png";
  const std::filesystem::path folder = shot.has_parent_path() ? shot.parent_path() : ".";
  if (!std::filesystem::is_directory(folder, ec))
    return std::filesystem::exists(folder, ec)
               ? folder.string() + " is not a folder; give the PNG a name in a folder"
               : "the folder " + folder.string() + " does not exist; make it first";
  return "";
}

int key_code(const std::string& name) {
  static const std::map<std::string, int> named = {
      {"space", GLFW_KEY_SPACE},     {"left", GLFW_KEY_LEFT},     {"right", GLFW_KEY_RIGHT},
      {"up", GLFW_KEY_UP},           {"down", GLFW_KEY_DOWN},     {"home", GLFW_KEY_HOME},
      {"end", GLFW_KEY_END},         {"escape", GLFW_KEY_ESCAPE}, {"[", GLFW_KEY_LEFT_BRACKET},
      {"]", GLFW_KEY_RIGHT_BRACKET}, {"enter", GLFW_KEY_ENTER},   {"tab", GLFW_KEY_TAB}};
  if (auto it = named.find(name); it != named.end()) return it->second;
  if (name.size() == 1) {
    const char c = static_cast<char>(std::toupper(static_cast<unsigned char>(name[0])));
    if (c >= 'A' && c <= 'Z') return GLFW_KEY_A + (c - 'A');
    if (c >= '0' && c <= '9') return GLFW_KEY_0 + (c - '0');
  }
  return -1;
}

std::vector<ScriptAction> parse_script(const std::string& text) {
  std::vector<ScriptAction> actions;
  std::stringstream all(text);
  std::vector<std::string> entries;
  for (std::string line; std::getline(all, line);) {
    if (auto hash = line.find('#'); hash != std::string::npos) line.resize(hash);
    std::stringstream parts(line);
    for (std::string part; std::getline(parts, part, ';');) {
      part = trim(part);
      if (!part.empty()) entries.push_back(part);
    }
  }
  using Kind = ScriptAction::Kind;
  static const std::map<std::string, std::pair<Kind, int>> kinds = {
      // action name → kind, argument count (-1: optional one)
      {"key", {Kind::key, 1}},           {"seek", {Kind::seek, 1}},
      {"speed", {Kind::speed, 1}},       {"play", {Kind::play, 0}},
      {"pause", {Kind::pause, 0}},       {"reverse", {Kind::reverse, 0}},
      {"orbit", {Kind::orbit, 2}},       {"zoom", {Kind::zoom, 1}},
      {"transfer", {Kind::transfer, 1}}, {"sse", {Kind::sse, 1}},
      {"settle", {Kind::settle, -1}},    {"screenshot", {Kind::screenshot, 1}},
      {"resize", {Kind::resize, 2}},     {"camera", {Kind::camera, 0}},
      {"layout", {Kind::layout, 0}},     {"quit", {Kind::quit, 0}}};
  for (const std::string& e : entries) {
    const auto fail = [&](const std::string& why) {
      throw InputError("script entry '" + e + "': " + why);
    };
    std::stringstream words(e);
    std::vector<std::string> w;
    for (std::string s; words >> s;) w.push_back(s);
    if (w.size() < 2) fail("expected WHEN ACTION [ARGS]");
    ScriptAction a;
    a.source = e;
    std::string when = w[0];
    if (!when.empty() && when[0] == '+') {
      a.relative = true;
      when.erase(0, 1);
    }
    double value = 0;
    const auto bad_when = [&] {
      fail(
          "expected when, a time in seconds like '0.5' or a frame number like '12f' (either "
          "after '+' for one relative to the entry before), found '" +
          w[0] + "'");
    };
    if (!when.empty() && when.back() == 'f') {
      if (!parse_double(when.substr(0, when.size() - 1), value) || value < 0 ||
          value > max_script_frame)
        bad_when();
      a.at_frame = static_cast<std::int64_t>(value);
    } else {
      if (!when.empty() && when.back() == 's') when.pop_back();
      if (!parse_double(when, value) || value < 0) bad_when();
      a.at_seconds = value;
    }
    const auto k = kinds.find(w[1]);
    if (k == kinds.end()) fail("unknown action '" + w[1] + "'");
    a.kind = k->second.first;
    const int want = k->second.second;
    const auto args = static_cast<int>(w.size()) - 2;
    if (want >= 0 && args != want)
      fail("'" + w[1] + "' takes " + std::to_string(want) + " argument(s), found " +
           std::to_string(args));
    if (want < 0 && args > 1) fail("'" + w[1] + "' takes at most one argument");
    switch (a.kind) {
      case Kind::key:
        a.text = w[2];
        if (key_code(a.text) < 0) fail("unknown key '" + a.text + "'");
        break;
      case Kind::transfer: {
        a.text = w[2];
        const auto& names = cpu_render::TransferFunction::preset_names();
        if (std::find(names.begin(), names.end(), a.text) == names.end()) {
          std::string list;
          for (const std::string& n : names) list += (list.empty() ? "" : ", ") + n;
          fail("unknown transfer-function preset '" + a.text + "' (presets: " + list + ")");
        }
        break;
      }
      case Kind::screenshot:
        a.text = w[2];
        if (const std::string problem = screenshot_path_problem(a.text); !problem.empty())
          fail(a.text + ": " + problem);
        break;
      case Kind::orbit:
        if (!parse_double(w[2], a.x) || !parse_double(w[3], a.y))
          fail("expected two finite numbers (degrees)");
        break;
      case Kind::resize:
        if (!parse_double(w[2], a.x) || !parse_double(w[3], a.y) || a.x < 1 || a.y < 1 ||
            a.x > 16384 || a.y > 16384)
          fail("expected a width and a height in 1..16384");
        break;
      case Kind::settle:
        a.x = 20;
        if (args == 1 && (!parse_double(w[2], a.x) || a.x < 0))
          fail("expected a timeout in seconds >= 0, found '" + w[2] + "'");
        break;
      case Kind::seek:
      case Kind::speed:
      case Kind::zoom:
      case Kind::sse:
        if (!parse_double(w[2], a.x)) fail("expected a finite number, found '" + w[2] + "'");
        if ((a.kind == Kind::zoom || a.kind == Kind::sse) && a.x <= 0)
          fail("expected a positive number");
        if (a.kind == Kind::seek && a.x < 0)
          fail("expected a playhead >= 0 (keyframe units; past the last it stops at the last)");
        if (a.kind == Kind::speed &&
            !(a.x >= stream::Playhead::min_speed && a.x <= stream::Playhead::max_speed))
          fail("expected a speed in 0.25..8 (keyframes a second), found '" + w[2] + "'");
        break;
      default:
        break;
    }
    actions.push_back(std::move(a));
  }
  return actions;
}

}  // namespace volreel::app
