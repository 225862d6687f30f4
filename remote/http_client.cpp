// http_client.cpp: libcurl's multi interface on one thread (see http_client.hpp).
#include "volreel/remote/http_client.hpp"

#include <curl/curl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <unordered_map>
#include <utility>

namespace volreel::remote {

namespace {

using detail::iequals_prefix;
using detail::trim;

/// One GET in flight.
struct Transfer {
  std::string url;
  std::uint64_t offset = 0, bytes = 0;  // bytes 0: the whole file
  std::uint64_t limit = 0;              // the most body bytes accepted
  std::promise<HttpResponse> promise;
  std::vector<std::byte> body;
  std::string content_range;
  bool over_limit = false;
  /// The last time a body byte arrived, and whether the transfer was stopped for no byte since
  /// for the stall timeout (on_progress).
  std::chrono::steady_clock::time_point last_byte{};
  double stall_timeout_s = 0;
  bool stalled = false;
  char error[CURL_ERROR_SIZE] = {};
  std::atomic<std::uint64_t>* received = nullptr;
  CURL* easy = nullptr;

  std::string what() const {
    return bytes > 0 ? url + ": bytes " + std::to_string(offset) + "-" +
                           std::to_string(offset + bytes - 1)
                     : url;
  }
};

std::size_t on_body(char* data, std::size_t size, std::size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::size_t n = size * count;
  if (t->body.size() + n > t->limit) {
    t->over_limit = true;
    return 0;  // aborts the transfer (CURLE_WRITE_ERROR)
  }
  const auto* p = reinterpret_cast<const std::byte*>(data);
  t->body.insert(t->body.end(), p, p + n);
  *t->received += n;
  t->last_byte = std::chrono::steady_clock::now();
  return n;
}

/// libcurl's progress callback, called about once a second while nothing arrives: stops a
/// transfer whose body began and then got no byte for the stall timeout. (LOW_SPEED_TIME, which
/// covers the wait before the first byte, follows an average speed over the last seconds, so
/// after a burst it notices a stall seconds late.)
int on_progress(void* user, curl_off_t, curl_off_t, curl_off_t, curl_off_t) {
  auto* t = static_cast<Transfer*>(user);
  if (t->body.empty()) return 0;
  const double idle =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t->last_byte).count();
  if (idle < t->stall_timeout_s) return 0;
  t->stalled = true;
  return 1;  // aborts the transfer (CURLE_ABORTED_BY_CALLBACK)
}

std::size_t on_header(char* data, std::size_t size, std::size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::size_t n = size * count;
  const std::string_view line(data, n);
  if (iequals_prefix(line, "HTTP/")) {
    t->content_range.clear();  // a new response (after a redirect or an interim one)
  } else if (iequals_prefix(line, "content-range:")) {
    t->content_range = std::string(trim(line.substr(14)));
  }
  return n;
}

/// Whether a libcurl failure may go away on its own.
bool transient_failure(CURLcode code) {
  switch (code) {
    case CURLE_UNSUPPORTED_PROTOCOL:
    case CURLE_URL_MALFORMAT:
    case CURLE_NOT_BUILT_IN:
    case CURLE_PEER_FAILED_VERIFICATION:
    case CURLE_SSL_CERTPROBLEM:
    case CURLE_SSL_CACERT_BADFILE:
    case CURLE_TOO_MANY_REDIRECTS:
    case CURLE_WRITE_ERROR:
    case CURLE_OUT_OF_MEMORY:
      return false;
    default:
      return true;
  }
}

/// The stall timeout in whole seconds, rounded up: libcurl's LOW_SPEED_TIME counts seconds, and
/// the progress callback that watches a stalled body runs about once a second.
long stall_seconds(const HttpOptions& o) {
  return std::max(1L, static_cast<long>(std::ceil(o.stall_timeout_s)));
}

/// What a timeout means, from whether this transfer's request went out (on a new or a reused
/// connection): the server never answered the connection (or its TLS handshake), or it stopped
/// sending.
std::string timeout_error(CURL* e, const Transfer& t, const HttpOptions& o) {
  long request_bytes = 0;
  curl_easy_getinfo(e, CURLINFO_REQUEST_SIZE, &request_bytes);
  char text[200];
  if (request_bytes == 0)
    std::snprintf(text, sizeof text,
                  "no connection within %.3g s (connect timeout: the server did not answer the "
                  "connection or its TLS handshake)",
                  o.connect_timeout_s);
  else
    std::snprintf(text, sizeof text,
                  "no byte arrived for %ld s after %zu bytes of the body (stall timeout: the "
                  "server accepted the request, then stopped sending)",
                  stall_seconds(o), t.body.size());
  return text;
}

HttpResponse finish(Transfer& t, CURLcode code, const HttpOptions& o) {
  HttpResponse r;
  long status = 0;
  curl_easy_getinfo(t.easy, CURLINFO_RESPONSE_CODE, &status);
  r.status = status;
  const std::string what = t.what();
  const std::string expected_size = t.bytes > 0 ? std::to_string(t.bytes) + " bytes"
                                                : "at most " + std::to_string(t.limit) + " bytes";
  // A range answered with the whole file (HTTP 200): the body runs past the range first.
  const std::string no_ranges = what +
                                ": expected HTTP 206 (a byte range), found HTTP 200 (the server "
                                "does not serve byte ranges)";
  const long wanted = t.bytes > 0 ? 206 : 200;
  const auto status_error = [&] {
    if (t.bytes > 0 && status == 200)
      r.error = no_ranges;
    else
      r.error = what + ": expected HTTP " + std::to_string(wanted) + ", found HTTP " +
                std::to_string(status) +
                (status == 404   ? " (no such file on the server: check the URL)"
                 : status == 403 ? " (the server refuses to serve it)"
                                 : "");
    r.transient = status == 408 || status == 429 || status >= 500;
  };
  if (code != CURLE_OK) {
    if (t.over_limit) {
      // An error page longer than the bytes asked for ends the transfer too: its status is what
      // went wrong.
      if (status != wanted)
        status_error();
      else
        r.error = what + ": expected " + expected_size + ", found more";
    } else {
      if (code == CURLE_OPERATION_TIMEDOUT || (code == CURLE_ABORTED_BY_CALLBACK && t.stalled)) {
        r.error = what + ": " + timeout_error(t.easy, t, o);
      } else {
        r.error = what + ": " + curl_easy_strerror(code);
        if (t.error[0] != '\0') r.error += std::string(" (") + t.error + ")";
        if (code == CURLE_PEER_FAILED_VERIFICATION && o.ca_file.empty())
          r.error +=
              "; a server whose certificate a centre's own authority signed is trusted with that "
              "authority's PEM file (--ca-file, or ca_file= in Python)";
      }
      r.transient = transient_failure(code);
    }
    return r;
  }
  if (status != wanted) {
    status_error();
    return r;
  }
  if (t.bytes > 0) {
    const auto range = parse_content_range(t.content_range);
    if (!range || range->first != t.offset || range->last != t.offset + t.bytes - 1) {
      r.error = what + ": expected Content-Range bytes " + std::to_string(t.offset) + "-" +
                std::to_string(t.offset + t.bytes - 1) + ", found " +
                (t.content_range.empty() ? std::string("none") : "\"" + t.content_range + "\"");
      return r;
    }
    if (t.body.size() != t.bytes) {
      r.error = what + ": expected " + std::to_string(t.bytes) + " bytes, found " +
                std::to_string(t.body.size()) + " (response truncated)";
      r.transient = true;
      return r;
    }
  }
  r.body = std::move(t.body);
  return r;
}

void global_init() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK)
      throw std::runtime_error("libcurl could not be initialised");
  });
}

}  // namespace

