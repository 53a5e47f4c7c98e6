// text_file.h: writing small text outputs (JSON, CSV, scripts) the way every kiln output is
// written: into `path.tmp`, then renamed over `path`, so a failure or a cancelled run never
// leaves a half-written file and an earlier file stays as it was.
#pragma once

#include <string>
#include <string_view>

#include "src/result.h"

namespace kiln {

// Writes `text` to `path` atomically (temporary file + rename). On failure the temporary is
// removed, `path` is untouched, and the error names the file.
Status writeTextFileAtomically(const std::string& path, std::string_view text);

}  // namespace kiln
