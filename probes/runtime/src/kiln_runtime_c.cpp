// kiln_runtime_c.cpp: the C API (kiln_runtime.h) over probe_set.h / probe_runtime.h. Every
// entry point catches C++ exceptions and turns them into status codes (as Embree does).
#include "kiln_runtime.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <new>
#include <string>

#include "kiln/probe_runtime.h"
#include "kiln/probe_set.h"

struct kiln_probes {
  std::atomic<int> references{1};
  kiln::ProbeSet set;
};

namespace {

thread_local std::string tlsError;

kiln_status setError(kiln_status status, std::string message) {
  try {
    tlsError = std::move(message);
  } catch (...) {
    tlsError.clear();
  }
  return status;
}

kiln_status ok() {
  tlsError.clear();
  return KILN_OK;
}

template <typename F>
kiln_status guarded(F&& f) {
  try {
    return f();
  } catch (const std::bad_alloc&) {
    return setError(KILN_ERROR_OUT_OF_MEMORY, "out of memory");
  } catch (const std::exception& e) {
    return setError(KILN_ERROR_UNKNOWN, e.what());
  } catch (...) {
    return setError(KILN_ERROR_UNKNOWN, "unknown error");
  }
}

void toC(const kiln::ProbeLocation& loc, kiln_probe_location* out) {
  out->cell = loc.cell;
  for (int k = 0; k < 4; ++k) {
    out->probes[k] = loc.probes[k];
    out->weights[k] = loc.weights[k];
    out->barycentric[k] = loc.barycentric[k];
  }
  out->visibility_weighted = loc.visibilityWeighted ? 1 : 0;
}

void blendToC(const kiln::ProbeBlendSettings& b, kiln_probe_blend* out) {
  out->visibility = b.visibility ? 1 : 0;
  for (int k = 0; k < 3; ++k) out->normal[k] = b.normal[k];
  out->normal_bias = b.normalBias;
  out->distance_bias = b.distanceBias;
  out->min_sigma = b.minSigma;
}

bool finite3(const float* v) {
  return std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
}

// A blend from C is untrusted: NULL means the defaults; a field the visibility test cannot
// use (NaN, infinite, a negative bias, a zero sigma) is an error naming it, set under the
// name of the calling function.
kiln_status blendFromC(const char* function, const kiln_probe_blend* in,
                       kiln::ProbeBlendSettings& out) {
  out = kiln::ProbeBlendSettings{};
  if (!in) return KILN_OK;
  auto bad = [&](const char* field, const char* what) {
    return setError(KILN_ERROR_INVALID_ARGUMENT,
                    std::string(function) + ": blend." + field + ": " + what);
  };
  if (!finite3(in->normal)) return bad("normal", "not finite");
  if (!(std::isfinite(in->normal_bias) && in->normal_bias >= 0.0f))
    return bad("normal_bias", "must be a finite distance >= 0");
  if (!(std::isfinite(in->distance_bias) && in->distance_bias >= 0.0f))
    return bad("distance_bias", "must be a finite distance >= 0");
  if (!(std::isfinite(in->min_sigma) && in->min_sigma > 0.0f))
    return bad("min_sigma", "must be a finite distance > 0");
  out.visibility = in->visibility != 0;
  out.normal = glm::vec3(in->normal[0], in->normal[1], in->normal[2]);
  out.normalBias = in->normal_bias;
  out.distanceBias = in->distance_bias;
  out.minSigma = in->min_sigma;
  return KILN_OK;
}

void shToFloats(const kiln::ShL2Rgb& sh, float* out) {
  for (int i = 0; i < kiln::kShL2Count; ++i) {
    for (int ch = 0; ch < 3; ++ch) out[3 * i + ch] = sh.c[i][ch];
  }
}

// A location from C is untrusted: check its indices before blending.
bool fromC(const kiln::ProbeSet& set, const kiln_probe_location* in, kiln::ProbeLocation& loc) {
  loc.cell = in->cell;
  for (int k = 0; k < 4; ++k) {
    if (in->probes[k] < 0 || in->probes[k] >= set.probeCount()) return false;
    loc.probes[k] = in->probes[k];
    loc.weights[k] = in->weights[k];
    loc.barycentric[k] = in->barycentric[k];
  }
  loc.visibilityWeighted = in->visibility_weighted != 0;
  return true;
}

// kiln_probes_locate and kiln_probes_locate_blend (`blend` NULL = defaults); `function` names
// the entry point in messages.
kiln_status locate(const char* function, const kiln_probes* probes, const float* position,
                   int32_t hint, const kiln_probe_blend* blend, kiln_probe_location* out) {
  return guarded([&] {
    if (!probes || !position || !out) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, std::string(function) + ": NULL argument");
    }
    kiln::ProbeBlendSettings settings;
    if (kiln_status st = blendFromC(function, blend, settings); st != KILN_OK) return st;
    toC(kiln::locateProbe(probes->set, glm::vec3(position[0], position[1], position[2]), hint,
                          settings),
        out);
    return ok();
  });
}

