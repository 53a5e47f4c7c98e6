// progress.cpp: progress lines on stderr and the Ctrl-C cancellation flag.
//
// On a terminal the line is rewritten in place ("\r") at most every half second; when
// stderr is a file or pipe (CI logs) a new line is printed at most every few seconds so logs
// stay readable.
#include "src/progress.h"

#include "src/distributed.h"

#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstring>

namespace kiln {

namespace {

bool stderrIsTty() {
  static const bool tty = ::isatty(::fileno(stderr)) != 0;
  return tty;
}

std::string formatDuration(double seconds) {
  if (!(seconds >= 0.0) || seconds > 1e8) return "-:--:--";
  long s = long(seconds + 0.5);
  char buf[32];
  std::snprintf(buf, sizeof buf, "%ld:%02ld:%02ld", s / 3600, (s / 60) % 60, s % 60);
  return buf;
}

std::string formatRate(double rate) {
  char buf[32];
  if (rate >= 100.0 || rate == 0.0)
    std::snprintf(buf, sizeof buf, "%.0f", rate);
  else
    std::snprintf(buf, sizeof buf, "%.3g", rate);
  return buf;
}

// Namespace-scope and constant-initialised, so the signal handler never touches a
// function-local static's guard.
std::atomic<bool> gCancel{false};
static_assert(std::atomic<bool>::is_always_lock_free, "signal handler needs a lock-free flag");

extern "C" void onInterrupt(int) {
  gCancel.store(true);
  // The other ranks of a distributed bake stay quiet (mpirun signals every rank).
  if (distributedRank() != 0) return;
  // Async-signal-safe report; SA_RESETHAND already restored the default action, so a
  // second Ctrl-C terminates the process.
  static const char kMessage[] = "\nkiln: interrupted, stopping (press Ctrl-C again to kill)\n";
  ssize_t ignored = ::write(STDERR_FILENO, kMessage, sizeof kMessage - 1);
  (void)ignored;
}

}  // namespace

Progress::Progress(std::string label, size_t total, std::string unit, bool enabled)
    : label_(std::move(label)), unit_(std::move(unit)), total_(total), enabled_(enabled) {
  start_ = lastPrint_ = std::chrono::steady_clock::now();
}

Progress::~Progress() {
  // Leave the terminal on a fresh line if an in-place line was shown but finish() was not
  // called (an error or cancellation).
  if (enabled_ && distributedRoot() && !finished_ && stderrIsTty() && lastPrint_ != start_)
    std::fputc('\n', stderr);
}

void Progress::advance(size_t n) {
  done_.fetch_add(n, std::memory_order_relaxed);
  if (stage_ != 0 && !distributedRoot()) {
    // Another rank's share: report it to rank 0 every half second.
    const auto now = std::chrono::steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
    if (!lock.owns_lock() || std::chrono::duration<double>(now - lastPrint_).count() < 0.5)
      return;
    lastPrint_ = now;
    sendDistributedProgress(stage_, done_.load(std::memory_order_relaxed), false,
                            cancelFlag().load());
    return;
  }
  poll();
}

void Progress::poll() {
  if (!enabled_ || !distributedRoot()) return;
  auto now = std::chrono::steady_clock::now();
  double interval = stderrIsTty() ? 0.5 : 3.0;
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;  // someone else is printing
  if (std::chrono::duration<double>(now - lastPrint_).count() < interval) return;
  lastPrint_ = now;
  print(false);
}

void Progress::splitAcrossRanks() { stage_ = newDistributedStage(); }

void Progress::finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_ && distributedRoot()) print(true);
}

Progress::Busy::Busy(Progress& progress) : progress_(progress) {
  std::lock_guard<std::mutex> lock(progress_.mutex_);
  progress_.measuresBusy_ = true;
  progress_.busyOpen_ = true;
  progress_.busyStart_ = std::chrono::steady_clock::now();
}

Progress::Busy::~Busy() {
  std::lock_guard<std::mutex> lock(progress_.mutex_);
  progress_.busySeconds_ +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - progress_.busyStart_)
          .count();
  progress_.busyOpen_ = false;
}

// Caller holds mutex_.
double Progress::elapsedSeconds() const {
  const auto now = std::chrono::steady_clock::now();
  if (!measuresBusy_) return std::chrono::duration<double>(now - start_).count();
  return busySeconds_ +
         (busyOpen_ ? std::chrono::duration<double>(now - busyStart_).count() : 0.0);
}

// Caller holds mutex_.
void Progress::print(bool final) {
  // Split across ranks: the other ranks' latest reports too (rank 0 only prints).
  const size_t remote = stage_ != 0 ? size_t(remoteDistributedProgress(stage_)) : 0;
  size_t done = std::min(done_.load(std::memory_order_relaxed) + remote, total_);
  double elapsed = elapsedSeconds();
  double fraction = total_ > 0 ? double(done) / double(total_) : 1.0;
  double rate = elapsed > 0 ? double(done) / elapsed : 0.0;
  char line[256];
  if (final) {
    std::snprintf(line, sizeof line, "%s: %.1f%% (%zu/%zu %s, %s %s/s, %s total)", label_.c_str(),
                  100.0 * fraction, done, total_, unit_.c_str(), formatRate(rate).c_str(),
                  unit_.c_str(), formatDuration(elapsed).c_str());
  } else {
    double eta = rate > 0 ? double(total_ - done) / rate : -1.0;
    std::snprintf(line, sizeof line, "%s: %.1f%% (%zu/%zu %s, %s %s/s, ETA %s)", label_.c_str(),
                  100.0 * fraction, done, total_, unit_.c_str(), formatRate(rate).c_str(),
                  unit_.c_str(), formatDuration(eta).c_str());
  }
  if (stderrIsTty())
    std::fprintf(stderr, "\r%s\033[K%s", line, final ? "\n" : "");
  else
    std::fprintf(stderr, "%s\n", line);
  std::fflush(stderr);
}

std::atomic<bool>& cancelFlag() { return gCancel; }

void installInterruptHandler() {
  struct sigaction action;
  std::memset(&action, 0, sizeof action);
  action.sa_handler = onInterrupt;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESETHAND | SA_RESTART;
  ::sigaction(SIGINT, &action, nullptr);
  ::sigaction(SIGTERM, &action, nullptr);
}

}  // namespace kiln
