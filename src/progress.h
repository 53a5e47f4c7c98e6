// progress.h: progress reports on stderr and cooperative cancellation (Ctrl-C).
#pragma once

#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <string>

namespace kiln {

// Thread-safe progress of one long operation, printed to stderr at most every half second
// as "bake: 42.0% (1234/5678 texels, 812 texels/s, ETA 0:12)". Prints nothing when
// disabled (tests, --quiet).
class Progress {
 public:
  Progress(std::string label, size_t total, std::string unit, bool enabled = true);
  ~Progress();

  void advance(size_t n = 1);
  // Prints the final line (100%, total time) once.
  void finish();
  size_t done() const { return done_.load(std::memory_order_relaxed); }

 private:
  void print(bool final);
  std::string label_, unit_;
  size_t total_;
  bool enabled_;
  bool finished_ = false;
  std::atomic<size_t> done_{0};
  std::chrono::steady_clock::time_point start_, lastPrint_;
  std::mutex mutex_;
};

// A process-wide cancellation flag. installInterruptHandler() makes SIGINT (Ctrl-C) and
// SIGTERM set it; long operations poll it and stop early, leaving outputs untouched.
std::atomic<bool>& cancelFlag();
void installInterruptHandler();

}  // namespace kiln
