// json_fields.hpp (private to volreel::cpu_render): reading typed fields of the transfer-function
// and tour JSON with errors that name the field, what was expected and what was found.
#pragma once

#include <cmath>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "volreel/datasets/volume.hpp"

namespace volreel::cpu_render::detail {

/// A short rendering of a JSON value for error messages ("\"abc\"", "[1,2]", "null").
inline std::string shown(const nlohmann::json& value) {
  std::string text = value.dump();
  if (text.size() > 60) text = text.substr(0, 57) + "...";
  return text;
}

[[noreturn]] inline void fail(const std::string& where, const std::string& expected,
                              const nlohmann::json& found) {
  throw InputError(where + ": expected " + expected + ", found " + shown(found));
}
[[noreturn]] inline void fail_text(const std::string& where, const std::string& what) {
  throw InputError(where + ": " + what);
}

inline const nlohmann::json& object(const nlohmann::json& json, const std::string& where) {
  if (!json.is_object()) fail(where, "a JSON object", json);
  return json;
}

/// A number as people write it: 3, 4.5, 1e-06 (no trailing ".0").
inline std::string format_number(double v) {
  std::ostringstream out;
  out.precision(15);
  out << v;
  return out.str();
}

/// A finite number.
inline double number(const nlohmann::json& value, const std::string& where) {
  if (!value.is_number()) fail(where, "a number", value);
  const double v = value.get<double>();
  if (!std::isfinite(v)) fail(where, "a finite number", value);
  return v;
}

/// A finite number in [lo, hi].
inline double number_in(const nlohmann::json& value, double lo, double hi,
                        const std::string& where) {
  const double v = number(value, where);
  if (!(v >= lo && v <= hi))
    fail(where, "a number in [" + format_number(lo) + ", " + format_number(hi) + "]", value);
  return v;
}

/// Fails on keys of `json` not in `known` (catches misspelt fields).
inline void only_known_keys(const nlohmann::json& json, std::initializer_list<const char*> known,
                            const std::string& where) {
  for (const auto& item : json.items()) {
    bool ok = false;
    for (const char* k : known) ok = ok || item.key() == k;
    if (!ok) {
      std::string list;
      for (const char* k : known) list += std::string(list.empty() ? "" : ", ") + "\"" + k + "\"";
      fail_text(where, "unknown field \"" + item.key() + "\" (known: " + list + ")");
    }
  }
}

}  // namespace volreel::cpu_render::detail
