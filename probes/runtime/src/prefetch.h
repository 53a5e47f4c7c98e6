// prefetch.h: a cache hint for kiln's passes over scattered cells (the lookup's walks, the
// topology build, validation). Private to kiln (the runtime and the bake tools).
#pragma once

namespace kiln::runtime_detail {

// Asks for the cache line at `address` to be fetched for reading; no effect on results.
inline void prefetch([[maybe_unused]] const void* address) noexcept {
#if defined(__GNUC__) || defined(__clang__)
  __builtin_prefetch(address, 0, 3);
#endif
}

}  // namespace kiln::runtime_detail
