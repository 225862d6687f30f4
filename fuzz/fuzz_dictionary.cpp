// fuzz_dictionary.cpp: a dictionary file, with its trailing CRC recomputed so that mutations reach
// the checks behind it. Every outcome is a FormatError or a valid dictionary.
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#include "volreel/format/crc32c.hpp"
#include "volreel/format/dictionary_file.hpp"
#include "volreel/format/error.hpp"

using namespace volreel::format;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  std::vector<std::byte> bytes(size);
  if (size > 0) std::memcpy(bytes.data(), data, size);
  if (size >= 4) {
    const std::uint32_t crc = crc32c(std::span<const std::byte>(bytes).first(size - 4));
    std::memcpy(bytes.data() + size - 4, &crc, 4);
  }
  try {
    const DictionaryFile d = parse_dictionary_file(bytes, "dictionary.bin");
    (void)serialize_dictionary_file(d);
  } catch (const FormatError&) {
  }
  return 0;
}
