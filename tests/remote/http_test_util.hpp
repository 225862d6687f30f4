// http_test_util.hpp: real servers on 127.0.0.1 for the tests of remote reading — nginx (Debian's)
// serving a folder on a free port, optionally shaped with limit_rate, that a test can stop and
// start again on the same port; and the fault proxy (fault_proxy.py) in front of it.
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "../test_util.hpp"

namespace volreel::test {

/// A TCP port on 127.0.0.1 that was free a moment ago.
inline int free_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = 0;
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0)
    throw std::runtime_error("no free port on 127.0.0.1");
  socklen_t n = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &n);
  ::close(fd);
  return ntohs(a.sin_port);
}

/// Whether something accepts connections on 127.0.0.1:port.
inline bool port_open(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  const bool ok = fd >= 0 && ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  if (fd >= 0) ::close(fd);
  return ok;
}

/// `program` as execv takes it: itself where it names a path, else the first match on PATH.
inline std::string program_path(const std::string& program) {
  if (program.find('/') != std::string::npos) return program;
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/bin:/bin";
  for (std::size_t at = 0; at <= dirs.size();) {
    const std::size_t end = std::min(dirs.find(':', at), dirs.size());
    const std::string dir = end > at ? dirs.substr(at, end - at) : ".";  // "": the current one
    const std::string candidate = dir + "/" + program;
    std::error_code unreadable;  // a folder on PATH that cannot be searched: the next one
    if (std::filesystem::is_regular_file(candidate, unreadable) &&
        ::access(candidate.c_str(), X_OK) == 0)
      return candidate;
    at = end + 1;
  }
  throw std::runtime_error("cannot start " + program + ": not found on PATH");
}

/// Starts a server process that ends when the test process does (PR_SET_PDEATHSIG): a test that
/// crashes leaves no server behind holding the test's output open, which would keep ctest waiting
/// until its timeout. The signal follows the thread that calls this: call it from the test's own
/// thread, not from one that ends before the server should. Throws naming the program if it
/// cannot be started.
inline pid_t spawn(const std::vector<std::string>& args, int stdout_fd = -1) {
  const std::string program = program_path(args[0]);
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  int status_pipe[2];  // the child writes errno here if exec fails; closed by a successful exec
  if (::pipe2(status_pipe, O_CLOEXEC) != 0) throw std::runtime_error("cannot start " + args[0]);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(status_pipe[0]);
    ::close(status_pipe[1]);
    throw std::runtime_error("cannot start " + args[0] + ": fork failed");
  }
  if (pid == 0) {  // only async-signal-safe calls until exec
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);  // the test ended before prctl
    if (stdout_fd >= 0) ::dup2(stdout_fd, 1);
    ::execv(program.c_str(), argv.data());
    const int error = errno;
    [[maybe_unused]] const auto written = ::write(status_pipe[1], &error, sizeof error);
    ::_exit(127);
  }
  ::close(status_pipe[1]);
  int error = 0;
  ssize_t got;
  do got = ::read(status_pipe[0], &error, sizeof error);
  while (got < 0 && errno == EINTR);
  ::close(status_pipe[0]);
  if (got == static_cast<ssize_t>(sizeof error)) {
    ::waitpid(pid, nullptr, 0);
    throw std::runtime_error("cannot start " + program + ": " + std::strerror(error));
  }
  return pid;
}

inline void stop_process(pid_t& pid) {
  if (pid <= 0) return;
  ::kill(pid, SIGTERM);
  int status = 0;
  ::waitpid(pid, &status, 0);
  pid = 0;
}

inline std::string nginx_binary() {
  for (const char* p : {"/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx"})
    if (std::filesystem::exists(p)) return p;
  throw std::runtime_error("nginx not found: install Debian's nginx (scripts/install-deps)");
}

