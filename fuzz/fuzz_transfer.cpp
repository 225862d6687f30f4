// fuzz_transfer.cpp: a transfer function file (`--transfer FILE.json`), parsed as the player reads
// it and written back. Every outcome is an error naming the file or a valid transfer function.
#include <cstddef>
#include <cstdint>
#include <string>

#include "volreel/cpu_render/transfer_function.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/error.hpp"
#include "volreel/format/json_input.hpp"

using namespace volreel;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  try {
    const nlohmann::json j = format::parse_json_document(
        std::string(reinterpret_cast<const char*>(data), size), "transfer.json");
    const auto tf = cpu_render::TransferFunction::from_json(j, {-1.0f, 2.0f}, "transfer.json");
    (void)cpu_render::TransferFunction::from_json(tf.to_json(), {-1.0f, 2.0f}, "transfer.json");
  } catch (const format::FormatError&) {
  } catch (const InputError&) {
  }
  return 0;
}
