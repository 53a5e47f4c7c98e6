// lppv_volume.cpp: the LPPV grid at run time (lppv_volume.h): trilinear sampling, filling from
// the probe field with hinted walks along rows, validation, and the .klppv reader/writer. The
// reader treats files as untrusted: the header's resolution is checked against the file length
// before anything is allocated, and every value is checked before sampling may rely on it.
#include "kiln/lppv_volume.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>

#include "binary_file.h"
#include "kiln/probe_runtime.h"

namespace kiln {

static_assert(std::endian::native == std::endian::little,
              "the .klppv reader/writer assumes a little-endian host");
static_assert(sizeof(ShL2Rgb) == 27 * sizeof(float), "ShL2Rgb must be 27 packed floats");

namespace {

constexpr uint64_t kBytesPerCell = 27 * 4 + 4;
constexpr uint64_t kOcclusionBytesPerCell = 4 * 4;  // version 2 on

Error fail(std::string_view name, const std::string& what) {
  return Error{std::string(name) + ": " + what};
}

bool finite(glm::vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

template <typename T>
T readAt(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

struct Header {
  uint32_t version;
  uint32_t resolution[3];
  uint32_t placement;
  float boundsMin[3], boundsMax[3];
  uint32_t reserved[2];
  uint64_t checksum;
};

Header decodeHeader(const uint8_t* h) {
  Header r{};
  r.version = readAt<uint32_t>(h + 4);
  for (int a = 0; a < 3; ++a) {
    r.resolution[a] = readAt<uint32_t>(h + 8 + 4 * a);
    r.boundsMin[a] = readAt<float>(h + 24 + 4 * a);
    r.boundsMax[a] = readAt<float>(h + 36 + 4 * a);
  }
  r.placement = readAt<uint32_t>(h + 20);
  r.reserved[0] = readAt<uint32_t>(h + 48);
  r.reserved[1] = readAt<uint32_t>(h + 52);
  r.checksum = readAt<uint64_t>(h + kLppvFileChecksumOffset);
  return r;
}

// Checks the header alone and returns the total file size its resolution implies.
Result<uint64_t> checkHeader(const uint8_t* h, uint64_t available, std::string_view name) {
  if (available < kLppvFileHeaderSize) {
    return fail(name, "header: truncated (" + std::to_string(available) + " bytes, need " +
                          std::to_string(kLppvFileHeaderSize) + ")");
  }
  if (std::memcmp(h, "KLPV", 4) != 0) return fail(name, "magic: not a .klppv file");
  const Header hd = decodeHeader(h);
  if (hd.version < kLppvFileMinVersion || hd.version > kLppvFileVersion) {
    return fail(name, "version: file version " + std::to_string(hd.version) +
                          ", this reader supports " + std::to_string(kLppvFileMinVersion) + " to " +
                          std::to_string(kLppvFileVersion));
  }
  uint64_t cells = 1;
  static const char* kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (hd.resolution[a] < 1 || hd.resolution[a] > uint32_t(kLppvMaxAxis)) {
      return fail(name, std::string("resolution.") + kAxis[a] + ": " +
                            std::to_string(hd.resolution[a]) + " is not in [1, " +
                            std::to_string(kLppvMaxAxis) + "]");
    }
    cells *= hd.resolution[a];
  }
  if (cells > kLppvMaxCells) {
    return fail(name, "resolution: " + std::to_string(cells) + " cells, more than " +
                          std::to_string(kLppvMaxCells));
  }
  if (hd.placement > 1) {
    return fail(
        name, "placement: " + std::to_string(hd.placement) + " (0 = cell centre, 1 = cell corner)");
  }
  if (hd.reserved[0] != 0 || hd.reserved[1] != 0) return fail(name, "reserved: must be 0");
  const uint64_t perCell = kBytesPerCell + (hd.version >= 2 ? kOcclusionBytesPerCell : 0);
  const uint64_t expected = kLppvFileHeaderSize + cells * perCell;
  if (available != expected) {
    return fail(name, "size: file has " + std::to_string(available) +
                          " bytes but its resolution needs " + std::to_string(expected) +
                          (available < expected ? " (truncated)" : " (trailing data)"));
  }
  return expected;
}

// Grid coordinate along one axis (see locateLppv): lower sample, upper sample, weight of upper.
struct AxisLerp {
  uint32_t i0, i1;
  float t;
};

AxisLerp axisLerp(float p, float lo, float hi, int n, LppvPlacement placement) noexcept {
  if (n <= 1) return {0, 0, 0.0f};
  const float u = (p - lo) / (hi - lo);
  float f = placement == LppvPlacement::kCellCenter ? u * float(n) - 0.5f : u * float(n - 1);
  // Written so that NaN falls to 0 (comparisons with NaN are false).
  if (!(f > 0.0f)) f = 0.0f;
  if (f > float(n - 1)) f = float(n - 1);
  const int i0 = std::min(int(f), n - 2);
  return {uint32_t(i0), uint32_t(i0 + 1), f - float(i0)};
}

}  // namespace

glm::vec3 LppvVolume::samplePosition(int x, int y, int z) const {
  const glm::ivec3 i(x, y, z);
  glm::vec3 p;
  for (int a = 0; a < 3; ++a) {
    const int n = resolution[a];
    const float f = placement == LppvPlacement::kCellCorner && n > 1
                        ? float(i[a]) / float(n - 1)
                        : (float(i[a]) + 0.5f) / float(n);
    p[a] = boundsMin[a] + f * (boundsMax[a] - boundsMin[a]);
  }
  return p;
}

LppvVolume makeLppvVolume(glm::vec3 boundsMin, glm::vec3 boundsMax, glm::ivec3 resolution,
                          LppvPlacement placement) {
  LppvVolume v;
  v.boundsMin = boundsMin;
  v.boundsMax = boundsMax;
  v.resolution = resolution;
  v.placement = placement;
  assert(resolution.x >= 1 && resolution.y >= 1 && resolution.z >= 1);
  assert(resolution.x <= kLppvMaxAxis && resolution.y <= kLppvMaxAxis &&
         resolution.z <= kLppvMaxAxis);
  assert(boundsMin.x < boundsMax.x && boundsMin.y < boundsMax.y && boundsMin.z < boundsMax.z);
  v.sh.assign(v.cellCount(), ShL2Rgb{});
  v.validity.assign(v.cellCount(), 1.0f);
  v.occlusion.assign(v.cellCount(), glm::vec4(1.0f));
  return v;
}

Status validateLppvVolume(const LppvVolume& v, std::string_view name) {
  static const char* kAxis[3] = {"x", "y", "z"};
  for (int a = 0; a < 3; ++a) {
    if (v.resolution[a] < 1 || v.resolution[a] > kLppvMaxAxis) {
      return fail(name, std::string("resolution.") + kAxis[a] + ": " +
                            std::to_string(v.resolution[a]) + " is not in [1, " +
                            std::to_string(kLppvMaxAxis) + "]");
    }
  }
  if (uint64_t(v.cellCount()) > kLppvMaxCells) return fail(name, "resolution: too many cells");
  if (v.placement != LppvPlacement::kCellCenter && v.placement != LppvPlacement::kCellCorner) {
    return fail(name, "placement: unknown value");
  }
  if (!finite(v.boundsMin) || !finite(v.boundsMax)) return fail(name, "bounds: not finite");
  for (int a = 0; a < 3; ++a) {
    // Also rejects extents so small that (p - min) / (max - min) overflows.
    if (!(v.boundsMax[a] > v.boundsMin[a]) ||
        !std::isfinite(1.0f / (v.boundsMax[a] - v.boundsMin[a]))) {
      return fail(name, std::string("bounds.") + kAxis[a] + ": max must exceed min");
    }
  }
  const size_t n = v.cellCount();
  if (v.sh.size() != n) return fail(name, "sh: size differs from the resolution's cell count");
  if (v.validity.size() != n) {
    return fail(name, "validity: size differs from the resolution's cell count");
  }
  if (!v.occlusion.empty() && v.occlusion.size() != n) {
    return fail(name, "occlusion: size differs from the resolution's cell count");
  }
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < kShL2Count; ++k) {
      if (!finite(v.sh[i].c[k])) {
        return fail(name, "sh[" + std::to_string(i) + "][" + std::to_string(k) + "]: not finite");
      }
    }
    if (!(v.validity[i] >= 0.0f && v.validity[i] <= 1.0f)) {
      return fail(name, "validity[" + std::to_string(i) + "]: not in [0, 1]");
    }
    for (int c = 0; c < 4 && !v.occlusion.empty(); ++c) {
      if (!(v.occlusion[i][c] >= 0.0f && v.occlusion[i][c] <= 1.0f)) {
        return fail(
            name, "occlusion[" + std::to_string(i) + "][" + std::to_string(c) + "]: not in [0, 1]");
      }
    }
  }
  return Status::success();
}

