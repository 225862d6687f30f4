// http_source.cpp: a container read over HTTP(S) (see http_source.hpp).
#include "volreel/remote/http_source.hpp"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <thread>

#include <nlohmann/json.hpp>

#include "volreel/format/container.hpp"
#include "volreel/format/error.hpp"

namespace volreel::remote {

namespace fs = std::filesystem;

HttpSource::HttpSource(std::string url, RemoteOptions options)
    : url_(check_url(std::move(url))), options_(std::move(options)) {
  // A password in the URL goes to the server with each request, never into a message or the
  // cache's keys.
  if (auto [user, password] = take_credentials(url_); !user.empty()) {
    options_.http.user = std::move(user);
    options_.http.password = std::move(password);
  }
  client_ = std::make_unique<HttpClient>(options_.http);
  if (!options_.cache_dir.empty())
    cache_ = std::make_unique<DiskCache>(options_.cache_dir, options_.cache_bytes);
}

fs::path HttpSource::name(const std::string& relative) const {
  return url_ + "/" + relative;
}

std::string HttpSource::relative_of(const fs::path& file) const {
  const std::string s = file.string();
  if (s.size() <= url_.size() + 1 || s.compare(0, url_.size(), url_) != 0 || s[url_.size()] != '/')
    return {};
  const std::string relative = s.substr(url_.size() + 1);
  std::lock_guard lock(mutex_);
  return tags_.count(relative) ? relative : std::string();
}

void HttpSource::learn_manifest(std::span<const std::byte> bytes) const {
  const auto j = nlohmann::json::parse(reinterpret_cast<const char*>(bytes.data()),
                                       reinterpret_cast<const char*>(bytes.data()) + bytes.size(),
                                       nullptr, false);
  if (!j.is_object() || !j.contains("container_id")) return;  // the reader says what is wrong
  std::map<std::string, FileTag> tags;
  const std::string id = j["container_id"].dump();
  const auto add = [&](const nlohmann::json& f) {
    if (f.is_object() && f.contains("file") && f["file"].is_string() && f.contains("crc32c") &&
        f["crc32c"].is_number_unsigned() && f.contains("bytes") && f["bytes"].is_number_unsigned())
      tags[f["file"].get<std::string>()] = {id + "/" + f["crc32c"].dump(),
                                            f["bytes"].get<std::uint64_t>(),
                                            f["crc32c"].get<std::uint32_t>()};
  };
  if (j.contains("dictionary")) add(j["dictionary"]);
  if (j.contains("frames") && j["frames"].is_array())
    for (const auto& f : j["frames"]) add(f);
  std::lock_guard lock(mutex_);
  tags_ = std::move(tags);
}

std::string HttpSource::cache_key(const std::string& relative, std::uint64_t offset,
                                  const std::string& bytes) const {
  if (!cache_) return {};
  std::lock_guard lock(mutex_);
  const auto it = tags_.find(relative);
  if (it == tags_.end()) return {};
  return url_ + "/" + relative + "@" + it->second.tag + ":" + std::to_string(offset) + "+" + bytes;
}

std::optional<std::vector<std::byte>> HttpSource::cached(const std::string& relative,
                                                         std::uint64_t offset,
                                                         std::uint64_t bytes) const {
  const std::string key = cache_key(relative, offset, std::to_string(bytes));
  if (key.empty()) return std::nullopt;
  auto data = cache_->get(key);
  if (data && data->size() != bytes) data.reset();
  if (data) {
    std::lock_guard lock(mutex_);
    cache_served_ += data->size();
  }
  return data;
}

std::uint64_t HttpSource::cache_bytes_served() const {
  std::lock_guard lock(mutex_);
  return cache_served_;
}

namespace {
constexpr std::chrono::milliseconds waiting_call_interval{100};
}  // namespace

HttpResponse HttpSource::answer(std::future<HttpResponse> response) const {
  if (options_.while_waiting)
    while (response.wait_for(waiting_call_interval) != std::future_status::ready)
      options_.while_waiting();
  return response.get();
}

std::vector<std::byte> HttpSource::fetch(const std::string& relative, std::uint64_t offset,
                                         std::uint64_t bytes) const {
  double wait = options_.retry_initial_s;
  const auto start = std::chrono::steady_clock::now();
  HttpResponse r;
  unsigned attempt = 1;
  for (;; ++attempt) {
    r = answer(client_->get(url_ + "/" + relative, offset, bytes));
    if (r.ok()) return std::move(r.body);
    if (!r.transient || attempt >= std::max(1u, options_.attempts)) break;
    const auto until = std::chrono::steady_clock::now() +
                       std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                           std::chrono::duration<double>(wait));
    for (auto now = std::chrono::steady_clock::now(); now < until;
         now = std::chrono::steady_clock::now()) {
      std::this_thread::sleep_for(
          std::min<std::chrono::steady_clock::duration>(waiting_call_interval, until - now));
      if (options_.while_waiting) options_.while_waiting();
    }
    wait = std::min(2 * wait, options_.retry_max_s);
  }
  // The message already names the URL and the range.
  const std::string prefix = url_ + "/" + relative + ": ";
  std::string error =
      r.error.compare(0, prefix.size(), prefix) == 0 ? r.error.substr(prefix.size()) : r.error;
  if (attempt > 1) {
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    char tries[96];
    std::snprintf(tries, sizeof tries, " (the last of %u tries over %.1f s)", attempt, seconds);
    error += tries;
  }
  throw NetworkError(name(relative), error);
}

