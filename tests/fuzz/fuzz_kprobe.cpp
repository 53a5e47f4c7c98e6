// fuzz_kprobe.cpp: libFuzzer harness for the .kprobe reader (probes/runtime/src/probe_set.cpp).
//
// parseProbeSet is what loadProbeFile runs on a file's bytes: it must return a ProbeSet or an
// Error for every input, allocate no more than the input justifies, and leave a set that
// validateProbeSet accepts. The file's FNV-1a checksum would make almost every mutation a
// checksum error, so the harness stores the right checksum for the mutated bytes first (with
// inputs shorter than the header left as they are): the fuzzer then reaches the field checks.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "kiln/probe_set.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  if (bytes.size() >= kiln::kProbeFileHeaderSize && !(size % 2)) {
    // Even-sized inputs get a valid checksum; odd-sized ones keep theirs (checksum path).
    const uint64_t hash = kiln::binaryFileChecksum(bytes, kiln::kProbeFileChecksumOffset,
                                                   kiln::kProbeFileHeaderSize);
    std::memcpy(bytes.data() + kiln::kProbeFileChecksumOffset, &hash, 8);
  }
  kiln::Result<kiln::ProbeSet> set = kiln::parseProbeSet(bytes, "fuzz.kprobe");
  if (set && !kiln::validateProbeSet(set.value(), "fuzz.kprobe")) std::abort();
  return 0;
}