// kiln_probes_sample_batch and kiln_probes_sample_batch_blend (`normals` NULL = blend's normal
// for every point).
kiln_status sampleBatch(const char* function, const kiln_probes* probes, size_t count,
                        const float* positions, const float* normals, const kiln_probe_blend* blend,
                        int32_t* hints, kiln_probe_location* out_locations, float* out_sh) {
  return guarded([&] {
    if (!probes || (count > 0 && !positions)) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, std::string(function) + ": NULL argument");
    }
    kiln::ProbeBlendSettings settings;
    if (kiln_status st = blendFromC(function, blend, settings); st != KILN_OK) return st;
    // Every normal is checked first, so a bad one leaves hints and outputs untouched.
    if (normals) {
      for (size_t i = 0; i < count; ++i) {
        if (!finite3(normals + 3 * i)) {
          return setError(KILN_ERROR_INVALID_ARGUMENT, std::string(function) + ": normals[" +
                                                           std::to_string(i) + "]: not finite");
        }
      }
    }
    // The cells come from the C++ batch form (interleaved walks) a chunk at a time, with plain
    // weights; each point's own blend (its normal) then weights them, as locateProbe would.
    constexpr size_t kChunk = 64;
    glm::vec3 points[kChunk];
    int32_t chunkHints[kChunk];
    kiln::ProbeLocation locations[kChunk];
    kiln::ProbeBlendSettings cellsOnly = settings;
    cellsOnly.visibility = false;
    for (size_t first = 0; first < count; first += kChunk) {
      const size_t n = std::min(kChunk, count - first);
      for (size_t i = 0; i < n; ++i) {
        const float* p = positions + 3 * (first + i);
        points[i] = glm::vec3(p[0], p[1], p[2]);
        chunkHints[i] = hints ? hints[first + i] : -1;
      }
      kiln::locateProbes(probes->set, std::span<const glm::vec3>(points, n),
                         std::span<int32_t>(chunkHints, n),
                         std::span<kiln::ProbeLocation>(locations, n), cellsOnly);
      for (size_t i = 0; i < n; ++i) {
        const size_t at = first + i;
        if (normals) {
          const float* nv = normals + 3 * at;
          settings.normal = glm::vec3(nv[0], nv[1], nv[2]);
        }
        kiln::ProbeLocation& loc = locations[i];
        kiln::weightByVisibility(probes->set, points[i], loc, settings);
        if (hints) hints[at] = loc.cell;
        if (out_locations) toC(loc, out_locations + at);
        if (out_sh) shToFloats(kiln::interpolateProbes(probes->set, loc), out_sh + 27 * at);
      }
    }
    return ok();
  });
}

}  // namespace

