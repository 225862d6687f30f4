// json_input.hpp: JSON documents read from files (manifest.json, series.json, tours, transfer
// functions), parsed with a nesting limit and described in error messages without recursion, so
// that no input, however deep or large, can crash a reader or flood a message.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

namespace volreel::format {

/// The nesting depth a volreel JSON document may have (its own files need 4).
constexpr int max_json_depth = 64;

/// Parses `text`, read from `name`. Throws FormatError naming the file: not valid JSON (with the
/// parser's byte position), nested deeper than max_json_depth, or (allow_bom false) starting with
/// a UTF-8 byte order mark.
nlohmann::json parse_json_document(std::string_view text, const std::filesystem::path& name,
                                   bool allow_bom = true);

/// Reads (open_regular_file's rules, at most 256 MiB) and parses the JSON file `path`.
nlohmann::json read_json_file(const std::filesystem::path& path, bool allow_bom = true);

/// A value for an error message, short and without recursion: numbers, booleans and null as
/// written, strings quoted and cut at 60 characters, arrays and objects by their size
/// ("an array of 3 values", "an object of 2 fields").
std::string describe_json(const nlohmann::json& value);

}  // namespace volreel::format
