// progress.cpp: the terminal progress bar.
#include "progress.hpp"

#include <omp.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <thread>

namespace volreel::cli {

namespace {

std::atomic<int> stop_signal{0};  // the first signal received, 0 before
static_assert(std::atomic<int>::is_always_lock_free, "read and written in a signal handler");
std::atomic<bool> stop_active{false};
std::thread::id stop_thread;
struct sigaction previous_int, previous_term;

extern "C" void on_stop_signal(int signal) {
  int none = 0;
  if (!stop_signal.compare_exchange_strong(none, signal)) {
    // The second: at once, as without the handler.
    sigaction(SIGINT, &previous_int, nullptr);
    sigaction(SIGTERM, &previous_term, nullptr);
    std::raise(signal);
    return;
  }
  static const char message[] =
      "\nvolreel: interrupted: stopping at the next step (again to stop at once)\n";
  [[maybe_unused]] const ssize_t n = ::write(STDERR_FILENO, message, sizeof message - 1);
}

/// Handles `signal` unless it is ignored (a background job's SIGINT stays ignored).
void handle(int signal, struct sigaction& previous) {
  sigaction(signal, nullptr, &previous);
  if (previous.sa_handler == SIG_IGN) return;
  struct sigaction action {};
  action.sa_handler = on_stop_signal;
  action.sa_flags = SA_RESTART;
  sigemptyset(&action.sa_mask);
  sigaction(signal, &action, nullptr);
}

}  // namespace

StopOnSignal::StopOnSignal() {
  stop_signal = 0;
  stop_thread = std::this_thread::get_id();
  handle(SIGINT, previous_int);
  handle(SIGTERM, previous_term);
  stop_active = true;
}

StopOnSignal::~StopOnSignal() {
  stop_active = false;
  sigaction(SIGINT, &previous_int, nullptr);
  sigaction(SIGTERM, &previous_term, nullptr);
}

void end_by_stop_signal() {
  const int signal = stop_signal.load();
  if (signal == 0) return;
  struct sigaction action {};
  action.sa_handler = SIG_DFL;
  sigemptyset(&action.sa_mask);
  sigaction(signal, &action, nullptr);
  std::raise(signal);
}

void stop_if_interrupted() {
  if (stop_active && stop_signal.load() != 0 && std::this_thread::get_id() == stop_thread &&
      omp_get_level() == 0)
    throw Interrupted();
}

std::string format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  const auto s = static_cast<long>(seconds + 0.5);
  char text[32];
  if (s >= 3600)
    std::snprintf(text, sizeof text, "%ldh%02ldm", s / 3600, s / 60 % 60);
  else if (s >= 60)
    std::snprintf(text, sizeof text, "%ldm%02lds", s / 60, s % 60);
  else
    std::snprintf(text, sizeof text, "%lds", s);
  return text;
}

ProgressBar::ProgressBar(std::string label, std::string unit)
    : label_(std::move(label)),
      unit_(std::move(unit)),
      terminal_(isatty(STDERR_FILENO) != 0),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

ProgressBar::~ProgressBar() {
  if (!finished_ && terminal_ && last_.total > 0) std::fputc('\n', stderr);
}

Progress ProgressBar::progress() {
  return Progress{
      [](const ProgressUpdate& u, void* self) { static_cast<ProgressBar*>(self)->update(u); },
      this};
}

void ProgressBar::update(const ProgressUpdate& update) {
  stop_if_interrupted();
  last_ = update;
  const auto now = std::chrono::steady_clock::now();
  const double fraction = update.total > 0 ? update.done / update.total : 0;
  if (terminal_) {
    if (now - last_draw_ < std::chrono::milliseconds(100) && fraction < 1) return;
  } else {
    if (fraction >= 1) return;  // finish() prints the last line
    const bool step = fraction >= last_logged_fraction_ + 0.1;
    if (!step && now - last_draw_ < std::chrono::seconds(10)) return;
    last_logged_fraction_ = std::floor(fraction * 10) / 10;
  }
  last_draw_ = now;
  draw(false);
}

void ProgressBar::finish() {
  if (finished_) return;
  draw(true);
  finished_ = true;
}

void ProgressBar::draw(bool final) {
  const double elapsed =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double fraction = last_.total > 0 ? std::clamp(last_.done / last_.total, 0.0, 1.0) : 0.0;
  const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : std::nan("");
  constexpr int width = 28;
  std::string bar(width, ' ');
  for (int i = 0; i < static_cast<int>(fraction * width + 0.5); ++i)
    bar[static_cast<std::size_t>(i)] = '#';
  char counts[64];
  if (last_.total == std::floor(last_.total))
    std::snprintf(counts, sizeof counts, "%.0f/%.0f %s", last_.done, last_.total, unit_.c_str());
  else
    std::snprintf(counts, sizeof counts, "%.2f/%.2f %s", last_.done, last_.total, unit_.c_str());
  const std::string timing =
      final ? "in " + format_duration(elapsed) : "ETA " + format_duration(eta);
  std::fprintf(stderr, "%s%s [%s] %3.0f%% %s  %s  %s%s", terminal_ ? "\r\033[K" : "",
               label_.c_str(), bar.c_str(), fraction * 100, counts, last_.status.c_str(),
               timing.c_str(), terminal_ && !final ? "" : "\n");
  std::fflush(stderr);
}

}  // namespace volreel::cli