extern "C" {

kiln_status kiln_probes_load(const char* path, kiln_probes** out) {
  return guarded([&] {
    if (!path || !out) return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probes_load: NULL");
    *out = nullptr;
    std::FILE* f = std::fopen(path, "rb");
    if (!f) return setError(KILN_ERROR_IO, std::string(path) + ": cannot open");
    std::fclose(f);
    kiln::Result<kiln::ProbeSet> set = kiln::loadProbeFile(path);
    if (!set) return setError(KILN_ERROR_INVALID_FILE, set.error());
    auto* handle = new kiln_probes;
    handle->set = std::move(set).value();
    *out = handle;
    return ok();
  });
}

void kiln_probes_retain(kiln_probes* probes) {
  if (probes) probes->references.fetch_add(1, std::memory_order_relaxed);
}

void kiln_probes_release(kiln_probes* probes) {
  if (probes && probes->references.fetch_sub(1, std::memory_order_acq_rel) == 1) delete probes;
}

uint32_t kiln_probes_count(const kiln_probes* probes) {
  return probes ? uint32_t(probes->set.probeCount()) : 0u;
}

uint32_t kiln_probes_cell_count(const kiln_probes* probes) {
  return probes ? uint32_t(probes->set.cellCount()) : 0u;
}

int kiln_probes_has_visibility(const kiln_probes* probes) {
  return probes && !probes->set.visibility.empty() ? 1 : 0;
}

uint32_t kiln_probes_visibility_resolution(const kiln_probes* probes) {
  return probes ? uint32_t(probes->set.visibility.resolution) : 0u;
}

kiln_status kiln_probe_blend_defaults(kiln_probe_blend* blend) {
  return guarded([&] {
    if (!blend) return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probe_blend_defaults: NULL");
    blendToC(kiln::ProbeBlendSettings{}, blend);
    return ok();
  });
}

kiln_status kiln_probes_locate(const kiln_probes* probes, const float position[3], int32_t hint,
                               kiln_probe_location* out) {
  return locate("kiln_probes_locate", probes, position, hint, nullptr, out);
}

kiln_status kiln_probes_locate_blend(const kiln_probes* probes, const float position[3],
                                     int32_t hint, const kiln_probe_blend* blend,
                                     kiln_probe_location* out) {
  return locate("kiln_probes_locate_blend", probes, position, hint, blend, out);
}

kiln_status kiln_probes_sample_sh(const kiln_probes* probes, const kiln_probe_location* location,
                                  float out_sh[27]) {
  return guarded([&] {
    if (!probes || !location || !out_sh) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probes_sample_sh: NULL argument");
    }
    kiln::ProbeLocation loc;
    if (!fromC(probes->set, location, loc)) {
      return setError(KILN_ERROR_INVALID_ARGUMENT,
                      "kiln_probes_sample_sh: location.probes: index out of range");
    }
    shToFloats(kiln::interpolateProbes(probes->set, loc), out_sh);
    return ok();
  });
}

kiln_status kiln_probes_sample_occlusion(const kiln_probes* probes,
                                         const kiln_probe_location* location,
                                         float out_occlusion[4]) {
  return guarded([&] {
    if (!probes || !location || !out_occlusion) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probes_sample_occlusion: NULL argument");
    }
    kiln::ProbeLocation loc;
    if (!fromC(probes->set, location, loc)) {
      return setError(KILN_ERROR_INVALID_ARGUMENT,
                      "kiln_probes_sample_occlusion: location.probes: index out of range");
    }
    const glm::vec4 o = kiln::interpolateOcclusion(probes->set, loc);
    for (int c = 0; c < 4; ++c) out_occlusion[c] = o[c];
    return ok();
  });
}

kiln_status kiln_probes_occlusion_lights(const kiln_probes* probes, int32_t out_lights[4]) {
  return guarded([&] {
    if (!probes || !out_lights) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probes_occlusion_lights: NULL argument");
    }
    for (int c = 0; c < 4; ++c) out_lights[c] = probes->set.occlusionLights[size_t(c)];
    return ok();
  });
}

kiln_status kiln_probes_irradiance(const float sh[27], const float normal[3], float out_rgb[3]) {
  return guarded([&] {
    if (!sh || !normal || !out_rgb) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_probes_irradiance: NULL argument");
    }
    kiln::ShL2Rgb s;
    for (int i = 0; i < kiln::kShL2Count; ++i) {
      s.c[i] = glm::vec3(sh[3 * i], sh[3 * i + 1], sh[3 * i + 2]);
    }
    const glm::vec3 e = s.irradiance(glm::vec3(normal[0], normal[1], normal[2]));
    out_rgb[0] = e.x;
    out_rgb[1] = e.y;
    out_rgb[2] = e.z;
    return ok();
  });
}

kiln_status kiln_probes_sample_batch(const kiln_probes* probes, size_t count,
                                     const float* positions, int32_t* hints,
                                     kiln_probe_location* out_locations, float* out_sh) {
  return sampleBatch("kiln_probes_sample_batch", probes, count, positions, nullptr, nullptr, hints,
                     out_locations, out_sh);
}

kiln_status kiln_probes_sample_batch_blend(const kiln_probes* probes, size_t count,
                                           const float* positions, const float* normals,
                                           const kiln_probe_blend* blend, int32_t* hints,
                                           kiln_probe_location* out_locations, float* out_sh) {
  return sampleBatch("kiln_probes_sample_batch_blend", probes, count, positions, normals, blend,
                     hints, out_locations, out_sh);
}

const char* kiln_last_error(void) { return tlsError.c_str(); }

}  // extern "C"
