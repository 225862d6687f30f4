// http_client.hpp: HTTP(S) GETs, whole or by byte range, with libcurl's multi interface on one
// thread: every request of a process shares its connections (kept alive and reused, HTTP/2
// multiplexed where the server offers it over TLS), callers on any thread get a future.
//
// A response is checked before it is handed out: the transfer completed (no connection error, no
// timeout: a connect timeout and a stall timeout — no byte for a while — rather than a total
// one, since a shaped link may be slow), the status is 200 for a whole file or 206 with the
// asked-for Content-Range for a range, and exactly the expected number of bytes arrived. Anything
// else is an error naming the URL, the range, what was expected and what was found, marked
// `transient` when asking again may help (connection refused or reset, timeout, 408, 429, 5xx,
// a short body).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace volreel::remote {

struct HttpOptions {
  double connect_timeout_s = 5;  ///< to establish a connection
  double stall_timeout_s = 20;   ///< a transfer with no byte for this long fails
  unsigned max_connections = 4;  ///< per host (requests beyond it wait for a connection)
  std::uint64_t max_bytes = std::uint64_t{1} << 31;  ///< the largest body accepted
  /// PEM file of the certificate authorities to trust for https (a centre's own CA); empty: the
  /// system's.
  std::string ca_file;
  /// User and password sent with every request (HTTP Basic authentication); an empty user: none.
  /// HttpSource takes them from a URL's user information (take_credentials).
  std::string user, password;
};

struct HttpResponse {
  long status = 0;              ///< HTTP status, 0 if none arrived
  std::vector<std::byte> body;  ///< the bytes, when ok()
  std::string error;            ///< empty on success: "URL: bytes A-B: expected …, found …"
  bool transient = false;       ///< a retry may succeed
  bool ok() const { return error.empty(); }
};

/// A Content-Range value "bytes FIRST-LAST/TOTAL" (TOTAL may be "*"); nullopt if it is not one.
struct ContentRange {
  std::uint64_t first = 0, last = 0;
  std::optional<std::uint64_t> total;
};
std::optional<ContentRange> parse_content_range(std::string_view value);

/// "http://" or "https://" followed by a host: the URL without trailing slashes. Throws
/// std::invalid_argument saying what is wrong (another scheme, no host, spaces or control
/// characters).
std::string check_url(std::string url);
/// The user information of a URL checked by check_url (user and password of
/// "https://user:password@host/...", each percent-decoded), taken out of `url`: what is printed,
/// logged and cached then holds no password. Empty where there is none.
std::pair<std::string, std::string> take_credentials(std::string& url);
/// `location` as messages and files show it: a URL without its user information; a path as is.
std::string without_credentials(std::string location);
/// Whether `location` names a URL (has a "scheme://" prefix) rather than a path.
bool is_url(std::string_view location);

namespace detail {
bool iequals_prefix(std::string_view text, std::string_view prefix);
std::string_view trim(std::string_view s);
bool parse_u64(std::string_view s, std::uint64_t& v);
}  // namespace detail

class HttpClient {
 public:
  explicit HttpClient(HttpOptions options = {});
  /// Fails the transfers still running ("the HTTP client was closed") and stops the thread.
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  /// GET `url`: bytes [offset, offset + bytes) when bytes > 0, else the whole (up to max_bytes).
  std::future<HttpResponse> get(std::string url, std::uint64_t offset = 0, std::uint64_t bytes = 0);

  /// Fails every request waiting or in flight ("cancelled") at once; later requests run as usual.
  void cancel_all();

  /// Requests completed (any outcome) and body bytes received, over the client's life.
  std::uint64_t requests() const { return requests_; }
  std::uint64_t bytes_received() const { return bytes_received_; }
  /// Responses that came over HTTP/2, and connections opened (the rest reused one).
  std::uint64_t http2_responses() const { return http2_responses_; }
  std::uint64_t connections_opened() const { return connections_opened_; }
  const HttpOptions& options() const { return options_; }

 private:
  struct Impl;
  HttpOptions options_;
  std::atomic<std::uint64_t> requests_{0}, bytes_received_{0}, http2_responses_{0},
      connections_opened_{0};
  std::unique_ptr<Impl> impl_;
};

}  // namespace volreel::remote
