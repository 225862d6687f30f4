// remote_options.hpp: how the commands that read a container (info, verify, render, play, bench
// stream) open one named by a path or an http(s):// URL, with the options of remote reading:
// --cache DIR, --cache-size, --connections, --ca-file, --stall-timeout, --tries.
#pragma once

#include <cstdio>
#include <memory>
#include <stdexcept>
#include <string>

#include <CLI/CLI.hpp>

#include "commands.hpp"
#include "volreel/datasets/volume.hpp"
#include "volreel/format/file_io.hpp"
#include "volreel/format/source.hpp"
#include "volreel/remote/http_source.hpp"

namespace volreel::cli {

struct RemoteCli {
  std::string cache;  ///< folder; empty: no cache
  std::string cache_size = remote::RemoteOptions::default_cache_size;
  unsigned connections = remote::HttpOptions{}.max_connections;
  std::string ca_file;
  double stall_timeout = remote::HttpOptions{}.stall_timeout_s;
  unsigned tries = remote::RemoteOptions{}.attempts;
};

/// The CONTAINER argument's help: a folder or a URL.
inline constexpr const char* container_argument_help =
    "Container: a NAME.vreel folder, or its http:// or https:// URL (any static web server or "
    "object store; a user and password in the URL are sent, never printed), or its "
    "manifest.json";

inline void add_remote_options(CLI::App& cmd, RemoteCli& o) {
  cmd.add_option("--cache", o.cache,
                 "For a URL: keep what arrives in this folder (bricks, indexes, dictionary), so "
                 "that the next run starts warm");
  cmd.add_option("--cache-size", o.cache_size,
                 "For a URL: the cache folder's size limit, least recently used out first (e.g. "
                 "2G, 500M)")
      ->capture_default_str();
  cmd.add_option("--connections", o.connections,
                 "For a URL: HTTP connections to the server at most")
      ->check(CLI::Range(1u, remote::RemoteOptions::max_connections))
      ->capture_default_str();
  cmd.add_option("--ca-file", o.ca_file,
                 "For an https URL: trust the certificate authorities in this PEM file (a "
                 "centre's own CA) instead of the system's")
      ->check(CLI::ExistingFile);
  cmd.add_option("--stall-timeout", o.stall_timeout,
                 "For a URL: give a request up when no byte has arrived for this many seconds "
                 "(the server accepted it, then stopped sending; whole seconds, a fraction "
                 "rounded up)")
      ->check(in_range(remote::RemoteOptions::min_stall_timeout_s,
                       remote::RemoteOptions::max_stall_timeout_s))
      ->capture_default_str();
  cmd.add_option(
         "--tries", o.tries,
         "For a URL: how many times a read of the manifest, dictionary or a frame index "
         "is tried when it fails in a way that may pass (timeout, refused or reset "
         "connection, HTTP 5xx), waiting 0.25 s, then twice as long each time (at most 8 s)")
      ->check(in_range(1, remote::RemoteOptions::max_attempts))
      ->capture_default_str();
}

/// The source of the container at `location` (a folder or a URL). Throws CLI::ValidationError (a
/// mistake on the command line, exit status 2) for a bad URL or option, format::FormatError for a
/// folder that is not a container or a cache folder that cannot be used.
inline std::shared_ptr<const format::ContainerSource> open_container_source(
    const std::string& location, const RemoteCli& o) {
  // Options given where they do nothing are said to be ignored, not dropped without a word.
  const RemoteCli defaults;
  std::string ignored;
  const auto given = [&](bool differs, const char* name) {
    if (differs) ignored += (ignored.empty() ? "" : ", ") + std::string(name);
  };
  if (!remote::is_url(location)) {
    given(!o.cache.empty(), "--cache");
    given(o.cache_size != defaults.cache_size, "--cache-size");
    given(o.connections != defaults.connections, "--connections");
    given(!o.ca_file.empty(), "--ca-file");
    given(o.stall_timeout != defaults.stall_timeout, "--stall-timeout");
    given(o.tries != defaults.tries, "--tries");
    if (!ignored.empty())
      std::fprintf(stderr,
                   "volreel: warning: %s is a folder on this machine, and %s appl%s to a URL "
                   "only: ignored\n",
                   location.c_str(), ignored.c_str(),
                   ignored.find(',') == std::string::npos ? "ies" : "y");
  } else if (o.cache.empty() && o.cache_size != defaults.cache_size) {
    std::fprintf(stderr, "volreel: warning: --cache-size without --cache: ignored (no cache)\n");
  }
  remote::RemoteOptions options;
  options.http.max_connections = o.connections;
  options.http.ca_file = o.ca_file;
  options.http.stall_timeout_s = o.stall_timeout;
  options.attempts = o.tries;
  try {
    if (!o.cache.empty()) {
      options.cache_dir = o.cache;
      options.cache_bytes = format::detail::parse_byte_size(o.cache_size, "--cache-size");
    }
    return remote::open_source(location, options);
  } catch (const std::invalid_argument& e) {
    throw CLI::ValidationError(e.what());
  }
}

/// One line on what a remote source transferred ("remote: 41 requests, 1.9 MB received, 0.3 MB
/// from the cache"), to stderr; nothing for a local one.
inline void print_remote_summary(const format::ContainerSource& source, const char* command) {
  const auto* http = dynamic_cast<const remote::HttpSource*>(&source);
  if (!http) return;
  std::fprintf(stderr,
               "volreel %s: %s: %llu HTTP requests (%llu over HTTP/2) on %llu connections, "
               "%.2f MB received",
               command, http->location().c_str(), static_cast<unsigned long long>(http->requests()),
               static_cast<unsigned long long>(http->client().http2_responses()),
               static_cast<unsigned long long>(http->client().connections_opened()),
               static_cast<double>(http->bytes_received()) / 1e6);
  if (http->cache())
    std::fprintf(stderr, ", %.2f MB from the cache %s (%.1f MB held)",
                 static_cast<double>(http->cache_bytes_served()) / 1e6,
                 http->cache()->directory().c_str(),
                 static_cast<double>(http->cache()->bytes()) / 1e6);
  std::fprintf(stderr, "\n");
}

}  // namespace volreel::cli
