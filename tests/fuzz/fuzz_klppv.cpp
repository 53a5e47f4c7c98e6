// fuzz_klppv.cpp: libFuzzer harness for the .klppv reader (probes/runtime/src/lppv_volume.cpp).
//
// parseLppvVolume is what loadLppvFile runs on a file's bytes: it must return a volume or an
// Error for every input and allocate only after the header's counts were checked against the
// input size. As for .kprobe, even-sized inputs get the right FNV-1a checksum stored first so
// that mutations reach the field checks; odd-sized ones keep theirs.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "kiln/lppv_volume.h"
#include "kiln/probe_set.h"  // binaryFileChecksum

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::vector<uint8_t> bytes(data, data + size);
  if (bytes.size() >= kiln::kLppvFileHeaderSize && !(size % 2)) {
    const uint64_t hash = kiln::binaryFileChecksum(bytes, kiln::kLppvFileChecksumOffset,
                                                   kiln::kLppvFileHeaderSize);
    std::memcpy(bytes.data() + kiln::kLppvFileChecksumOffset, &hash, 8);
  }
  kiln::Result<kiln::LppvVolume> volume = kiln::parseLppvVolume(bytes, "fuzz.klppv");
  if (volume) {
    const kiln::LppvVolume& v = volume.value();
    size_t cells = size_t(v.resolution.x) * v.resolution.y * v.resolution.z;
    if (v.validity.size() != cells) std::abort();
  }
  return 0;
}