/// nginx serving `root` on 127.0.0.1:port (one process, no daemon), with `limit_rate` bytes/s per
/// request when > 0, and with `tls` over https and HTTP/2 with a self-signed certificate for
/// 127.0.0.1 (certificate()). Stopped on destruction.
class Nginx {
 public:
  Nginx(std::filesystem::path root, std::filesystem::path work, std::uint64_t limit_rate = 0,
        bool tls = false)
      : root_(std::move(root)), work_(std::move(work)), port_(free_port()), tls_(tls) {
    std::filesystem::create_directories(work_ / "tmp");
    if (tls_) {
      const std::string command =
          "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=127.0.0.1 -addext "
          "subjectAltName=IP:127.0.0.1 -keyout " +
          (work_ / "key.pem").string() + " -out " + certificate().string() + " 2>/dev/null";
      if (std::system(command.c_str()) != 0)
        throw std::runtime_error("openssl could not make a certificate (scripts/install-deps)");
    }
    std::ofstream c(work_ / "nginx.conf");
    c << (::geteuid() == 0 ? "user root;\n" : "") << "worker_processes 1;\nmaster_process off;\n"
      << "daemon off;\npid " << (work_ / "nginx.pid").string() << ";\nerror_log "
      << (work_ / "error.log").string() << " warn;\nevents { worker_connections 256; }\n"
      << "http {\n  access_log " << (work_ / "access.log").string() << ";\n"
      << "  client_body_temp_path " << (work_ / "tmp").string() << ";\n"
      << "  proxy_temp_path " << (work_ / "tmp").string() << ";\n"
      << "  fastcgi_temp_path " << (work_ / "tmp").string() << ";\n"
      << "  uwsgi_temp_path " << (work_ / "tmp").string() << ";\n"
      << "  scgi_temp_path " << (work_ / "tmp").string() << ";\n"
      << "  default_type application/octet-stream;\n  keepalive_requests 100000;\n"
      << "  server {\n    listen 127.0.0.1:" << port_ << (tls_ ? " ssl http2" : "") << ";\n"
      << (tls_ ? "    ssl_certificate " + certificate().string() + ";\n    ssl_certificate_key " +
                     (work_ / "key.pem").string() + ";\n"
               : std::string())
      << "    root " << root_.string() << ";\n"
      << (limit_rate > 0 ? "    limit_rate " + std::to_string(limit_rate) + ";\n" : "")
      << "  }\n}\n";
    c.close();
    start();
  }
  ~Nginx() { stop(); }
  Nginx(const Nginx&) = delete;
  Nginx& operator=(const Nginx&) = delete;

  void start() {
    pid_ = spawn({nginx_binary(), "-p", work_.string(), "-e", (work_ / "error.log").string(), "-c",
                  (work_ / "nginx.conf").string()});
    for (int i = 0; i < 500 && !port_open(port_); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    if (!port_open(port_)) {
      const std::vector<std::byte> log = read_bytes(work_ / "error.log");
      const std::string text(reinterpret_cast<const char*>(log.data()), log.size());
      stop();
      throw std::runtime_error("nginx did not start on 127.0.0.1:" + std::to_string(port_) + ": " +
                               text);
    }
  }
  void stop() { stop_process(pid_); }
  int port() const { return port_; }
  std::string url(const std::string& path) const {
    return std::string(tls_ ? "https" : "http") + "://127.0.0.1:" + std::to_string(port_) + "/" +
           path;
  }
  std::filesystem::path certificate() const { return work_ / "cert.pem"; }
  /// Requests nginx has served (lines of its access log).
  std::size_t requests_served() const {
    std::ifstream log(work_ / "access.log");
    std::size_t n = 0;
    for (std::string line; std::getline(log, line);) ++n;
    return n;
  }

 private:
  std::filesystem::path root_, work_;
  int port_;
  bool tls_ = false;
  pid_t pid_ = 0;
};

/// fault_proxy.py in front of 127.0.0.1:upstream_port; set_mode() changes how it answers.
class FaultProxy {
 public:
  FaultProxy(const std::filesystem::path& script, int upstream_port, std::filesystem::path work)
      : mode_file_(std::move(work) / "proxy_mode") {
    set_mode("pass");
    int fds[2];
    if (::pipe(fds) != 0) throw std::runtime_error("pipe");
    pid_ = spawn({"python3", script.string(), std::to_string(upstream_port), mode_file_.string()},
                 fds[1]);
    ::close(fds[1]);
    std::string line;
    char c = 0;
    while (::read(fds[0], &c, 1) == 1 && c != '\n') line += c;
    ::close(fds[0]);
    port_ = std::stoi(line);
  }
  ~FaultProxy() { stop_process(pid_); }
  FaultProxy(const FaultProxy&) = delete;
  FaultProxy& operator=(const FaultProxy&) = delete;

  void set_mode(const std::string& mode) { std::ofstream(mode_file_) << mode << '\n'; }
  std::string url(const std::string& path) const {
    return "http://127.0.0.1:" + std::to_string(port_) + "/" + path;
  }

 private:
  std::filesystem::path mode_file_;
  int port_ = 0;
  pid_t pid_ = 0;
};

}  // namespace volreel::test
