// fuzz_manifest.cpp: manifest.json as it is read, and again with its checksum recomputed so that
// mutations reach the field checks behind it. Every outcome is a FormatError or a valid manifest.
#include <cstddef>
#include <cstdint>
#include <string>

#include "volreel/format/container.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/json_input.hpp"

using namespace volreel::format;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  try {
    manifest_from_json(text, "manifest.json");
  } catch (const FormatError&) {
  }
  try {
    const nlohmann::json j = parse_json_document(text, "manifest.json");
    if (j.is_object()) manifest_from_json(manifest_text(j), "manifest.json");
  } catch (const FormatError&) {
  }
  return 0;
}
