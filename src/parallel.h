// parallel.h: the one parallel loop every stage runs through (TBB), with progress and
// cancellation.
//
// Determinism contract: the body must make item i's result depend only on i (write it to
// out[i], draw its randoms from a stream keyed by i). The partition of the range among
// threads then never changes the output, whatever the thread count.
#pragma once

#include <atomic>
#include <cstddef>
#include <functional>

#include "src/progress.h"

namespace kiln {

struct ParallelOptions {
  int threads = 0;        // worker threads; 0 = all cores
  size_t grain = 16;      // items per task, at least
  Progress* progress = nullptr;              // advanced by finished items
  const std::atomic<bool>* cancel = nullptr;  // polled between chunks
};

// Runs body(begin, end) over chunks covering [0, count). Returns false when cancelled (some
// items may not have run).
bool parallelFor(size_t count, const std::function<void(size_t begin, size_t end)>& body,
                 const ParallelOptions& options = {});

}  // namespace kiln