LppvTrilinear locateLppv(const LppvVolume& v, glm::vec3 p) noexcept {
  const AxisLerp ax = axisLerp(p.x, v.boundsMin.x, v.boundsMax.x, v.resolution.x, v.placement);
  const AxisLerp ay = axisLerp(p.y, v.boundsMin.y, v.boundsMax.y, v.resolution.y, v.placement);
  const AxisLerp az = axisLerp(p.z, v.boundsMin.z, v.boundsMax.z, v.resolution.z, v.placement);
  const uint32_t nx = uint32_t(v.resolution.x), nxy = nx * uint32_t(v.resolution.y);
  LppvTrilinear r;
  for (int k = 0; k < 8; ++k) {
    const bool hx = k & 1, hy = (k >> 1) & 1, hz = (k >> 2) & 1;
    r.cells[k] = (hx ? ax.i1 : ax.i0) + nx * (hy ? ay.i1 : ay.i0) + nxy * (hz ? az.i1 : az.i0);
    r.weights[k] =
        (hx ? ax.t : 1.0f - ax.t) * (hy ? ay.t : 1.0f - ay.t) * (hz ? az.t : 1.0f - az.t);
  }
  return r;
}

ShL2Rgb sampleLppv(const LppvVolume& v, glm::vec3 p) noexcept {
  const LppvTrilinear t = locateLppv(v, p);
  ShL2Rgb r;
  for (int k = 0; k < 8; ++k) {
    const ShL2Rgb& s = v.sh[t.cells[k]];
    for (int i = 0; i < kShL2Count; ++i) r.c[i] += t.weights[k] * s.c[i];
  }
  return r;
}

