// text_file.h: small text files. Outputs (JSON, CSV, scripts) are written the way every kiln
// output is written: into `path.tmp`, then renamed over `path`, so a failure or a cancelled
// run never leaves a half-written file and an earlier file stays as it was. JSON inputs are
// read with errors that name the file.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "kiln/result.h"

namespace kiln {

// Writes `text` to `path` atomically (temporary file + rename). On failure the temporary is
// removed, `path` is untouched, and the error names the file.
Status writeTextFileAtomically(const std::string& path, std::string_view text);

// Reads and parses a JSON file (manifests, indexes, sphere lists). Errors name the file:
// "<path>: cannot open", "<path>: malformed JSON: <the parser's message>".
// Regular files only: a FIFO, device or socket also refused ("<path>: is not a regular file
// ..."), since reading one can block forever or never end.
Result<nlohmann::json> readJsonFile(const std::string& path);

// Success when `path` is missing (the open that follows reports it) or a regular file (or a
// link to one); otherwise "<path>: is not a regular file (a FIFO, device, socket or
// directory)". Every kiln reader calls it before opening its input (docs/limits.md).
Status checkRegularFile(const std::string& path);

}  // namespace kiln
