// binary_file.cpp: see binary_file.h.
#include "binary_file.h"

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <system_error>

namespace kiln::runtime_detail {

Status writeFileAtomically(const std::string& path, const std::vector<uint8_t>& bytes) {
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return Error{tmp + ": cannot open for writing"};
  const size_t written = std::fwrite(bytes.data(), 1, bytes.size(), f);
  const bool closed = std::fclose(f) == 0;
  if (written != bytes.size() || !closed) {
    std::remove(tmp.c_str());
    return Error{tmp + ": write failed"};
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::remove(tmp.c_str());
    return Error{path + ": cannot rename from " + tmp + ": " + ec.message()};
  }
  return Status::success();
}

Result<std::vector<uint8_t>> readHeaderSizedFile(
    const std::string& path, size_t headerSize,
    const std::function<Result<uint64_t>(const uint8_t* header, uint64_t available)>&
        expectedSize) {
  // Regular files only, checked before opening: opening a FIFO blocks until a writer comes,
  // and a device (/dev/zero) has no end to read to.
  std::error_code ec;
  const std::filesystem::file_status st = std::filesystem::status(path, ec);
  if (!ec && std::filesystem::exists(st) && !std::filesystem::is_regular_file(st))
    return Error{path + ": is not a regular file (a FIFO, device, socket or directory)"};
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return Error{path + ": cannot open"};
  struct Closer {
    std::FILE* f;
    ~Closer() { std::fclose(f); }
  } closer{f};
  if (std::fseek(f, 0, SEEK_END) != 0) return Error{path + ": cannot seek"};
  const long end = std::ftell(f);
  if (end < 0) return Error{path + ": cannot tell size"};
  std::rewind(f);
  const uint64_t fileSize = uint64_t(end);
  std::vector<uint8_t> header(headerSize, 0);
  const size_t got = std::fread(header.data(), 1, std::min<uint64_t>(fileSize, headerSize), f);
  Result<uint64_t> expected = expectedSize(header.data(), got < headerSize ? got : fileSize);
  if (!expected) return Error{expected.error()};
  std::vector<uint8_t> bytes(static_cast<size_t>(expected.value()));
  std::memcpy(bytes.data(), header.data(), headerSize);
  const size_t rest = bytes.size() - headerSize;
  if (std::fread(bytes.data() + headerSize, 1, rest, f) != rest)
    return Error{path + ": read failed"};
  return bytes;
}

}  // namespace kiln::runtime_detail
