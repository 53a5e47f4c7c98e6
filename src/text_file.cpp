// text_file.cpp: atomic text output and JSON input (see text_file.h).
#include "src/text_file.h"

#include <cstdio>
#include <filesystem>
#include <fstream>

namespace kiln {

Status writeTextFileAtomically(const std::string& path, std::string_view text) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return Error{path + ": cannot open for writing"};
    out.write(text.data(), std::streamsize(text.size()));
    out.close();
    if (!out) {
      std::remove(tmp.c_str());
      return Error{path + ": write failed"};
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    return Error{path + ": cannot rename from " + tmp + ": " + ec.message()};
  }
  return Status::success();
}

Status checkRegularFile(const std::string& path) {
  std::error_code ec;
  std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(st) || std::filesystem::is_regular_file(st))
    return Status::success();
  return Error{path + ": is not a regular file (a FIFO, device, socket or directory)"};
}

Result<nlohmann::json> readJsonFile(const std::string& path) {
  if (Status regular = checkRegularFile(path); !regular) return Error{regular.error()};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open"};
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    return Error{path + ": malformed JSON: " + e.what()};
  }
}

}  // namespace kiln
