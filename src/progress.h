// progress.h: progress reports on stderr and cooperative cancellation (Ctrl-C).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
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

  // Distributed bakes (src/distributed.h): the work this line counts is split across ranks.
  // `total` stays the whole job's; each rank advances by its own items. The other ranks
  // report their counts to rank 0 at most every half second and print nothing; rank 0's line
  // shows the sum (percent, rate and ETA of the whole job). Call on every rank, in the same
  // order (it takes the next id of distributed.h's sequence). No-op when not distributed.
  void splitAcrossRanks();
  uint64_t distributedStage() const { return stage_; }
  // Prints the line if it is due (rank 0, while it waits for the other ranks' shares).
  void poll();

  // For an operation done in pieces interleaved with others (the post-processing steps, page
  // by page): once a Busy has been made, the rate, ETA and total time count only the time
  // spent while one was alive, not the time since construction. One at a time.
  class Busy {
   public:
    explicit Busy(Progress& progress);
    ~Busy();
    Busy(const Busy&) = delete;
    Busy& operator=(const Busy&) = delete;

   private:
    Progress& progress_;
  };
  Busy busy() { return Busy(*this); }

 private:
  double elapsedSeconds() const;  // caller holds mutex_
  void print(bool final);
  std::string label_, unit_;
  size_t total_;
  uint64_t stage_ = 0;  // splitAcrossRanks' id; 0 = this process's work only
  bool enabled_;
  bool finished_ = false;
  std::atomic<size_t> done_{0};
  std::chrono::steady_clock::time_point start_, lastPrint_;
  bool measuresBusy_ = false;  // a Busy was made: elapsed = busySeconds_ (+ the open one)
  bool busyOpen_ = false;
  double busySeconds_ = 0.0;
  std::chrono::steady_clock::time_point busyStart_;
  std::mutex mutex_;
};

// A process-wide cancellation flag. installInterruptHandler() makes SIGINT (Ctrl-C) and
// SIGTERM set it; long operations poll it and stop early, leaving outputs untouched.
std::atomic<bool>& cancelFlag();
void installInterruptHandler();

}  // namespace kiln
