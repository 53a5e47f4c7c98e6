// distributed.cpp: distributed.h over MPI (KILN_WITH_MPI), or a job of one process without it.
//
// Threads: MPI is started with MPI_THREAD_SERIALIZED and every MPI call here holds gMpiMutex,
// so worker threads (progress reports from inside parallelFor) never call MPI at the same
// time as another thread.
#include "src/distributed.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <thread>

#include "src/progress.h"

#ifdef KILN_WITH_MPI
// The C API only: not the deprecated C++ bindings mpi.h would otherwise pull in.
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace kiln {

namespace {

int gRank = 0;
int gSize = 1;
bool gStarted = false;
uint64_t gStage = 0;
uint64_t gBytesSent = 0, gBytesReceived = 0;
bool gFailureAgreed = false;

const char* envValue(const char* name) {
  const char* v = std::getenv(name);
  return v && *v ? v : nullptr;
}

// The process count a launcher announced (0: not started by a known launcher).
int launcherSize() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"})
    if (const char* v = envValue(name)) return std::max(1, std::atoi(v));
  if (envValue("PMIX_RANK") || envValue("PMI_RANK")) {
    // PMIx gives no size in the environment; under Slurm's srun the task count says it.
    const char* tasks = envValue("SLURM_NTASKS");
    return tasks ? std::max(1, std::atoi(tasks)) : 1;
  }
  return 0;
}

#ifdef KILN_WITH_MPI
std::mutex gMpiMutex;
MPI_Comm gProgressComm = MPI_COMM_NULL;  // progress reports (point to point, tag kProgressTag)
MPI_Comm gDataComm = MPI_COMM_NULL;      // exchangeBytes
constexpr int kProgressTag = 1;
constexpr int kDataTag = 2;
constexpr int kCancelTag = 3;  // rank 0 -> the others: a rank was interrupted, stop too
bool gCancelSent = false;
int gCancelOrigin = -1;  // rank 0: the rank whose interruption it passed on
// Largest single message: MPI counts are ints.
constexpr size_t kChunkBytes = size_t(1) << 30;

// Rank 0's view of the other ranks' progress reports: per rank, the latest (stage, done,
// final) received.
struct RemoteProgress {
  uint64_t stage = 0, done = 0;
  bool final = false;
};
std::vector<RemoteProgress> gRemote;

// Caller holds gMpiMutex. Rank 0: tells every other rank to stop (once) and stops itself.
void broadcastCancelLocked() {
  cancelFlag().store(true);
  if (gCancelSent) return;
  gCancelSent = true;
  const uint64_t msg = 1;
  for (int r = 1; r < gSize; ++r) MPI_Send(&msg, 1, MPI_UINT64_T, r, kCancelTag, gProgressComm);
}

// Caller holds gMpiMutex. Rank 0's cancel request, if one came: sets the cancel flag.
void receiveCancelLocked() {
  int flag = 0;
  MPI_Iprobe(0, kCancelTag, gProgressComm, &flag, MPI_STATUS_IGNORE);
  if (!flag) return;
  uint64_t msg = 0;
  MPI_Recv(&msg, 1, MPI_UINT64_T, 0, kCancelTag, gProgressComm, MPI_STATUS_IGNORE);
  cancelFlag().store(true);
}

// Caller holds gMpiMutex. Receives every pending progress report; a rank that reports it was
// interrupted (Ctrl-C reaches every rank, but SIGTERM may reach one) stops the whole job.
void drainProgressLocked() {
  for (;;) {
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, kProgressTag, gProgressComm, &flag, &status);
    if (!flag) return;
    uint64_t msg[3];
    MPI_Recv(msg, 3, MPI_UINT64_T, status.MPI_SOURCE, kProgressTag, gProgressComm,
             MPI_STATUS_IGNORE);
    RemoteProgress& r = gRemote[size_t(status.MPI_SOURCE)];
    if (msg[0] < r.stage) continue;  // a late report of an earlier stage
    r = {msg[0], msg[1], (msg[2] & 1u) != 0};
    if (msg[2] & 2u) {
      if (gCancelOrigin < 0) gCancelOrigin = status.MPI_SOURCE;
      broadcastCancelLocked();
    }
  }
}

void sendChunked(const std::byte* data, size_t bytes, int to) {
  for (size_t off = 0; off < bytes; off += kChunkBytes) {
    const int n = int(std::min(kChunkBytes, bytes - off));
    MPI_Send(data + off, n, MPI_BYTE, to, kDataTag, gDataComm);
  }
  gBytesSent += bytes;
}

void receiveChunked(std::byte* data, size_t bytes, int from) {
  for (size_t off = 0; off < bytes; off += kChunkBytes) {
    const int n = int(std::min(kChunkBytes, bytes - off));
    MPI_Recv(data + off, n, MPI_BYTE, from, kDataTag, gDataComm, MPI_STATUS_IGNORE);
  }
  gBytesReceived += bytes;
}
#endif

}  // namespace

