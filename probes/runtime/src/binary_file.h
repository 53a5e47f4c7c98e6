// binary_file.h: kiln_runtime's file I/O for its binary formats (.kprobe, .klppv), shared by
// probe_set.cpp and lppv_volume.cpp. The runtime does not link kiln_core, whose
// src/text_file.h does the same for text.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "kiln/result.h"

namespace kiln::runtime_detail {

// Writes `bytes` to path + ".tmp", then renames it over `path`: readers never see a partly
// written file, and a failed write leaves the previous file intact.
Status writeFileAtomically(const std::string& path, const std::vector<uint8_t>& bytes);

// Reads a file whose first headerSize bytes say how long it must be. `expectedSize` gets the
// header (zero-padded when the file is shorter) and the bytes available (the file's size, or
// what was read of a short header) and returns the total size or an error; it runs before the
// payload is allocated, so a corrupt header cannot ask for gigabytes.
Result<std::vector<uint8_t>> readHeaderSizedFile(
    const std::string& path, size_t headerSize,
    const std::function<Result<uint64_t>(const uint8_t* header, uint64_t available)>&
        expectedSize);

}  // namespace kiln::runtime_detail
