// http_text.cpp: the text of HTTP that volreel parses — Content-Range values and URLs (no
// libcurl here, so that the fuzz harness reaches it alone).
#include <algorithm>
#include <cctype>
#include <charconv>
#include <stdexcept>

#include "volreel/remote/http_client.hpp"

namespace volreel::remote {

namespace detail {

bool iequals_prefix(std::string_view text, std::string_view prefix) {
  if (text.size() < prefix.size()) return false;
  for (std::size_t i = 0; i < prefix.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(text[i])) !=
        std::tolower(static_cast<unsigned char>(prefix[i])))
      return false;
  return true;
}

std::string_view trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() &&
         (s.back() == ' ' || s.back() == '\t' || s.back() == '\r' || s.back() == '\n'))
    s.remove_suffix(1);
  return s;
}

bool parse_u64(std::string_view s, std::uint64_t& v) {
  if (s.empty() || s.size() > 20) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  return ec == std::errc() && end == s.data() + s.size();
}

}  // namespace detail

using detail::iequals_prefix;
using detail::parse_u64;
using detail::trim;

std::optional<ContentRange> parse_content_range(std::string_view value) {
  value = trim(value);
  if (!iequals_prefix(value, "bytes ")) return std::nullopt;
  value = trim(value.substr(6));
  const std::size_t dash = value.find('-'), slash = value.find('/');
  if (dash == std::string_view::npos || slash == std::string_view::npos || dash > slash)
    return std::nullopt;
  ContentRange r;
  if (!parse_u64(value.substr(0, dash), r.first) ||
      !parse_u64(value.substr(dash + 1, slash - dash - 1), r.last) || r.last < r.first)
    return std::nullopt;
  const std::string_view total = value.substr(slash + 1);
  if (total != "*") {
    std::uint64_t v = 0;
    if (!parse_u64(total, v) || v <= r.last) return std::nullopt;
    r.total = v;
  }
  return r;
}

bool is_url(std::string_view location) {
  const std::size_t colon = location.find("://");
  if (colon == std::string_view::npos || colon == 0) return false;
  return std::all_of(
      location.begin(), location.begin() + static_cast<std::ptrdiff_t>(colon), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || c == '+' || c == '-' || c == '.';
      });
}

std::string check_url(std::string url) {
  // Messages name the URL without a password it may hold.
  const std::string shown = without_credentials(url);
  const std::size_t colon = url.find("://");
  if (!is_url(url))
    throw std::invalid_argument(shown + ": not a URL (expected http:// or https://)");
  std::string scheme = url.substr(0, colon);
  std::transform(scheme.begin(), scheme.end(), scheme.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (scheme != "http" && scheme != "https")
    throw std::invalid_argument(shown + ": unsupported scheme \"" + scheme +
                                "://\" (volreel reads http:// and https:// URLs, or local paths)");
  for (const char c : url)
    if (static_cast<unsigned char>(c) <= 0x20 || c == 0x7f)
      throw std::invalid_argument(shown + ": a URL may not hold spaces or control characters " +
                                  "(percent-encode them)");
  if (url.find_first_of("?#") != std::string::npos)
    throw std::invalid_argument(shown + ": a container URL names its folder; query strings and " +
                                "fragments are not supported");
  while (url.size() > colon + 3 && url.back() == '/') url.pop_back();
  const std::size_t host_end = url.find('/', colon + 3);
  if (url.substr(colon + 3, host_end - colon - 3).empty())
    throw std::invalid_argument(shown + ": no host");
  return scheme + url.substr(colon);
}

std::string without_credentials(std::string location) {
  if (is_url(location)) take_credentials(location);
  return location;
}

std::pair<std::string, std::string> take_credentials(std::string& url) {
  if (url.find("://") == std::string::npos) return {};
  const std::size_t authority = url.find("://") + 3;
  const std::size_t end = std::min(url.find('/', authority), url.size());
  const std::size_t at = url.rfind('@', end - 1);
  if (at == std::string::npos || at < authority) return {};
  const std::string info = url.substr(authority, at - authority);
  url.erase(authority, at + 1 - authority);
  const auto decode = [](std::string_view encoded) {
    const auto hex = [](char c) {
      return std::isdigit(static_cast<unsigned char>(c))
                 ? c - '0'
                 : std::tolower(static_cast<unsigned char>(c)) - 'a' + 10;
    };
    std::string decoded;
    for (std::size_t i = 0; i < encoded.size(); ++i) {
      if (encoded[i] == '%' && i + 2 < encoded.size() &&
          std::isxdigit(static_cast<unsigned char>(encoded[i + 1])) &&
          std::isxdigit(static_cast<unsigned char>(encoded[i + 2]))) {
        decoded += static_cast<char>(16 * hex(encoded[i + 1]) + hex(encoded[i + 2]));
        i += 2;
      } else {
        decoded += encoded[i];
      }
    }
    return decoded;
  };
  // The user ends at the first ':' as written (one in a name is percent-encoded).
  const std::size_t colon = info.find(':');
  return {decode(std::string_view(info).substr(0, colon)),
          colon == std::string::npos ? std::string() : decode(info.substr(colon + 1))};
}

}  // namespace volreel::remote
