// parallel.cpp: parallelFor on oneTBB, with per-chunk progress and cancellation.
#include "src/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

#include <algorithm>

namespace kiln {

bool parallelFor(size_t count, const std::function<void(size_t begin, size_t end)>& body,
                 const ParallelOptions& options) {
  auto cancelled = [&] {
    return options.cancel && options.cancel->load(std::memory_order_relaxed);
  };
  if (cancelled()) return false;
  if (count == 0) return true;
  size_t grain = std::max<size_t>(1, options.grain);

  auto runChunk = [&](const tbb::blocked_range<size_t>& r) {
    // Chunks that start after a cancel return at once, so the loop drains quickly.
    if (cancelled()) return;
    body(r.begin(), r.end());
    if (options.progress) options.progress->advance(r.size());
  };
  // simple_partitioner: chunks of grain/2..grain items, so cancellation latency and progress
  // granularity are bounded by the grain rather than by count / threads.
  auto run = [&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, grain), runChunk,
                      tbb::simple_partitioner());
  };
  if (options.threads == 1) {
    // Plain serial loop in the calling thread: no arena, same chunking.
    for (size_t begin = 0; begin < count; begin += grain)
      runChunk(tbb::blocked_range<size_t>(begin, std::min(count, begin + grain), grain));
  } else {
    tbb::task_arena arena(options.threads > 0 ? options.threads : tbb::task_arena::automatic);
    arena.execute(run);
  }
  return !cancelled();
}

}  // namespace kiln
