// leak_probe.cpp: a Vulkan program for the leak-check test. It creates a volreel Vulkan context
// (which loads the driver and, where installed, the validation layer), decodes nothing, releases
// it and exits; with --leak it first leaves one allocation of its own unreleased, so that a
// LeakSanitizer build must report exactly that allocation and fail.
// Exit codes: 0 done, 77 no Vulkan device (the test skips), 2 bad arguments or Vulkan error.
#include <cstdio>
#include <cstring>
#include <exception>

#include "volreel/vulkan/context.hpp"

namespace {

constexpr std::size_t leaked_bytes = 4321;  // a size no Vulkan implementation allocates by chance

// Not inlined, so that the leak report names this function.
[[gnu::noinline]] void leak_on_purpose() {
  char* block = new char[leaked_bytes];
  std::memset(block, 0x5a, leaked_bytes);
  std::printf("leak_probe: left %zu bytes at %p unreleased\n", leaked_bytes,
              static_cast<void*>(block));
}

}  // namespace

int main(int argc, char** argv) {
  const bool leak = argc == 2 && std::strcmp(argv[1], "--leak") == 0;
  if (argc > 2 || (argc == 2 && !leak)) {
    std::fprintf(stderr, "usage: leak_probe [--leak]\n");
    return 2;
  }
  try {
    volreel::vulkan::ContextOptions options;
    options.application_name = "volreel leak_probe";
    const volreel::vulkan::Context context(options);
    std::printf("leak_probe: %s\n", context.describe().c_str());
  } catch (const volreel::vulkan::NoDeviceError& e) {
    std::printf("leak_probe: no Vulkan device: %s\n", e.what());
    return 77;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "leak_probe: %s\n", e.what());
    return 2;
  }
  if (leak) leak_on_purpose();
  return 0;
}