float sampleLppvValidity(const LppvVolume& v, glm::vec3 p) noexcept {
  const LppvTrilinear t = locateLppv(v, p);
  float r = 0.0f;
  for (int k = 0; k < 8; ++k) r += t.weights[k] * v.validity[t.cells[k]];
  return r;
}

glm::vec4 sampleLppvOcclusion(const LppvVolume& v, glm::vec3 p) noexcept {
  if (v.occlusion.empty()) return glm::vec4(1.0f);
  const LppvTrilinear t = locateLppv(v, p);
  glm::vec4 r(0.0f);
  float sum = 0.0f;
  for (int k = 0; k < 8; ++k) {
    r += t.weights[k] * v.occlusion[t.cells[k]];
    sum += t.weights[k];
  }
  // As interpolateOcclusion: an all-1 neighbourhood gives exactly 1.
  if (sum > 0.0f) r /= sum;
  return glm::clamp(r, glm::vec4(0.0f), glm::vec4(1.0f));
}

glm::vec3 lppvIrradiance(const LppvVolume& v, glm::vec3 p, glm::vec3 n) noexcept {
  return probeIrradiance(sampleLppv(v, p), n);
}

void sampleLppv(const LppvVolume& v, std::span<const glm::vec3> points,
                std::span<ShL2Rgb> out) noexcept {
  assert(out.size() == points.size());
  const size_t n = std::min(points.size(), out.size());
  for (size_t i = 0; i < n; ++i) out[i] = sampleLppv(v, points[i]);
}

void fillLppvRows(const ProbeSet& set, LppvVolume& v, size_t rowBegin, size_t rowEnd) noexcept {
  assert(v.sh.size() == v.cellCount() && v.validity.size() == v.cellCount());
  const int nx = v.resolution.x, ny = v.resolution.y;
  rowEnd = std::min(rowEnd, size_t(ny) * size_t(v.resolution.z));
  for (size_t row = rowBegin; row < rowEnd; ++row) {
    const int y = int(row % size_t(ny)), z = int(row / size_t(ny));
    // Each row starts from the seed grid, so a row's values never depend on which rows were
    // filled before it (identical results for any split of the rows among threads).
    int32_t hint = -1;
    for (int x = 0; x < nx; ++x) {
      const ProbeLocation loc = locateProbe(set, v.samplePosition(x, y, z), hint);
      hint = loc.cell;
      const size_t cell = v.cellIndex(x, y, z);
      v.sh[cell] = interpolateProbes(set, loc);
      float validity = 0.0f;
      for (int k = 0; k < 4; ++k) {
        if (loc.cell >= 0) validity += loc.weights[k] * set.validity[size_t(loc.probes[k])];
      }
      v.validity[cell] = loc.cell >= 0 ? std::clamp(validity, 0.0f, 1.0f) : 0.0f;
      if (v.occlusion.size() == v.cellCount()) v.occlusion[cell] = interpolateOcclusion(set, loc);
    }
  }
}

