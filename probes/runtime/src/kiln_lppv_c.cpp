// kiln_lppv_c.cpp: the LPPV C API (kiln_lppv.h) over kiln/lppv_volume.h. Every entry point
// catches C++ exceptions and turns them into status codes, as kiln_runtime_c.cpp does. Its
// error message is kept apart from kiln_last_error()'s, whose storage is private to
// kiln_runtime_c.cpp.
#include <atomic>
#include <cstdio>
#include <new>
#include <string>

#include "kiln/lppv_volume.h"
#include "kiln_lppv.h"

struct kiln_lppv {
  std::atomic<int> references{1};
  kiln::LppvVolume volume;
};

namespace {

thread_local std::string tlsLppvError;

kiln_status setError(kiln_status status, std::string message) {
  try {
    tlsLppvError = std::move(message);
  } catch (...) {
    tlsLppvError.clear();
  }
  return status;
}

kiln_status ok() {
  tlsLppvError.clear();
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

void shToFloats(const kiln::ShL2Rgb& sh, float* out) {
  for (int i = 0; i < kiln::kShL2Count; ++i) {
    for (int ch = 0; ch < 3; ++ch) out[3 * i + ch] = sh.c[i][ch];
  }
}

}  // namespace

extern "C" {

kiln_status kiln_lppv_load(const char* path, kiln_lppv** out) {
  return guarded([&] {
    if (!path || !out) return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_lppv_load: NULL");
    *out = nullptr;
    std::FILE* f = std::fopen(path, "rb");
    if (!f) return setError(KILN_ERROR_IO, std::string(path) + ": cannot open");
    std::fclose(f);
    kiln::Result<kiln::LppvVolume> volume = kiln::loadLppvFile(path);
    if (!volume) return setError(KILN_ERROR_INVALID_FILE, volume.error());
    auto* handle = new kiln_lppv;
    handle->volume = std::move(volume).value();
    *out = handle;
    return ok();
  });
}

void kiln_lppv_retain(kiln_lppv* volume) {
  if (volume) volume->references.fetch_add(1, std::memory_order_relaxed);
}

void kiln_lppv_release(kiln_lppv* volume) {
  if (volume && volume->references.fetch_sub(1, std::memory_order_acq_rel) == 1) delete volume;
}

kiln_status kiln_lppv_get_info(const kiln_lppv* volume, kiln_lppv_info* out) {
  return guarded([&] {
    if (!volume || !out) return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_lppv_get_info: NULL");
    const kiln::LppvVolume& v = volume->volume;
    for (int a = 0; a < 3; ++a) {
      out->bounds_min[a] = v.boundsMin[a];
      out->bounds_max[a] = v.boundsMax[a];
      out->resolution[a] = uint32_t(v.resolution[a]);
    }
    out->placement = v.placement == kiln::LppvPlacement::kCellCorner ? KILN_LPPV_CELL_CORNER
                                                                     : KILN_LPPV_CELL_CENTER;
    return ok();
  });
}

kiln_status kiln_lppv_sample_sh(const kiln_lppv* volume, const float position[3], float out_sh[27],
                                float* out_validity) {
  return guarded([&] {
    if (!volume || !position || !out_sh) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_lppv_sample_sh: NULL argument");
    }
    const glm::vec3 p(position[0], position[1], position[2]);
    shToFloats(kiln::sampleLppv(volume->volume, p), out_sh);
    if (out_validity) *out_validity = kiln::sampleLppvValidity(volume->volume, p);
    return ok();
  });
}

kiln_status kiln_lppv_irradiance(const kiln_lppv* volume, const float position[3],
                                 const float normal[3], float out_rgb[3]) {
  return guarded([&] {
    if (!volume || !position || !normal || !out_rgb) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_lppv_irradiance: NULL argument");
    }
    const glm::vec3 e =
        kiln::lppvIrradiance(volume->volume, glm::vec3(position[0], position[1], position[2]),
                             glm::vec3(normal[0], normal[1], normal[2]));
    out_rgb[0] = e.x;
    out_rgb[1] = e.y;
    out_rgb[2] = e.z;
    return ok();
  });
}

kiln_status kiln_lppv_sample_batch(const kiln_lppv* volume, size_t count, const float* positions,
                                   float* out_sh) {
  return guarded([&] {
    if (!volume || (count > 0 && (!positions || !out_sh))) {
      return setError(KILN_ERROR_INVALID_ARGUMENT, "kiln_lppv_sample_batch: NULL argument");
    }
    for (size_t i = 0; i < count; ++i) {
      const float* p = positions + 3 * i;
      shToFloats(kiln::sampleLppv(volume->volume, glm::vec3(p[0], p[1], p[2])), out_sh + 27 * i);
    }
    return ok();
  });
}

const char* kiln_lppv_last_error(void) { return tlsLppvError.c_str(); }

}  // extern "C"
