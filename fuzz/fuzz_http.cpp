// fuzz_http.cpp: the HTTP text volreel parses from a server or a user — a Content-Range value
// (what a range response claims to hold) and a container URL. Every outcome is a parsed range
// whose numbers agree, nullopt, a checked URL or std::invalid_argument.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <string_view>

#include "volreel/remote/http_client.hpp"

using namespace volreel::remote;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  if (const auto r = parse_content_range(text)) {
    if (r->last < r->first || (r->total && *r->total <= r->last)) std::abort();
  }
  try {
    const std::string url = check_url(text);
    if (!is_url(url) || url.empty() || url.back() == '/') std::abort();
    if (check_url(url) != url) std::abort();  // a checked URL checks again unchanged
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
