// probe_set.cpp: derived runtime data (outer-cell cubics, seed grid), validation, and the
// .kprobe reader/writer (format in probe_set.h). The reader treats files as untrusted: header
// counts are checked against the file length before anything is allocated, and every index
// and value is checked before the lookup may rely on it.
#include "kiln/probe_set.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

#include "binary_file.h"
#include "kiln/probe_runtime.h"
#include "prefetch.h"
#include "seed_grid.h"

namespace kiln {

static_assert(std::endian::native == std::endian::little,
              "the .kprobe reader/writer assumes a little-endian host");
static_assert(sizeof(ShL2Rgb) == 27 * sizeof(float), "ShL2Rgb must be 27 packed floats");
static_assert(sizeof(glm::vec3) == 12 && sizeof(glm::ivec4) == 16 && sizeof(glm::vec4) == 16);

namespace {

using runtime_detail::prefetch;

// Limits that keep every size computation far from overflow.
constexpr uint32_t kMaxProbes = 1u << 26;
constexpr uint32_t kMaxCells = 1u << 28;
constexpr uint32_t kMaxGridAxis = 1024;
constexpr uint64_t kMaxGridCells = 1u << 24;

constexpr uint64_t kBytesPerProbe = 12 + 108 + 4;
constexpr uint64_t kBytesPerCell = 16 + 16;
constexpr uint64_t kBytesPerOuterCell = 36 + 64;
// Version 2's occlusion block: channel lights, then 4 floats per probe.
constexpr uint64_t kOcclusionLightsBytes = 4 * 4;
constexpr uint64_t kOcclusionBytesPerProbe = 4 * 4;
// Version 4's sun block: i32 sunLight, then when it is >= 0 the light's SH, one visibility per
// probe, u32 rampCount and rampCount ramps of 4 floats.
constexpr uint64_t kSunLightBytes = 4;
constexpr uint64_t kSunShBytes = sizeof(ShL2Rgb);
constexpr uint64_t kSunBytesPerProbe = 4;
constexpr uint64_t kSunRampCountBytes = 4;
constexpr uint64_t kSunBytesPerRamp = 16;

Error fail(std::string_view name, const std::string& what) {
  return Error{std::string(name) + ": " + what};
}

bool finite(glm::vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Whether none of `count` floats is an infinity or a NaN (exponent bits all set), in one pass
// that the compiler vectorises.
bool allFiniteFloats(const float* values, size_t count) {
  uint32_t bad = 0;
  for (size_t i = 0; i < count; ++i) {
    uint32_t bits;
    std::memcpy(&bits, values + i, 4);
    bad |= uint32_t((bits & 0x7f800000u) == 0x7f800000u);
  }
  return bad == 0;
}

// Whether every one of `count` floats is in [0, 1] (NaN is not), likewise.
bool allInUnitInterval(const float* values, size_t count) {
  bool ok = true;
  for (size_t i = 0; i < count; ++i) ok &= values[i] >= 0.0f && values[i] <= 1.0f;
  return ok;
}

// Number of vertex slots a cell uses, by dimension and kind.
int usedSlots(int dimension, bool outer) {
  switch (dimension) {
    case 3: return outer ? 3 : 4;
    case 2: return outer ? 2 : 3;
    case 1: return 2;
    default: return 1;
  }
}

struct Header {
  uint32_t version, dimension, probeCount, cellCount, innerCellCount;
  uint32_t gridSize[3];
  float gridMin[3], gridMax[3];
  uint32_t visibilityResolution;  // "reserved" (0) before version 3
  uint64_t checksum;
};

template <typename T>
T readAt(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

Header decodeHeader(const uint8_t* h) {
  Header r{};
  r.version = readAt<uint32_t>(h + 4);
  r.dimension = readAt<uint32_t>(h + 8);
  r.probeCount = readAt<uint32_t>(h + 12);
  r.cellCount = readAt<uint32_t>(h + 16);
  r.innerCellCount = readAt<uint32_t>(h + 20);
  for (int i = 0; i < 3; ++i) {
    r.gridSize[i] = readAt<uint32_t>(h + 24 + 4 * i);
    r.gridMin[i] = readAt<float>(h + 36 + 4 * i);
    r.gridMax[i] = readAt<float>(h + 48 + 4 * i);
  }
  r.visibilityResolution = readAt<uint32_t>(h + 60);
  r.checksum = readAt<uint64_t>(h + kProbeFileChecksumOffset);
  return r;
}

// Checks the header alone and returns the total file size its counts imply.
Result<uint64_t> checkHeader(const uint8_t* h, uint64_t available, std::string_view name) {
  if (available < kProbeFileHeaderSize) {
    return fail(name, "header: truncated (" + std::to_string(available) + " bytes, need " +
                          std::to_string(kProbeFileHeaderSize) + ")");
  }
  if (std::memcmp(h, "KPRB", 4) != 0) return fail(name, "magic: not a .kprobe file");
  const Header hd = decodeHeader(h);
  if (hd.version < kProbeFileMinVersion || hd.version > kProbeFileVersion) {
    return fail(name, "version: file version " + std::to_string(hd.version) +
                          ", this reader supports " + std::to_string(kProbeFileMinVersion) +
                          " to " + std::to_string(kProbeFileVersion));
  }
  if (hd.dimension > 3) return fail(name, "dimension: " + std::to_string(hd.dimension));
  if (hd.probeCount == 0 || hd.probeCount > kMaxProbes) {
    return fail(name, "probeCount: " + std::to_string(hd.probeCount) + " out of range");
  }
  if (hd.cellCount == 0 || hd.cellCount > kMaxCells) {
    return fail(name, "cellCount: " + std::to_string(hd.cellCount) + " out of range");
  }
  if (hd.innerCellCount == 0 || hd.innerCellCount > hd.cellCount) {
    return fail(name, "innerCellCount: " + std::to_string(hd.innerCellCount) +
                          " out of range (cellCount " + std::to_string(hd.cellCount) + ")");
  }
  uint64_t gridCells = 1;
  for (int i = 0; i < 3; ++i) {
    if (hd.gridSize[i] > kMaxGridAxis) {
      return fail(name, "gridSize[" + std::to_string(i) + "]: " +
                            std::to_string(hd.gridSize[i]) + " out of range");
    }
    gridCells *= hd.gridSize[i];
  }
  if (gridCells > kMaxGridCells) return fail(name, "gridSize: too many grid cells");
  const uint32_t vr = hd.visibilityResolution;
  if (hd.version < 3 && vr != 0) return fail(name, "reserved: must be 0");
  if (!isVisibilityResolution(vr)) {
    return fail(name, "visibilityResolution: " + std::to_string(vr) + " out of range (0, or " +
                          std::to_string(kMinVisibilityResolution) + " to " +
                          std::to_string(kMaxVisibilityResolution) + ")");
  }
  const uint64_t outer = hd.cellCount - hd.innerCellCount;
  uint64_t expected = kProbeFileHeaderSize + hd.probeCount * kBytesPerProbe +
                      hd.cellCount * kBytesPerCell + outer * kBytesPerOuterCell + gridCells * 4;
  if (hd.version >= 2) {
    expected += kOcclusionLightsBytes + hd.probeCount * kOcclusionBytesPerProbe;
  }
  expected += hd.probeCount * visibilityBytesPerProbe(vr);
  if (hd.version < 4) {
    if (available != expected) {
      return fail(name, "size: file has " + std::to_string(available) +
                            " bytes but its header counts need " + std::to_string(expected) +
                            (available < expected ? " (truncated)" : " (trailing data)"));
    }
    return expected;
  }
  // Version 4: the sun block's size depends on its own fields (checkSunBlock reads them);
  // here only the range the header's counts allow, from sunLight -1 alone to a full layer
  // with one ramp per inner cell, so that no file makes the reader allocate beyond that.
  const uint64_t least = expected + kSunLightBytes;
  const uint64_t most = least + kSunShBytes + hd.probeCount * kSunBytesPerProbe +
                        kSunRampCountBytes + uint64_t(hd.innerCellCount) * kSunBytesPerRamp;
  if (available < least) {
    return fail(name, "size: file has " + std::to_string(available) +
                          " bytes but its header counts need at least " + std::to_string(least) +
                          " (truncated)");
  }
  if (available > most) {
    return fail(name, "size: file has " + std::to_string(available) +
                          " bytes but its header counts allow at most " + std::to_string(most) +
                          " (trailing data)");
  }
  return available;
}

// Offset of the version 4 sun block (sunLight) in a file whose header checkHeader accepted.
uint64_t sunBlockOffset(const Header& hd) {
  const uint64_t outer = hd.cellCount - hd.innerCellCount;
  const uint64_t gridCells = uint64_t(hd.gridSize[0]) * hd.gridSize[1] * hd.gridSize[2];
  return kProbeFileHeaderSize + hd.probeCount * kBytesPerProbe + hd.cellCount * kBytesPerCell +
         outer * kBytesPerOuterCell + gridCells * 4 + kOcclusionLightsBytes +
         hd.probeCount * kOcclusionBytesPerProbe +
         hd.probeCount * visibilityBytesPerProbe(hd.visibilityResolution);
}

// Version 4: the sun block's fields that size it (sunLight, rampCount) against the bytes the
// file has, before the checksum is computed and anything is read. `available` is at least
// sunBlockOffset + 4 (checkHeader).
Status checkSunBlock(std::span<const uint8_t> bytes, const Header& hd, std::string_view name) {
  const uint64_t at = sunBlockOffset(hd), available = bytes.size();
  const int32_t light = readAt<int32_t>(bytes.data() + at);
  if (light < -1) {
    return fail(name, "sunLight: " + std::to_string(light) + " is not a light or -1");
  }
  uint64_t expected = at + kSunLightBytes;
  if (light >= 0) {
    const uint64_t rampCountAt = expected + kSunShBytes + hd.probeCount * kSunBytesPerProbe;
    if (available < rampCountAt + kSunRampCountBytes) {
      return fail(name, "size: file has " + std::to_string(available) + " bytes but sunLight " +
                            std::to_string(light) + " needs at least " +
                            std::to_string(rampCountAt + kSunRampCountBytes) + " (truncated)");
    }
    const uint32_t ramps = readAt<uint32_t>(bytes.data() + rampCountAt);
    if (ramps != 0 && ramps != hd.innerCellCount) {
      return fail(name, "sunRampCount: " + std::to_string(ramps) + " is neither 0 nor " +
                            "innerCellCount (" + std::to_string(hd.innerCellCount) + ")");
    }
    if (ramps != 0 && hd.dimension != 3) {
      return fail(name, "sunRampCount: " + std::to_string(ramps) + " ramps in dimension " +
                            std::to_string(hd.dimension) + " (only tetrahedra have ramps)");
    }
    expected = rampCountAt + kSunRampCountBytes + uint64_t(ramps) * kSunBytesPerRamp;
  }
  if (available != expected) {
    return fail(name, "size: file has " + std::to_string(available) +
                          " bytes but its header counts and sun block need " +
                          std::to_string(expected) +
                          (available < expected ? " (truncated)" : " (trailing data)"));
  }
  return Status::success();
}

template <typename T>
void put(std::vector<uint8_t>& out, const T* data, size_t count) {
  const size_t at = out.size();
  out.resize(at + sizeof(T) * count);
  if (count) std::memcpy(out.data() + at, data, sizeof(T) * count);
}

template <typename T>
void take(const uint8_t*& p, std::vector<T>& v, size_t count) {
  v.resize(count);
  if (count) std::memcpy(v.data(), p, sizeof(T) * count);
  p += sizeof(T) * count;
}

// The visibility block: a resolution the format allows, one maxDistance and one map per probe,
// and spreads that values in [0, 1] can have.
Status validateVisibility(const ProbeVisibility& v, size_t np, std::string_view name) {
  if (v.resolution == 0) {
    if (!v.maxDistance.empty() || !v.moments.empty())
      return fail(name, "visibility: data without a resolution");
    return Status::success();
  }
  if (!isVisibilityResolution(v.resolution)) {
    return fail(name, "visibilityResolution: " + std::to_string(v.resolution) +
                          " out of range (0, or " + std::to_string(kMinVisibilityResolution) +
                          " to " + std::to_string(kMaxVisibilityResolution) + ")");
  }
  if (v.maxDistance.size() != np)
    return fail(name, "visibilityMaxDistance: size differs from positions");
  if (v.moments.size() != np * v.valuesPerProbe())
    return fail(name, "visibilityMoments: size differs from probeCount x resolution^2 x 3");
  // sigma is an RMS of fractions of D about a fit through them: above 1/2 it is no spread of
  // values in [0, 1].
  constexpr uint16_t kMaxSigma = 32768;  // 1/2 rounded up to unorm16
  const size_t texels = v.valuesPerProbe() / kVisibilityValuesPerTexel;
  for (size_t i = 0; i < np; ++i) {
    const float d = v.maxDistance[i];
    if (!(std::isfinite(d) && d > 0.0f)) {
      return fail(name, "visibilityMaxDistance[" + std::to_string(i) +
                            "]: not a finite distance > 0");
    }
    for (size_t t = 0; t < texels; ++t) {
      if (v.moments[kVisibilityValuesPerTexel * (i * texels + t) + 1] > kMaxSigma) {
        return fail(name, "visibilityMoments[" + std::to_string(i) + "][" + std::to_string(t) +
                              "]: spread above half the distance range");
      }
    }
  }
  return Status::success();
}

// Whether every ramp is four finite floats or four NaNs (x NaN = no ramp), without branches on
// the data (one per inner cell: a 100k-probe set has over half a million).
bool rampsValid(const glm::vec4* ramps, size_t count) {
  bool ok = true;
#ifdef __SSE2__
  // The four lanes at once: exponent bits all set (an infinity or NaN), and of those the NaNs
  // (mantissa not zero); a ramp is fine with no such lane or four NaNs.
  const __m128i exponent = _mm_set1_epi32(0x7f800000), mantissa = _mm_set1_epi32(0x007fffff);
  const __m128i zero = _mm_setzero_si128();
  for (size_t c = 0; c < count; ++c) {
    const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(&ramps[c]));
    const __m128i special = _mm_cmpeq_epi32(_mm_and_si128(b, exponent), exponent);
    const __m128i nan = _mm_andnot_si128(_mm_cmpeq_epi32(_mm_and_si128(b, mantissa), zero), special);
    const int s = _mm_movemask_ps(_mm_castsi128_ps(special));
    const int n = _mm_movemask_ps(_mm_castsi128_ps(nan));
    ok &= (s == 0) | (n == 0xf);
  }
#else
  for (size_t c = 0; c < count; ++c) {
    uint32_t bits[4];
    std::memcpy(bits, &ramps[c], 16);
    uint32_t special = 0, nan = 0;  // lanes with exponent bits all set; lanes that are NaN
    for (int k = 0; k < 4; ++k) {
      const uint32_t exponentAllSet = uint32_t((bits[k] & 0x7f800000u) == 0x7f800000u);
      special += exponentAllSet;
      nan += exponentAllSet & uint32_t((bits[k] & 0x007fffffu) != 0);
    }
    ok &= special == 0 || nan == 4;
  }
#endif
  return ok;
}

// The sun layer (ProbeSunLayer): nothing without a light; with one, a finite lobe, one
// visibility in [0, 1] per probe, and no ramps or one per inner cell of a dimension 3 set,
// each four finite values or four NaNs. Sizes must be checked first for probes; cells' too.
Status validateSunLayer(const ProbeSet& s, std::string_view name) {
  const ProbeSunLayer& sun = s.sun;
  if (sun.light < -1) {
    return fail(name, "sun.light: " + std::to_string(sun.light) + " is not a light or -1");
  }
  if (sun.light < 0) {
    if (!sun.visibility.empty()) return fail(name, "sun.visibility: data without a light");
    if (!sun.ramps.empty()) return fail(name, "sun.ramps: data without a light");
    return Status::success();
  }
  for (int k = 0; k < kShL2Count; ++k) {
    if (!finite(sun.sh.c[k])) return fail(name, "sun.sh[" + std::to_string(k) + "]: not finite");
  }
  const size_t np = s.positions.size();
  if (sun.visibility.size() != np) return fail(name, "sun.visibility: size differs from positions");
  if (!allInUnitInterval(sun.visibility.data(), np)) {
    for (size_t i = 0; i < np; ++i) {
      // Written so that NaN fails too.
      if (!(sun.visibility[i] >= 0.0f && sun.visibility[i] <= 1.0f)) {
        return fail(name, "sun.visibility[" + std::to_string(i) + "]: not in [0, 1]");
      }
    }
  }
  if (sun.ramps.empty()) return Status::success();
  if (s.dimension != 3) {
    return fail(name, "sun.ramps: ramps in dimension " + std::to_string(s.dimension) +
                          " (only tetrahedra have ramps)");
  }
  if (sun.ramps.size() != size_t(s.innerCellCount)) {
    return fail(name, "sun.ramps: size differs from innerCellCount");
  }
  if (!rampsValid(sun.ramps.data(), sun.ramps.size())) {
    for (size_t c = 0; c < sun.ramps.size(); ++c) {
      const glm::vec4 a = sun.ramps[c];
      if (std::isnan(a.x)) {
        if (!std::isnan(a.y) || !std::isnan(a.z) || !std::isnan(a.w)) {
          return fail(name, "sun.ramps[" + std::to_string(c) +
                                "]: x is NaN (no ramp) but y, z, w are not all NaN");
        }
      } else if (!finite(glm::vec3(a)) || !std::isfinite(a.w)) {
        return fail(name, "sun.ramps[" + std::to_string(c) +
                              "]: not finite (a ramp is four finite values, or NaN for none)");
      }
    }
  }
  return Status::success();
}

// Every cell slot as validateProbeSet requires it (probe indices in range in used slots, -1 in
// unused ones, neighbour indices in range, every link linked back), in one pass without
// branches on the data; sizes must already agree.
bool cellSlotsValid(const ProbeSet& s) {
  const size_t np = s.positions.size(), nc = s.cells.size();
  const size_t inner = size_t(s.innerCellCount);
  bool ok = true;
  auto cells = [&](size_t first, size_t last, int used) {
    for (size_t c = first; c < last; ++c) {
      // The linked cells' rows lie anywhere in the array: fetch those of the cell kAhead
      // places on (its own row is read in order), so that the misses overlap.
      constexpr size_t kAhead = 8;
      if (c + kAhead < last) {
        const glm::ivec4 ahead = s.neighbours[c + kAhead];
        for (int k = 0; k < 4; ++k) {
          if (uint32_t(ahead[k]) < nc) prefetch(&s.neighbours[size_t(ahead[k])]);
        }
      }
      const glm::ivec4 v = s.cells[c], n = s.neighbours[c];
      const int32_t ci = int32_t(c);
#ifdef __SSE2__
      // The same tests on the four slots at once: unsigned compares as signed ones of the
      // values with their top bit flipped; a back row holds c when any of its lanes does.
      // (np and nc + 1 as 32-bit bounds: int32 indices cannot reach beyond them anyway, and a
      // truncated bound could only reject, never accept.)
      const __m128i flip = _mm_set1_epi32(INT32_MIN);
      const __m128i vv = _mm_loadu_si128(reinterpret_cast<const __m128i*>(&v));
      const __m128i nn = _mm_loadu_si128(reinterpret_cast<const __m128i*>(&n));
      const __m128i unused = _mm_cmplt_epi32(_mm_set_epi32(3, 2, 1, 0), _mm_set1_epi32(used));
      const __m128i inRange = _mm_cmplt_epi32(_mm_xor_si128(vv, flip),
                                              _mm_set1_epi32(int32_t(uint32_t(np) ^ 0x80000000u)));
      const __m128i isMinusOne = _mm_cmpeq_epi32(vv, _mm_set1_epi32(-1));
      // Slot ok: used and in range, or unused and -1.
      const __m128i slotOk = _mm_or_si128(_mm_and_si128(unused, inRange),
                                          _mm_andnot_si128(unused, isMinusOne));
      // -1 .. nc - 1: n + 1 <= nc unsigned, i.e. n + 1 < nc + 1.
      const __m128i linkOk = _mm_cmplt_epi32(
          _mm_xor_si128(_mm_add_epi32(nn, _mm_set1_epi32(1)), flip),
          _mm_set1_epi32(int32_t((uint32_t(nc) + 1u) ^ 0x80000000u)));
      ok &= _mm_movemask_epi8(_mm_and_si128(slotOk, linkOk)) == 0xffff;
      const __m128i cc = _mm_set1_epi32(ci);
      for (int k = 0; k < 4; ++k) {
        // Read the named cell's links only when the index is in range (else a link to c
        // itself stands in, and the range test above has already failed).
        const glm::ivec4& back = s.neighbours[uint32_t(n[k]) < nc ? size_t(n[k]) : c];
        const __m128i b = _mm_loadu_si128(reinterpret_cast<const __m128i*>(&back));
        ok &= n[k] < 0 || _mm_movemask_epi8(_mm_cmpeq_epi32(b, cc)) != 0;
      }
#else
      for (int k = 0; k < 4; ++k) {
        ok &= k < used ? uint32_t(v[k]) < np : v[k] == -1;
        ok &= uint32_t(n[k] + 1) <= nc;  // -1 .. nc - 1
        // Read the named cell's links only when the index is in range (else a link to c
        // itself stands in, and the range test above has already failed).
        const glm::ivec4 back = s.neighbours[uint32_t(n[k]) < nc ? size_t(n[k]) : c];
        ok &= n[k] < 0 || back[0] == ci || back[1] == ci || back[2] == ci || back[3] == ci;
      }
#endif
    }
  };
  cells(0, inner, usedSlots(s.dimension, false));
  cells(inner, nc, usedSlots(s.dimension, true));
  return ok;
}

// The first slot cellSlotsValid rejects, as validateProbeSet's message.
Status describeBadSlot(const ProbeSet& s, std::string_view name) {
  const size_t np = s.positions.size(), nc = s.cells.size();
  auto slotField = [](const char* array, size_t c, int k) {
    return std::string(array) + "[" + std::to_string(c) + "][" + std::to_string(k) + "]";
  };
  int64_t asymmetricCell = -1;
  int asymmetricSlot = 0;
  for (size_t c = 0; c < nc; ++c) {
    const bool isOuter = c >= size_t(s.innerCellCount);
    const int used = usedSlots(s.dimension, isOuter);
    for (int k = 0; k < 4; ++k) {
      const int32_t v = s.cells[c][k];
      if (k < used && (v < 0 || size_t(v) >= np)) {
        return fail(name, slotField("cells", c, k) + ": probe index " + std::to_string(v) +
                              " out of range (probeCount " + std::to_string(np) + ")");
      }
      if (k >= used && v != -1) {
        return fail(name, slotField("cells", c, k) + ": unused slot must be -1");
      }
      const int32_t n = s.neighbours[c][k];
      if (n < -1 || (n >= 0 && size_t(n) >= nc)) {
        return fail(name, slotField("neighbours", c, k) + ": cell index " + std::to_string(n) +
                              " out of range");
      }
      // Symmetry in the same pass (this index is in range; the cell it names may not be
      // checked yet, but only compared with c). Reported after the range checks, as the
      // first asymmetric slot, so an out-of-range index is named as such wherever it is.
      if (n >= 0 && asymmetricCell < 0) {
        const glm::ivec4 back = s.neighbours[size_t(n)];
        const int32_t ci = int32_t(c);
        if (back[0] != ci && back[1] != ci && back[2] != ci && back[3] != ci) {
          asymmetricCell = int64_t(c);
          asymmetricSlot = k;
        }
      }
    }
  }
  if (asymmetricCell >= 0) {
    const size_t c = size_t(asymmetricCell);
    return fail(name, slotField("neighbours", c, asymmetricSlot) + ": cell " +
                          std::to_string(s.neighbours[c][asymmetricSlot]) +
                          " does not link back (asymmetric neighbours)");
  }
  return Status::success();
}

}  // namespace

uint64_t fnv1a64(std::span<const uint8_t> bytes, uint64_t hash) {
  for (uint8_t b : bytes) {
    hash ^= b;
    hash *= 1099511628211ull;
  }
  return hash;
}

uint64_t binaryFileChecksum(std::span<const uint8_t> file, size_t checksumOffset,
                            size_t headerSize) {
  return fnv1a64(file.subspan(headerSize), fnv1a64(file.subspan(0, checksumOffset)));
}

void computeOuterCellCubics(ProbeSet& set) {
  using glm::dvec3;
  set.outerCells.resize(size_t(set.cellCount() - set.innerCellCount));
  for (int32_t c = set.innerCellCount; c < set.cellCount(); ++c) {
    OuterCell& oc = set.outerCells[size_t(c - set.innerCellCount)];
    oc.cubic = {};
    if (set.dimension != 3) continue;
    const glm::ivec4 t = set.cells[c];
    const dvec3 A(set.positions[t[0]]), B(set.positions[t[1]]), C(set.positions[t[2]]);
    const dvec3 nA(oc.normals[0]), nB(oc.normals[1]), nC(oc.normals[2]);
    // n(t) = (E1 + t F1) x (E2 + t F2) = N0 + t N1 + t^2 N2, and the condition
    // dot(n(t), q - t nA) = 0 with q = p - A expands to the four rows below.
    const dvec3 e1 = B - A, e2 = C - A, f1 = nB - nA, f2 = nC - nA;
    const dvec3 n0 = glm::cross(e1, e2);
    const dvec3 n1 = glm::cross(e1, f2) + glm::cross(f1, e2);
    const dvec3 n2 = glm::cross(f1, f2);
    oc.cubic[0] = glm::vec4(0.0f, 0.0f, 0.0f, float(-glm::dot(n2, nA)));
    oc.cubic[1] = glm::vec4(glm::vec3(n2), float(-glm::dot(n1, nA)));
    oc.cubic[2] = glm::vec4(glm::vec3(n1), float(-glm::dot(n0, nA)));
    oc.cubic[3] = glm::vec4(glm::vec3(n0), 0.0f);
  }
}

// One pass over the inner cells, no walks: each grid cell's seed is, among the cells whose
// centroid falls in it, the one whose centroid is nearest its centre; grid cells that no
// centroid falls in take the seed of the nearest grid cell that has one (a breadth-first
// sweep over the grid). A query then starts within about a grid cell of its point.
namespace runtime_detail {

SeedGridBuilder::SeedGridBuilder(const std::vector<glm::vec3>& positions, int dimension,
                                 int32_t innerCellCount, int targetCellsPerSeed) {
  if (dimension < 2 || innerCellCount <= 0) return;
  active_ = true;
  inv_ = dimension == 3 ? 0.25f : 1.0f / 3.0f;
  // The bounds of every probe (a sequential pass; a merged or dropped probe only widens them
  // by a hair, and lookups clamp to the grid anyway).
  glm::vec3 lo(std::numeric_limits<float>::infinity()), hi(-lo);
  for (const glm::vec3& p : positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const glm::dvec3 ext = glm::dvec3(hi) - glm::dvec3(lo);
  const double diag = glm::length(ext);
  const glm::dvec3 e = glm::max(ext, glm::dvec3(1e-3 * diag + 1e-30));
  const double target = std::max(1.0, double(innerCellCount) / std::max(1, targetCellsPerSeed));
  const double k = std::cbrt(target / (e.x * e.y * e.z));
  for (int a = 0; a < 3; ++a) {
    grid_.size[a] = std::clamp(int(std::lround(e[a] * k)), 1, kSeedGridMaxAxis);
  }
  grid_.min = lo;
  grid_.max = hi;
  const glm::ivec3 n = grid_.size;
  const size_t count = size_t(n.x) * size_t(n.y) * size_t(n.z);
  key_.assign(count, kEmpty);
  // Grid coordinates of a point: (p - lo) * scale, the grid cell its integer part.
  lo_ = lo;
  for (int a = 0; a < 3; ++a) scale_[a] = hi[a] > lo[a] ? float(n[a]) / (hi[a] - lo[a]) : 0.0f;
}

ProbeSeedGrid SeedGridBuilder::finish() {
  if (!active_) return ProbeSeedGrid{};
  // The grid cells no centroid fell in take the seed of the neighbour that a breadth-first
  // sweep from the filled cells reaches them from first: the sweep starts with every filled
  // cell in index order and visits each one's neighbours at -x, +x, -y, +y, -z, +z (in that
  // order), an empty cell taking the seed of the first cell whose visit finds it. The sweep
  // is not run over the whole grid: an empty cell beside a filled one (all but a few: at
  // about one centroid per grid cell, about 0.4% of the cells have no filled neighbour) is
  // found first from its filled neighbour of smallest index, which one pass in index order
  // picks (the neighbours at -z, -y, -x, +x, +y, +z have increasing indices). The rest, the
  // cells two or more steps from any filled one, go to the sweep proper, started from the
  // cells one step away that border them, in the order the full sweep would queue those
  // (by their finder's index, then the direction it found them in; cells with the same
  // finder carry its seed, so only the index decides a seed): a cell one step away that
  // borders none of them would find nothing, so leaving it out changes no seed.
  const glm::ivec3 n = grid_.size;
  const size_t count = key_.size();
  const size_t stride[3] = {1, size_t(n.x), size_t(n.x) * size_t(n.y)};
  std::vector<int32_t>& seeds = grid_.seeds;
  seeds.resize(count);
  // The filled neighbour of grid cell i (at g) whose visit reaches i first, and the direction
  // of that visit (0..5: -x, +x, -y, +y, -z, +z from it); -1 when no neighbour is filled.
  auto finder = [&](size_t i, glm::ivec3 g, int& direction) -> int64_t {
    if (g.z > 0 && key_[i - stride[2]] != kEmpty) return direction = 5, int64_t(i - stride[2]);
    if (g.y > 0 && key_[i - stride[1]] != kEmpty) return direction = 3, int64_t(i - stride[1]);
    if (g.x > 0 && key_[i - 1] != kEmpty) return direction = 1, int64_t(i - 1);
    if (g.x + 1 < n.x && key_[i + 1] != kEmpty) return direction = 0, int64_t(i + 1);
    if (g.y + 1 < n.y && key_[i + stride[1]] != kEmpty) return direction = 2, int64_t(i + stride[1]);
    if (g.z + 1 < n.z && key_[i + stride[2]] != kEmpty) return direction = 4, int64_t(i + stride[2]);
    return -1;
  };
  const uint64_t* key = key_.data();
  int32_t* seed = seeds.data();
  for (int z = 0; z < n.z; ++z) {
    for (int y = 0; y < n.y; ++y) {
      // Without branches on the data (two cells in five are empty, at random): f is the key
      // of the finder (the last filled neighbour in the reverse of finder's order) or kEmpty;
      // a neighbour beyond the grid reads the cell itself, which is kEmpty when it matters.
      const size_t row = stride[1] * size_t(y) + stride[2] * size_t(z);
      const uint64_t* k = key + row;
      const uint64_t* up = z + 1 < n.z ? k + stride[2] : k;
      const uint64_t* north = y + 1 < n.y ? k + stride[1] : k;
      const uint64_t* south = y > 0 ? k - stride[1] : k;
      const uint64_t* down = z > 0 ? k - stride[2] : k;
      int32_t* out = seed + row;
      auto cell = [&](int x, int east, int west) {
        uint64_t f = kEmpty;
        for (const uint64_t v : {up[x], north[x], k[east], k[west], south[x], down[x]}) {
          f = v != kEmpty ? v : f;
        }
        out[x] = int32_t(uint32_t(k[x] != kEmpty ? k[x] : f));  // -1 from kEmpty
      };
      const int last = n.x - 1;
      cell(0, std::min(1, last), 0);
      for (int x = 1; x < last; ++x) cell(x, x + 1, x - 1);
      if (last > 0) cell(last, last, last - 1);
    }
  }
  std::vector<size_t> far;  // grid cells two or more steps from a filled one
  for (size_t c = 0; c < count; ++c) {
    if (seed[c] < 0) far.push_back(c);
  }
  if (!far.empty()) {
    auto coordinates = [&](size_t i) {
      return glm::ivec3(int(i % stride[1]), int(i / stride[1] % size_t(n.y)),
                        int(i / stride[2]));
    };
    // The cells one step away that border a far one, keyed by their place in the full
    // sweep's queue: finder index x 6 + direction.
    std::vector<std::pair<uint64_t, size_t>> border;
    for (size_t i : far) {
      const glm::ivec3 g = coordinates(i);
      for (int a = 0; a < 3; ++a) {
        for (int side = -1; side <= 1; side += 2) {
          const int x = g[a] + side;
          if (x < 0 || x >= n[a]) continue;
          const size_t j = side < 0 ? i - stride[a] : i + stride[a];
          if (seeds[j] < 0 || key_[j] != kEmpty) continue;
          int direction = 0;
          const int64_t f = finder(j, coordinates(j), direction);
          border.emplace_back(uint64_t(f) * 6 + uint64_t(direction), j);
        }
      }
    }
    std::sort(border.begin(), border.end());
    border.erase(std::unique(border.begin(), border.end()), border.end());
    // The sweep on from them (grid coordinates packed in 10 bits each, kSeedGridMaxAxis <=
    // 1024, so that a visit needs no division to find them).
    static_assert(kSeedGridMaxAxis <= 1024);
    std::vector<uint32_t> queue;
    queue.reserve(border.size() + far.size());
    for (const auto& b : border) {
      const glm::ivec3 g = coordinates(b.second);
      queue.push_back(uint32_t(g.x | g.y << 10 | g.z << 20));
    }
    for (size_t head = 0; head < queue.size(); ++head) {
      const uint32_t packed = queue[head];
      const glm::ivec3 g(int(packed & 1023), int((packed >> 10) & 1023), int(packed >> 20));
      const size_t i = size_t(g.x) + stride[1] * size_t(g.y) + stride[2] * size_t(g.z);
      for (int a = 0; a < 3; ++a) {
        for (int side = -1; side <= 1; side += 2) {
          const int x = g[a] + side;
          if (x < 0 || x >= n[a]) continue;
          const size_t j = side < 0 ? i - stride[a] : i + stride[a];
          if (seeds[j] < 0) {
            seeds[j] = seeds[i];
            queue.push_back(packed + (side < 0 ? 0u - (1u << (10 * a)) : 1u << (10 * a)));
          }
        }
      }
    }
  }
  std::vector<uint64_t>().swap(key_);
  active_ = false;
  return std::move(grid_);
}

}  // namespace runtime_detail

void buildProbeSeedGrid(ProbeSet& set, int targetCellsPerSeed) {
  runtime_detail::SeedGridBuilder grid(set.positions, set.dimension, set.innerCellCount,
                                       targetCellsPerSeed);
  if (grid.active()) {
    const bool tet = set.dimension == 3;
    for (int32_t c = 0; c < set.innerCellCount; ++c) {
      const glm::ivec4 t = set.cells[size_t(c)];
      glm::vec3 sum = set.positions[size_t(t[0])] + set.positions[size_t(t[1])] +
                      set.positions[size_t(t[2])];
      if (tet) sum += set.positions[size_t(t[3])];
      grid.offer(c, sum);
    }
  }
  set.grid = grid.finish();
}

Status validateProbeSet(const ProbeSet& s, std::string_view name) {
  if (s.dimension < 0 || s.dimension > 3) {
    return fail(name, "dimension: " + std::to_string(s.dimension) + " is not 0..3");
  }
  const size_t np = s.positions.size(), nc = s.cells.size();
  if (np == 0) return fail(name, "positions: no probes");
  if (s.sh.size() != np) return fail(name, "sh: size differs from positions");
  if (s.validity.size() != np) return fail(name, "validity: size differs from positions");
  if (!s.occlusion.empty() && s.occlusion.size() != np) {
    return fail(name, "occlusion: size differs from positions");
  }
  for (int c = 0; c < kProbeOcclusionChannels; ++c) {
    if (s.occlusionLights[c] < -1) {
      return fail(name, "occlusionLights[" + std::to_string(c) + "]: " +
                            std::to_string(s.occlusionLights[c]) + " is not a light or -1");
    }
  }
  if (Status v = validateVisibility(s.visibility, np, name); !v) return v;
  if (nc == 0) return fail(name, "cells: no cells");
  if (s.neighbours.size() != nc) return fail(name, "neighbours: size differs from cells");
  if (s.innerCellCount <= 0 || size_t(s.innerCellCount) > nc) {
    return fail(name, "innerCellCount: out of range");
  }
  const size_t outer = nc - size_t(s.innerCellCount);
  if (s.dimension < 2 && outer != 0) {
    return fail(name, "innerCellCount: dimension " + std::to_string(s.dimension) +
                          " has no outer cells");
  }
  if (s.outerCells.size() != outer) return fail(name, "outerCells: size differs from cells");
  if (Status v = validateSunLayer(s, name); !v) return v;
  // Positions, validity and SH are checked first as flat float arrays without branches (a
  // 100k-probe set has 10M of them); only when one is not finite does the loop below run, to
  // name it.
  const bool allFinite =
      allFiniteFloats(&s.positions[0].x, 3 * np) && allFiniteFloats(s.validity.data(), np) &&
      allFiniteFloats(&s.sh[0].c[0].x, size_t(3 * kShL2Count) * np);
  const bool occlusionValid =
      s.occlusion.empty() || allInUnitInterval(&s.occlusion[0].x, 4 * np);
  for (size_t i = 0; i < np && !(allFinite && occlusionValid); ++i) {
    if (!finite(s.positions[i])) return fail(name, "positions[" + std::to_string(i) + "]: not finite");
    if (!std::isfinite(s.validity[i])) {
      return fail(name, "validity[" + std::to_string(i) + "]: not finite");
    }
    for (int k = 0; k < kShL2Count; ++k) {
      if (!finite(s.sh[i].c[k])) {
        return fail(name, "sh[" + std::to_string(i) + "][" + std::to_string(k) + "]: not finite");
      }
    }
    if (!s.occlusion.empty()) {
      for (int c = 0; c < kProbeOcclusionChannels; ++c) {
        // Written so that NaN fails too.
        if (!(s.occlusion[i][c] >= 0.0f && s.occlusion[i][c] <= 1.0f)) {
          return fail(name, "occlusion[" + std::to_string(i) + "][" + std::to_string(c) +
                                "]: not in [0, 1]");
        }
      }
    }
  }
  // The per-slot checks run first as one branch-free pass (a 100k-probe set has millions of
  // slots); only when it finds a problem do the loops below run, to name it.
  if (!cellSlotsValid(s)) {
    if (Status st = describeBadSlot(s, name); !st) return st;
  }
  for (size_t i = 0; i < outer; ++i) {
    const OuterCell& oc = s.outerCells[i];
    for (int k = 0; k < 3; ++k) {
      if (!finite(oc.normals[k])) {
        return fail(name, "outerCells[" + std::to_string(i) + "].normals: not finite");
      }
    }
    for (int k = 0; k < 4; ++k) {
      if (!finite(glm::vec3(oc.cubic[k])) || !std::isfinite(oc.cubic[k].w)) {
        return fail(name, "outerCells[" + std::to_string(i) + "].cubic: not finite");
      }
    }
  }
  const ProbeSeedGrid& g = s.grid;
  const glm::ivec3 gs = g.size;
  if (gs.x < 0 || gs.y < 0 || gs.z < 0 || gs.x > int(kMaxGridAxis) || gs.y > int(kMaxGridAxis) ||
      gs.z > int(kMaxGridAxis)) {
    return fail(name, "gridSize: out of range");
  }
  const uint64_t gridCells = uint64_t(gs.x) * uint64_t(gs.y) * uint64_t(gs.z);
  if (gridCells != g.seeds.size()) return fail(name, "seeds: size differs from gridSize");
  if (!finite(g.min) || !finite(g.max)) return fail(name, "gridMin/gridMax: not finite");
  for (size_t i = 0; i < g.seeds.size(); ++i) {
    if (g.seeds[i] < 0 || size_t(g.seeds[i]) >= nc) {
      return fail(name, "seeds[" + std::to_string(i) + "]: cell index out of range");
    }
  }
  return Status::success();
}

std::vector<uint8_t> serializeProbeSet(const ProbeSet& s, uint32_t version) {
  std::vector<uint8_t> out(kProbeFileHeaderSize, 0);
  std::memcpy(out.data(), "KPRB", 4);
  const bool withVisibility = version >= 3 && !s.visibility.empty();
  const uint32_t words[] = {version,
                            uint32_t(s.dimension),
                            uint32_t(s.positions.size()),
                            uint32_t(s.cells.size()),
                            uint32_t(s.innerCellCount),
                            uint32_t(s.grid.size.x),
                            uint32_t(s.grid.size.y),
                            uint32_t(s.grid.size.z)};
  std::memcpy(out.data() + 4, words, sizeof(words));
  std::memcpy(out.data() + 36, &s.grid.min, 12);
  std::memcpy(out.data() + 48, &s.grid.max, 12);
  const uint32_t visibilityResolution = withVisibility ? uint32_t(s.visibility.resolution) : 0u;
  std::memcpy(out.data() + 60, &visibilityResolution, 4);
  put(out, s.positions.data(), s.positions.size());
  put(out, s.sh.data(), s.sh.size());
  put(out, s.validity.data(), s.validity.size());
  put(out, s.cells.data(), s.cells.size());
  put(out, s.neighbours.data(), s.neighbours.size());
  for (const OuterCell& oc : s.outerCells) put(out, oc.normals.data(), 3);
  for (const OuterCell& oc : s.outerCells) put(out, oc.cubic.data(), 4);
  put(out, s.grid.seeds.data(), s.grid.seeds.size());
  if (version >= 2) {
    put(out, s.occlusionLights.data(), s.occlusionLights.size());
    if (s.occlusion.empty()) {
      const std::vector<glm::vec4> ones(s.positions.size(), glm::vec4(1.0f));
      put(out, ones.data(), ones.size());
    } else {
      put(out, s.occlusion.data(), s.occlusion.size());
    }
  }
  if (withVisibility) {
    put(out, s.visibility.maxDistance.data(), s.visibility.maxDistance.size());
    put(out, s.visibility.moments.data(), s.visibility.moments.size());
  }
  if (version >= 4) {
    // A light below -1 is written as given (a bad file for tests); below 0, nothing follows.
    put(out, &s.sun.light, 1);
    if (s.sun.light >= 0) {
      put(out, &s.sun.sh, 1);
      put(out, s.sun.visibility.data(), s.sun.visibility.size());
      const uint32_t ramps = uint32_t(s.sun.ramps.size());
      put(out, &ramps, 1);
      put(out, s.sun.ramps.data(), s.sun.ramps.size());
    }
  }
  const uint64_t sum = binaryFileChecksum(out, kProbeFileChecksumOffset, kProbeFileHeaderSize);
  std::memcpy(out.data() + kProbeFileChecksumOffset, &sum, 8);
  return out;
}

Result<ProbeSet> parseProbeSet(std::span<const uint8_t> bytes, std::string_view name) {
  Result<uint64_t> size = checkHeader(bytes.data(), bytes.size(), name);
  if (!size) return Error{size.error()};
  const Header hd = decodeHeader(bytes.data());
  if (hd.version >= 4) {
    if (Status st = checkSunBlock(bytes, hd, name); !st) return Error{st.error()};
  }
  if (binaryFileChecksum(bytes, kProbeFileChecksumOffset, kProbeFileHeaderSize) != hd.checksum) return fail(name, "checksum: payload does not match (corrupt file)");

  ProbeSet s;
  s.dimension = int32_t(hd.dimension);
  s.innerCellCount = int32_t(hd.innerCellCount);
  s.grid.size = glm::ivec3(hd.gridSize[0], hd.gridSize[1], hd.gridSize[2]);
  s.grid.min = glm::vec3(hd.gridMin[0], hd.gridMin[1], hd.gridMin[2]);
  s.grid.max = glm::vec3(hd.gridMax[0], hd.gridMax[1], hd.gridMax[2]);
  const uint8_t* p = bytes.data() + kProbeFileHeaderSize;
  take(p, s.positions, hd.probeCount);
  take(p, s.sh, hd.probeCount);
  take(p, s.validity, hd.probeCount);
  take(p, s.cells, hd.cellCount);
  take(p, s.neighbours, hd.cellCount);
  const size_t outer = hd.cellCount - hd.innerCellCount;
  s.outerCells.resize(outer);
  for (OuterCell& oc : s.outerCells) {
    std::memcpy(oc.normals.data(), p, 36);
    p += 36;
  }
  for (OuterCell& oc : s.outerCells) {
    std::memcpy(oc.cubic.data(), p, 64);
    p += 64;
  }
  take(p, s.grid.seeds, size_t(hd.gridSize[0]) * hd.gridSize[1] * hd.gridSize[2]);
  if (hd.version >= 2) {
    std::memcpy(s.occlusionLights.data(), p, kOcclusionLightsBytes);
    p += kOcclusionLightsBytes;
    take(p, s.occlusion, hd.probeCount);
  } else {
    // Version 1 predates probe occlusion: nothing is occluded.
    s.occlusion.assign(hd.probeCount, glm::vec4(1.0f));
  }
  if (hd.visibilityResolution != 0) {
    s.visibility.resolution = int32_t(hd.visibilityResolution);
    take(p, s.visibility.maxDistance, hd.probeCount);
    take(p, s.visibility.moments, size_t(hd.probeCount) * s.visibility.valuesPerProbe());
  }
  if (hd.version >= 4) {  // sizes checked by checkSunBlock
    std::memcpy(&s.sun.light, p, kSunLightBytes);
    p += kSunLightBytes;
    if (s.sun.light >= 0) {
      std::memcpy(&s.sun.sh, p, kSunShBytes);
      p += kSunShBytes;
      take(p, s.sun.visibility, hd.probeCount);
      const uint32_t ramps = readAt<uint32_t>(p);
      p += kSunRampCountBytes;
      take(p, s.sun.ramps, ramps);
    }
  }
  Status st = validateProbeSet(s, name);
  if (!st) return Error{st.error()};
  prepareProbeLookup(s);
  return s;
}

Status writeProbeFile(const ProbeSet& set, const std::string& path) {
  return runtime_detail::writeFileAtomically(path, serializeProbeSet(set));
}

Result<ProbeSet> loadProbeFile(const std::string& path) {
  Result<std::vector<uint8_t>> bytes = runtime_detail::readHeaderSizedFile(
      path, kProbeFileHeaderSize, [&](const uint8_t* header, uint64_t available) {
        return checkHeader(header, available, path);
      });
  if (!bytes) return Error{bytes.error()};
  return parseProbeSet(*bytes, path);
}

}  // namespace kiln