Status startDistributed(bool force) {
  if (gStarted) return Status::success();
  const int announced = launcherSize();
  if (!force && announced == 0) return Status::success();
#ifdef KILN_WITH_MPI
  int initialized = 0;
  MPI_Initialized(&initialized);
  if (!initialized) {
    int provided = 0;
    if (MPI_Init_thread(nullptr, nullptr, MPI_THREAD_SERIALIZED, &provided) != MPI_SUCCESS)
      return Error{"MPI_Init_thread failed"};
    if (provided < MPI_THREAD_SERIALIZED) {
      MPI_Finalize();
      return Error{"the MPI library does not allow calls from several threads "
                   "(MPI_THREAD_SERIALIZED)"};
    }
  }
  // Errors inside MPI (a peer that died, a broken link) end the job rather than return.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_ARE_FATAL);
  MPI_Comm_rank(MPI_COMM_WORLD, &gRank);
  MPI_Comm_size(MPI_COMM_WORLD, &gSize);
  MPI_Comm_dup(MPI_COMM_WORLD, &gProgressComm);
  MPI_Comm_dup(MPI_COMM_WORLD, &gDataComm);
  gRemote.assign(size_t(gSize), RemoteProgress{});
  gStarted = true;
  return Status::success();
#else
  if (force)
    return Error{"--mpi: this kiln was built without MPI (configure with libopenmpi-dev "
                 "installed, KILN_WITH_MPI=ON)"};
  if (announced > 1)
    return Error{"started by an MPI launcher as one of " + std::to_string(announced) +
                 " processes, but this kiln was built without MPI (configure with "
                 "libopenmpi-dev installed, KILN_WITH_MPI=ON); each process would bake "
                 "everything and write the same files"};
  return Status::success();
#endif
}

void stopDistributed() {
#ifdef KILN_WITH_MPI
  if (!gStarted) return;
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) {
    MPI_Comm_free(&gProgressComm);
    MPI_Comm_free(&gDataComm);
    MPI_Finalize();
  }
  gStarted = false;
#endif
}

int distributedRank() { return gRank; }
bool distributedFailureAgreed() { return gFailureAgreed; }
int distributedSize() { return gSize; }

void distributedAbort(const std::string& message, int code) {
  std::fflush(stdout);
  if (message.empty()) {
  } else if (gSize > 1)
    std::fprintf(stderr, "kiln: error: rank %d of %d: %s\n", gRank, gSize, message.c_str());
  else
    std::fprintf(stderr, "kiln: error: %s\n", message.c_str());
  std::fflush(stderr);
#ifdef KILN_WITH_MPI
  if (gStarted) MPI_Abort(MPI_COMM_WORLD, code);
#endif
  std::exit(code);
}

WorkSplit splitWork(size_t count, size_t tile, const std::function<double(size_t)>& cost) {
  WorkSplit split;
  split.count = count;
  const int ranks = distributedSize();
  if (ranks == 1) return split;  // every item local: no costs to weigh
  std::vector<double> rankCost(size_t(ranks), 0.0);
  tile = std::max<size_t>(1, tile);
  split.owner.resize(count);
  for (size_t begin = 0; begin < count; begin += tile) {
    const size_t end = std::min(count, begin + tile);
    double c = 0.0;
    for (size_t i = begin; i < end; ++i) c += cost ? std::max(0.0, cost(i)) : 1.0;
    const size_t r =
        size_t(std::min_element(rankCost.begin(), rankCost.end()) - rankCost.begin());
    rankCost[r] += c;
    for (size_t i = begin; i < end; ++i) split.owner[i] = int32_t(r);
    if (int(r) == distributedRank())
      for (size_t i = begin; i < end; ++i) split.local.push_back(uint32_t(i));
  }
  return split;
}

bool parallelForLocal(const WorkSplit& split,
                      const std::function<void(size_t begin, size_t end)>& body,
                      const ParallelOptions& options) {
  if (!split.distributed()) return parallelFor(split.count, body, options);
  const std::vector<uint32_t>& local = split.local;
  return parallelFor(
      local.size(),
      [&](size_t begin, size_t end) {
        // Runs of consecutive items (a tile, or the part of it in this chunk).
        size_t run = begin;
        for (size_t j = begin + 1; j <= end; ++j)
          if (j == end || local[j] != local[j - 1] + 1) {
            body(local[run], size_t(local[j - 1]) + 1);
            run = j;
          }
      },
      options);
}

