// json_input.cpp: JSON documents with a nesting limit and short descriptions of values.
#include "volreel/format/json_input.hpp"

#include <algorithm>

#include "volreel/format/error.hpp"
#include "volreel/format/file_io.hpp"

namespace volreel::format {

using nlohmann::json;

nlohmann::json parse_json_document(std::string_view text, const std::filesystem::path& name,
                                   bool allow_bom) {
  if (!allow_bom && text.starts_with("\xEF\xBB\xBF"))
    throw FormatError(name, 0, "'{' (a JSON object)", "a UTF-8 byte order mark");
  // The callback sees every value as it is parsed, with its depth: refusing at the limit keeps
  // the document shallow, so that nothing that later walks it (dump, destruction) recurses far.
  const json::parser_callback_t limit = [&](int depth, json::parse_event_t event, json&) {
    if ((event == json::parse_event_t::object_start || event == json::parse_event_t::array_start) &&
        depth >= max_json_depth)
      throw FormatError(name, FormatError::no_offset,
                        "JSON nested at most " + std::to_string(max_json_depth) + " levels deep",
                        "deeper nesting");
    return true;
  };
  try {
    return json::parse(text.begin(), text.end(), limit);
  } catch (const json::exception& e) {
    // A syntax error (parse_error, with its byte) or a number beyond double's range
    // (out_of_range 406). e.what() reads "[json.exception.parse_error.101] parse error at ...".
    const std::string_view what = e.what();
    const std::size_t detail = what.find("] ");
    const auto* syntax = dynamic_cast<const json::parse_error*>(&e);
    const std::string where =
        syntax ? " at byte " + std::to_string(syntax->byte > 0 ? syntax->byte - 1 : 0) : "";
    throw FormatError(
        name, "not valid JSON" + where + ": " +
                  std::string(detail == std::string_view::npos ? what : what.substr(detail + 2)));
  }
}

nlohmann::json read_json_file(const std::filesystem::path& path, bool allow_bom) {
  const auto bytes = detail::read_whole_file(path, detail::max_json_bytes);
  return parse_json_document(
      std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()), path, allow_bom);
}

std::string describe_json(const nlohmann::json& value) {
  switch (value.type()) {
    case json::value_t::null:
      return "null";
    case json::value_t::array: {
      std::string text = "an array of " + std::to_string(value.size()) +
                         (value.size() == 1 ? " value" : " values");
      // A short array of numbers is shown whole: which value was wrong.
      const bool numbers =
          std::all_of(value.begin(), value.end(), [](const json& v) { return v.is_number(); });
      if (numbers && value.size() <= 8) text += ", " + value.dump();
      return text;
    }
    case json::value_t::object:
      return "an object of " + std::to_string(value.size()) +
             (value.size() == 1 ? " field" : " fields");
    case json::value_t::string: {
      const auto& s = value.get_ref<const std::string&>();
      if (s.size() <= 60) return json(s).dump(-1, ' ', false, json::error_handler_t::replace);
      return json(s.substr(0, 60)).dump(-1, ' ', false, json::error_handler_t::replace) +
             " (cut; " + std::to_string(s.size()) + " bytes)";
    }
    default:
      return value.dump();
  }
}

}  // namespace volreel::format
