// distributed.h: the one place kiln talks to MPI (Open MPI's mpirun, Slurm's srun). Bakers use
// this interface and never include mpi.h; kiln builds and runs without MPI (KILN_WITH_MPI off:
// every function below then behaves as a job of one process).
//
// A distributed bake: every rank loads the same scene and runs the same deterministic code;
// the expensive per-item loops (lightmap texels, probes, placement's cheap bakes) run only over
// the items this rank owns (splitWork), and exchangeItems() brings every item's result to rank
// 0 (lightmaps) or to every rank (probes, placement). Items draw their random numbers from
// streams keyed by the item, so the assembled results are bit-for-bit those of one process.
// Rank 0 writes every output; the other ranks write nothing and print nothing but fatal errors.
// docs/distributed.md describes the protocol and what it sends.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <type_traits>
#include <vector>

#include "kiln/result.h"
#include "src/parallel.h"

namespace kiln {

class Progress;

// Starts MPI when `force` (--mpi) or when the environment shows a launcher started this
// process (Open MPI's mpirun: OMPI_COMM_WORLD_SIZE; PMIx / PMI launchers such as srun:
// PMIX_RANK, PMI_RANK). Without MPI in the build, fails when asked (`force`) or when the
// launcher started more than one process (they would each bake everything and race on the
// outputs). Idempotent. The job ends with stopDistributed().
Status startDistributed(bool force);
// MPI_Finalize (no-op when not started). Called by kiln's main before it returns.
void stopDistributed();

int distributedRank();  // 0 when not distributed
int distributedSize();  // 1 when not distributed
inline bool distributedRoot() { return distributedRank() == 0; }
inline bool distributedActive() { return distributedSize() > 1; }

// Whether an exchangeBytes failed on every rank alike (one rank interrupted or failed): each
// rank then ends on its own path with the same outcome, no MPI_Abort needed.
bool distributedFailureAgreed();

// Prints "kiln: error: rank R of N: <message>" (nothing when `message` is empty) and ends the
// whole job (MPI_Abort, exit code `code`); without MPI prints "kiln: error: <message>" and
// exits with `code`.
[[noreturn]] void distributedAbort(const std::string& message, int code);

// Which items [0, count) this rank computes. Items are cut into tiles of `tile` consecutive
// items; tiles are dealt in order, each to the rank with the least estimated cost so far
// (ties: the lowest rank), so equal costs go round robin and neighbouring tiles (which cost
// alike) land on different ranks. The same on every rank. Not distributed: every item local,
// and `cost` is never called.
struct WorkSplit {
  size_t count = 0;
  std::vector<int32_t> owner;  // per item; empty when not distributed
  std::vector<uint32_t> local;  // this rank's items, ascending; empty when not distributed
  bool distributed() const { return !owner.empty(); }
};
// `cost(i)`: the estimated cost of item i (any unit, >= 0); null: every item costs 1.
WorkSplit splitWork(size_t count, size_t tile, const std::function<double(size_t)>& cost = {});

// parallelFor over this rank's items of `split`: body(begin, end) gets runs of consecutive
// local items; options.progress advances by local items. Returns false when cancelled.
bool parallelForLocal(const WorkSplit& split,
                      const std::function<void(size_t begin, size_t end)>& body,
                      const ParallelOptions& options);

// Collective over all ranks (every rank must call it, in the same order): each rank's local
// items' bytes (`itemBytes` bytes per item, items packed in the order of split.local) are
// copied into `data` (item i at data + i * itemBytes) on rank 0, or on every rank when
// `toAll`. `localOk` false (cancelled, failed) on any rank makes every rank return an error
// naming the first such rank; a rank that was cancelled also sets the process cancel flag on
// every rank, so the job ends as interrupted. `progress` (may be null), on rank 0, keeps
// printing the whole job's progress while rank 0 waits for the others' shares.
// Not distributed: a no-op that returns localOk.
Status exchangeBytes(const WorkSplit& split, std::byte* data, size_t itemBytes, bool toAll,
                     bool localOk, bool localCancelled, Progress* progress);

// exchangeBytes over a vector of trivially copyable items, `stride` values per item.
template <class T>
Status exchangeItems(const WorkSplit& split, std::vector<T>& items, size_t stride, bool toAll,
                     bool localOk, bool localCancelled, Progress* progress) {
  static_assert(std::is_trivially_copyable_v<T>, "items are sent as bytes");
  return exchangeBytes(split, reinterpret_cast<std::byte*>(items.data()), stride * sizeof(T),
                       toAll, localOk, localCancelled, progress);
}

// Bytes this process has sent and received through exchangeBytes (payload only), for
// docs/distributed.md's measurements and the summary line.
uint64_t distributedBytesSent();
uint64_t distributedBytesReceived();

// Progress reports (used by Progress; see progress.h): a new id for a progress line split
// across ranks (the same sequence on every rank), a rank's report of its done count (`final`
// when its share is over, `cancelled` when it was interrupted: rank 0 then sets the cancel
// flag of every rank, which each sees at its next report), and on rank 0 the sum of the
// other ranks' latest reports for `stage`.
uint64_t newDistributedStage();
void sendDistributedProgress(uint64_t stage, uint64_t done, bool final, bool cancelled = false);
uint64_t remoteDistributedProgress(uint64_t stage);

}  // namespace kiln