std::vector<uint8_t> serializeLppvVolume(const LppvVolume& v, uint32_t version) {
  std::vector<uint8_t> out(kLppvFileHeaderSize, 0);
  std::memcpy(out.data(), "KLPV", 4);
  const uint32_t words[] = {version, uint32_t(v.resolution.x), uint32_t(v.resolution.y),
                            uint32_t(v.resolution.z), uint32_t(v.placement)};
  std::memcpy(out.data() + 4, words, sizeof(words));
  std::memcpy(out.data() + 24, &v.boundsMin, 12);
  std::memcpy(out.data() + 36, &v.boundsMax, 12);
  const size_t shBytes = v.sh.size() * sizeof(ShL2Rgb);
  const size_t validityBytes = v.validity.size() * sizeof(float);
  std::vector<glm::vec4> occlusion;
  if (version >= 2) {
    occlusion =
        v.occlusion.empty() ? std::vector<glm::vec4>(v.sh.size(), glm::vec4(1.0f)) : v.occlusion;
  }
  const size_t occlusionBytes = occlusion.size() * sizeof(glm::vec4);
  out.resize(kLppvFileHeaderSize + shBytes + validityBytes + occlusionBytes);
  if (shBytes) std::memcpy(out.data() + kLppvFileHeaderSize, v.sh.data(), shBytes);
  if (validityBytes) {
    std::memcpy(out.data() + kLppvFileHeaderSize + shBytes, v.validity.data(), validityBytes);
  }
  if (occlusionBytes) {
    std::memcpy(out.data() + kLppvFileHeaderSize + shBytes + validityBytes, occlusion.data(),
                occlusionBytes);
  }
  const uint64_t sum = binaryFileChecksum(out, kLppvFileChecksumOffset, kLppvFileHeaderSize);
  std::memcpy(out.data() + kLppvFileChecksumOffset, &sum, 8);
  return out;
}

Result<LppvVolume> parseLppvVolume(std::span<const uint8_t> bytes, std::string_view name) {
  Result<uint64_t> size = checkHeader(bytes.data(), bytes.size(), name);
  if (!size) return Error{size.error()};
  const Header hd = decodeHeader(bytes.data());
  if (binaryFileChecksum(bytes, kLppvFileChecksumOffset, kLppvFileHeaderSize) != hd.checksum) return fail(name, "checksum: payload does not match (corrupt file)");

  LppvVolume v;
  v.resolution = glm::ivec3(int(hd.resolution[0]), int(hd.resolution[1]), int(hd.resolution[2]));
  v.placement = LppvPlacement(hd.placement);
  v.boundsMin = glm::vec3(hd.boundsMin[0], hd.boundsMin[1], hd.boundsMin[2]);
  v.boundsMax = glm::vec3(hd.boundsMax[0], hd.boundsMax[1], hd.boundsMax[2]);
  const size_t n = v.cellCount();
  v.sh.resize(n);
  v.validity.resize(n);
  const uint8_t* p = bytes.data() + kLppvFileHeaderSize;
  std::memcpy(v.sh.data(), p, n * sizeof(ShL2Rgb));
  std::memcpy(v.validity.data(), p + n * sizeof(ShL2Rgb), n * sizeof(float));
  v.occlusion.resize(n);
  if (hd.version >= 2) {
    std::memcpy(v.occlusion.data(), p + n * (sizeof(ShL2Rgb) + sizeof(float)),
                n * sizeof(glm::vec4));
  } else {
    std::fill(v.occlusion.begin(), v.occlusion.end(), glm::vec4(1.0f));  // predates occlusion
  }
  Status st = validateLppvVolume(v, name);
  if (!st) return Error{st.error()};
  return v;
}

Status writeLppvFile(const LppvVolume& v, const std::string& path) {
  return runtime_detail::writeFileAtomically(path, serializeLppvVolume(v));
}

Result<LppvVolume> loadLppvFile(const std::string& path) {
  Result<std::vector<uint8_t>> bytes = runtime_detail::readHeaderSizedFile(
      path, kLppvFileHeaderSize, [&](const uint8_t* header, uint64_t available) {
        return checkHeader(header, available, path);
      });
  if (!bytes) return Error{bytes.error()};
  return parseLppvVolume(*bytes, path);
}

}  // namespace kiln