Status exchangeBytes(const WorkSplit& split, std::byte* data, size_t itemBytes, bool toAll,
                     bool localOk, bool localCancelled, Progress* progress) {
  if (!split.distributed()) return localOk ? Status::success() : Status(Error{"cancelled"});
#ifdef KILN_WITH_MPI
  const uint64_t stage = progress ? progress->distributedStage() : 0;
  if (stage != 0) {
    if (gRank != 0) {
      sendDistributedProgress(stage, progress->done(), true, localCancelled);
    } else {
      // Keep the line moving while the other ranks finish their shares.
      for (;;) {
        bool all = true;
        {
          std::lock_guard<std::mutex> lock(gMpiMutex);
          if (localCancelled) broadcastCancelLocked();
          drainProgressLocked();
          for (int r = 1; r < gSize; ++r)
            all = all && gRemote[size_t(r)].stage == stage && gRemote[size_t(r)].final;
        }
        if (all) break;
        progress->poll();
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    }
  }
  std::lock_guard<std::mutex> lock(gMpiMutex);
  // Every rank's state and share size.
  std::vector<uint64_t> local = {localOk ? 1u : 0u, localCancelled ? 1u : 0u,
                                 uint64_t(split.local.size()) * itemBytes};
  std::vector<uint64_t> all(3 * size_t(gSize));
  MPI_Allgather(local.data(), 3, MPI_UINT64_T, all.data(), 3, MPI_UINT64_T, gDataComm);
  for (int r = 0; r < gSize; ++r) {
    if (all[3 * size_t(r)]) continue;
    // The rank interrupted first, rather than those rank 0 then stopped.
    if (gCancelOrigin > 0 && !all[3 * size_t(gCancelOrigin)]) r = gCancelOrigin;
    bool anyCancelled = false;
    for (int q = 0; q < gSize; ++q) anyCancelled = anyCancelled || all[3 * size_t(q) + 1];
    if (anyCancelled) cancelFlag().store(true);
    const std::string what = "rank " + std::to_string(r) + " of " + std::to_string(gSize) +
                             (all[3 * size_t(r) + 1] ? " was interrupted" : " failed");
    if (gRank == 0) std::fprintf(stderr, "kiln: %s\n", what.c_str());
    gFailureAgreed = true;
    return Error{what};
  }
  if (gRank == 0) {
    std::vector<std::byte> buffer;
    for (int r = 1; r < gSize; ++r) {
      buffer.resize(size_t(all[3 * size_t(r) + 2]));
      receiveChunked(buffer.data(), buffer.size(), r);
      size_t at = 0;
      for (size_t i = 0; i < split.count; ++i) {
        if (split.owner[i] != r) continue;
        if (at + itemBytes > buffer.size())
          distributedAbort("rank " + std::to_string(r) + " sent fewer items than it owns",
                           1);
        std::memcpy(data + i * itemBytes, buffer.data() + at, itemBytes);
        at += itemBytes;
      }
    }
  } else {
    std::vector<std::byte> buffer(split.local.size() * itemBytes);
    for (size_t j = 0; j < split.local.size(); ++j)
      std::memcpy(buffer.data() + j * itemBytes, data + size_t(split.local[j]) * itemBytes,
                  itemBytes);
    sendChunked(buffer.data(), buffer.size(), 0);
  }
  if (toAll) {
    const size_t bytes = split.count * itemBytes;
    for (size_t off = 0; off < bytes; off += kChunkBytes) {
      const int n = int(std::min(kChunkBytes, bytes - off));
      MPI_Bcast(data + off, n, MPI_BYTE, 0, gDataComm);
    }
    if (gRank == 0)
      gBytesSent += bytes * size_t(gSize - 1);
    else
      gBytesReceived += bytes;
  }
  return Status::success();
#else
  (void)data;
  (void)itemBytes;
  (void)toAll;
  (void)localCancelled;
  (void)progress;
  return localOk ? Status::success() : Status(Error{"cancelled"});
#endif
}

uint64_t distributedBytesSent() { return gBytesSent; }
uint64_t distributedBytesReceived() { return gBytesReceived; }

uint64_t newDistributedStage() { return distributedActive() ? ++gStage : 0; }

void sendDistributedProgress(uint64_t stage, uint64_t done, bool final, bool cancelled) {
#ifdef KILN_WITH_MPI
  if (!gStarted || gRank == 0 || stage == 0) return;
  std::lock_guard<std::mutex> lock(gMpiMutex);
  const uint64_t msg[3] = {stage, done, (final ? 1u : 0u) | (cancelled ? 2u : 0u)};
  // 24 bytes: sent eagerly, returns without rank 0 posting a receive.
  MPI_Send(msg, 3, MPI_UINT64_T, 0, kProgressTag, gProgressComm);
  receiveCancelLocked();
#else
  (void)stage;
  (void)done;
  (void)final;
  (void)cancelled;
#endif
}

uint64_t remoteDistributedProgress(uint64_t stage) {
#ifdef KILN_WITH_MPI
  if (!gStarted || gRank != 0 || stage == 0) return 0;
  std::lock_guard<std::mutex> lock(gMpiMutex);
  drainProgressLocked();
  uint64_t sum = 0;
  for (int r = 1; r < gSize; ++r)
    if (gRemote[size_t(r)].stage == stage) sum += gRemote[size_t(r)].done;
  return sum;
#else
  (void)stage;
  return 0;
#endif
}

}  // namespace kiln
