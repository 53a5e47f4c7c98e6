// huge_pages.h: the topology build's large new arrays on transparent huge pages (private to
// probes/). No effect on results.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace kiln::detail {

// Asks the kernel to back the 2 MB-aligned pages inside [address, address + bytes) with
// transparent huge pages when they are first touched (Linux with THP in "always" or "madvise"
// mode; a no-op elsewhere, or when the kernel declines: then 4 KB pages as before). A
// 100k-probe build writes about 100 MB of new arrays, the walk records alone 43 MB: in 4 KB
// pages that is a page fault per 4 KB (the walk array's zero-fill cost 17-24 ms CPU, 5-6 ms on
// huge pages; docs/probes.md "Speed").
inline void adviseHugePages([[maybe_unused]] const void* address,
                            [[maybe_unused]] size_t bytes) noexcept {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
  constexpr uintptr_t kHuge = uintptr_t(1) << 21;
  const uintptr_t begin = (uintptr_t(address) + kHuge - 1) & ~(kHuge - 1);
  const uintptr_t end = (uintptr_t(address) + bytes) & ~(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);
#endif
}

// v.reserve(n) on an empty vector, its new storage advised as above when it spans a few huge
// pages: for arrays the build then writes whole (no memory is wasted: the advice covers only
// whole 2 MB pages inside the array, which malloc gives to this array alone while it lives).
template <class T>
void reserveOnHugePages(std::vector<T>& v, size_t n) {
  const bool fresh = v.capacity() == 0;
  v.reserve(n);
  constexpr size_t kMinBytes = size_t(4) << 20;
  if (fresh && n * sizeof(T) >= kMinBytes) adviseHugePages(v.data(), n * sizeof(T));
}

}  // namespace kiln::detail