std::vector<std::byte> HttpSource::read_file(const std::string& relative,
                                             std::uint64_t max_bytes) const {
  std::optional<std::uint64_t> size;
  std::uint32_t crc = 0;
  {
    std::lock_guard lock(mutex_);
    if (const auto it = tags_.find(relative); it != tags_.end())
      size = it->second.bytes, crc = it->second.crc32c;
  }
  if (size && *size > max_bytes)
    throw format::FormatError(name(relative), "larger than " + std::to_string(max_bytes) +
                                                  " bytes (" + std::to_string(*size) + ")");
  // A file the manifest lists (a frame, the dictionary) read whole is kept as such, under its
  // checksum's tag; the manifest itself is always read fresh.
  const std::string key = cache_key(relative, 0, "whole");
  if (!key.empty())
    if (auto data = cache_->get(key); data && data->size() <= max_bytes) {
      std::lock_guard lock(mutex_);
      cache_served_ += data->size();
      return std::move(*data);
    }
  std::vector<std::byte> data = fetch(relative, 0, 0);
  if (data.size() > max_bytes)
    throw format::FormatError(name(relative), "larger than " + std::to_string(max_bytes) +
                                                  " bytes (" + std::to_string(data.size()) + ")");
  if (relative == "manifest.json") learn_manifest(data);
  // Kept only as the manifest lists it: a transfer damaged at the right length is not served
  // again from the cache (the reader finds the damage and names it).
  if (!key.empty() && size && data.size() == *size && format::manifest_crc(data) == crc)
    cache_->put(key, data);
  return data;
}

std::vector<std::byte> HttpSource::read_range(const std::string& relative, std::uint64_t offset,
                                              std::uint64_t bytes) const {
  if (bytes == 0) return {};
  if (auto data = cached(relative, offset, bytes)) return std::move(*data);
  return fetch(relative, offset, bytes);
}

void HttpSource::keep(const std::string& relative, std::uint64_t offset,
                      std::span<const std::byte> bytes) const {
  const std::string key = cache_key(relative, offset, "*");
  if (!key.empty() && !cache_->contains(key)) cache_->put(key, bytes);
}

std::optional<std::vector<std::byte>> HttpSource::kept(const std::string& relative,
                                                       std::uint64_t offset) const {
  const std::string key = cache_key(relative, offset, "*");
  if (key.empty()) return std::nullopt;
  auto data = cache_->get(key);
  if (data) {
    std::lock_guard lock(mutex_);
    cache_served_ += data->size();
  }
  return data;
}

std::shared_ptr<format::RangeReader> HttpSource::brick_reader() const {
  return std::const_pointer_cast<HttpSource>(shared_from_this());
}

std::string HttpSource::read(const fs::path& file, std::span<const format::ByteRange> ranges,
                             std::vector<std::vector<std::byte>>& out) {
  out.clear();
  if (ranges.empty()) return {};
  const std::string relative = relative_of(file);
  if (relative.empty())
    return file.string() + ": not a file of the container " + url_ + " (refused)";
  // A single range the cache holds is read from it.
  if (ranges.size() == 1)
    if (auto data = cached(relative, ranges[0].offset, ranges[0].bytes)) {
      out.push_back(std::move(*data));
      return {};
    }
  const std::uint64_t begin = ranges.front().offset;
  std::uint64_t end = begin;
  for (const format::ByteRange& r : ranges) {
    if (r.offset != end || r.bytes == 0)
      return file.string() + ": offset " + std::to_string(r.offset) +
             ": expected ranges back to back from offset " + std::to_string(begin);
    end += r.bytes;
  }
  HttpResponse response = answer(client_->get(file.string(), begin, end - begin));
  if (!response.ok()) return response.error;
  out.reserve(ranges.size());
  for (const format::ByteRange& r : ranges) {
    const auto* p = response.body.data() + (r.offset - begin);
    out.emplace_back(p, p + r.bytes);
  }
  return {};
}

bool HttpSource::holds(const fs::path& file, format::ByteRange range) const {
  if (!cache_) return false;
  const std::string relative = relative_of(file);
  if (relative.empty()) return false;
  const std::string key = cache_key(relative, range.offset, std::to_string(range.bytes));
  return !key.empty() && cache_->contains(key);
}

void HttpSource::keep(const fs::path& file, std::uint64_t offset,
                      std::span<const std::byte> bytes) {
  const std::string key = cache_key(relative_of(file), offset, std::to_string(bytes.size()));
  if (!key.empty() && !cache_->contains(key)) cache_->put(key, bytes);
}

std::shared_ptr<const format::ContainerSource> open_source(const std::string& location,
                                                           const RemoteOptions& options) {
  // A container's manifest named in place of its folder (a link copied from a listing): the folder.
  const auto folder = [](std::string s) {
    while (s.size() > 1 && s.back() == '/') s.pop_back();
    constexpr std::string_view manifest = "/manifest.json";
    if (s.size() > manifest.size() && s.ends_with(manifest))
      s.resize(s.size() - manifest.size());
    else if (s == "manifest.json")
      s = ".";
    return s;
  };
  if (is_url(location)) return std::make_shared<HttpSource>(folder(location), options);
  return std::make_shared<format::LocalSource>(folder(location));
}

}  // namespace volreel::remote