struct HttpClient::Impl {
  CURLM* multi = nullptr;
  std::mutex mutex;
  std::deque<std::unique_ptr<Transfer>> incoming;
  bool stopping = false;
  bool cancelling = false;
  std::unordered_map<CURL*, std::unique_ptr<Transfer>> active;
  std::thread thread;

  void start(Transfer& t, const HttpOptions& o) {
    CURL* e = curl_easy_init();
    if (!e) {
      HttpResponse r;
      r.error = t.what() + ": libcurl could not make a handle";
      r.transient = true;
      t.promise.set_value(std::move(r));
      return;
    }
    t.easy = e;
    curl_easy_setopt(e, CURLOPT_URL, t.url.c_str());
    if (!o.user.empty()) {
      curl_easy_setopt(e, CURLOPT_USERNAME, o.user.c_str());
      curl_easy_setopt(e, CURLOPT_PASSWORD, o.password.c_str());
    }
    curl_easy_setopt(e, CURLOPT_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(e, CURLOPT_REDIR_PROTOCOLS_STR, "http,https");
    curl_easy_setopt(e, CURLOPT_FOLLOWLOCATION, 1L);
    curl_easy_setopt(e, CURLOPT_MAXREDIRS, 5L);
    curl_easy_setopt(e, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(e, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(o.connect_timeout_s * 1e3));
    curl_easy_setopt(e, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(e, CURLOPT_LOW_SPEED_TIME, stall_seconds(o));
    t.stall_timeout_s = static_cast<double>(stall_seconds(o));
    curl_easy_setopt(e, CURLOPT_XFERINFOFUNCTION, on_progress);
    curl_easy_setopt(e, CURLOPT_XFERINFODATA, &t);
    curl_easy_setopt(e, CURLOPT_NOPROGRESS, 0L);
    curl_easy_setopt(e, CURLOPT_HTTP_VERSION, static_cast<long>(CURL_HTTP_VERSION_2TLS));
    curl_easy_setopt(e, CURLOPT_PIPEWAIT, 1L);
    curl_easy_setopt(e, CURLOPT_TCP_KEEPALIVE, 1L);
    curl_easy_setopt(e, CURLOPT_USERAGENT, "volreel");
    if (!o.ca_file.empty()) curl_easy_setopt(e, CURLOPT_CAINFO, o.ca_file.c_str());
    curl_easy_setopt(e, CURLOPT_ERRORBUFFER, t.error);
    curl_easy_setopt(e, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(e, CURLOPT_WRITEDATA, &t);
    curl_easy_setopt(e, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(e, CURLOPT_HEADERDATA, &t);
    std::string range;
    if (t.bytes > 0) {
      range = std::to_string(t.offset) + "-" + std::to_string(t.offset + t.bytes - 1);
      curl_easy_setopt(e, CURLOPT_RANGE, range.c_str());  // copied by libcurl
    }
    curl_multi_add_handle(multi, e);
  }

  /// Fails every transfer in `transfers` with `why`.
  static void fail(std::deque<std::unique_ptr<Transfer>>& transfers, const std::string& why) {
    for (auto& t : transfers) {
      HttpResponse r;
      r.error = t->what() + ": " + why;
      t->promise.set_value(std::move(r));
    }
    transfers.clear();
  }

  /// Fails every transfer that is running with `why`.
  void fail_active(const std::string& why) {
    for (auto& [e, t] : active) {
      curl_multi_remove_handle(multi, e);
      curl_easy_cleanup(e);
      HttpResponse r;
      r.error = t->what() + ": " + why;
      t->promise.set_value(std::move(r));
    }
    active.clear();
  }

  /// Fails every transfer that is running or waiting with `why`.
  void fail_all(const std::string& why) {
    fail_active(why);
    std::deque<std::unique_ptr<Transfer>> waiting;
    {
      std::lock_guard lock(mutex);
      waiting.swap(incoming);
    }
    fail(waiting, why);
  }

  void run(const HttpOptions& o, HttpClient& client) {
    for (;;) {
      std::deque<std::unique_ptr<Transfer>> added;
      bool cancel = false;
      {
        std::lock_guard lock(mutex);
        if (stopping) break;
        added.swap(incoming);
        cancel = std::exchange(cancelling, false);
      }
      // cancel_all() failed what was waiting; what runs now was started before it. What was
      // added since is a later request and runs.
      if (cancel) fail_active("cancelled");
      for (auto& t : added) {
        start(*t, o);
        if (t->easy) active.emplace(t->easy, std::move(t));
      }
      int running = 0;
      curl_multi_perform(multi, &running);
      int left = 0;
      while (CURLMsg* m = curl_multi_info_read(multi, &left)) {
        if (m->msg != CURLMSG_DONE) continue;
        CURL* e = m->easy_handle;
        const CURLcode code = m->data.result;
        const auto it = active.find(e);
        curl_multi_remove_handle(multi, e);
        if (it != active.end()) {
          std::unique_ptr<Transfer> t = std::move(it->second);
          active.erase(it);
          ++client.requests_;
          long version = 0, connects = 0;
          curl_easy_getinfo(e, CURLINFO_HTTP_VERSION, &version);
          curl_easy_getinfo(e, CURLINFO_NUM_CONNECTS, &connects);
          if (version == CURL_HTTP_VERSION_2_0) ++client.http2_responses_;
          client.connections_opened_ += static_cast<std::uint64_t>(std::max(0L, connects));
          t->promise.set_value(finish(*t, code, o));
        }
        curl_easy_cleanup(e);
      }
      curl_multi_poll(multi, nullptr, 0, 1000, nullptr);
    }
    // Closing: what is still running or waiting fails.
    fail_all("the HTTP client was closed");
  }
};

HttpClient::HttpClient(HttpOptions options) : options_(options), impl_(std::make_unique<Impl>()) {
  global_init();
  impl_->multi = curl_multi_init();
  if (!impl_->multi) throw std::runtime_error("libcurl could not make a multi handle");
  curl_multi_setopt(impl_->multi, CURLMOPT_MAX_HOST_CONNECTIONS,
                    static_cast<long>(std::max(1u, options_.max_connections)));
  curl_multi_setopt(impl_->multi, CURLMOPT_PIPELINING, static_cast<long>(CURLPIPE_MULTIPLEX));
  impl_->thread = std::thread([this] { impl_->run(options_, *this); });
}

HttpClient::~HttpClient() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->stopping = true;
  }
  curl_multi_wakeup(impl_->multi);
  impl_->thread.join();
  curl_multi_cleanup(impl_->multi);
}

void HttpClient::cancel_all() {
  // What waits fails here; what runs fails on the client's thread, before anything submitted
  // after this call starts (the flag is read together with the next batch of requests).
  std::deque<std::unique_ptr<Transfer>> waiting;
  {
    std::lock_guard lock(impl_->mutex);
    waiting.swap(impl_->incoming);
    impl_->cancelling = true;
  }
  Impl::fail(waiting, "cancelled");
  curl_multi_wakeup(impl_->multi);
}

std::future<HttpResponse> HttpClient::get(std::string url, std::uint64_t offset,
                                          std::uint64_t bytes) {
  auto t = std::make_unique<Transfer>();
  t->url = std::move(url);
  t->offset = offset;
  t->bytes = bytes;
  t->limit = bytes > 0 ? bytes : options_.max_bytes;
  t->received = &bytes_received_;
  std::future<HttpResponse> f = t->promise.get_future();
  {
    std::lock_guard lock(impl_->mutex);
    if (impl_->stopping) {
      HttpResponse r;
      r.error = t->what() + ": the HTTP client was closed";
      t->promise.set_value(std::move(r));
      return f;
    }
    impl_->incoming.push_back(std::move(t));
  }
  curl_multi_wakeup(impl_->multi);
  return f;
}

}  // namespace volreel::remote
