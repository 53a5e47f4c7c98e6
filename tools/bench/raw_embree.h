// raw_embree.h: the benchmarks' baseline, a bare Embree 3 scene of a kiln Scene's triangles
// (one geometry per object, geometry ID = object index, kiln's Tracer flags and build
// quality, no filter functions) and the conversion of kiln's rays to Embree's.
#pragma once

#include <embree3/rtcore.h>

#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

inline RTCRay toRtcRay(const Ray& r) {
  RTCRay ray;
  ray.org_x = r.origin.x;
  ray.org_y = r.origin.y;
  ray.org_z = r.origin.z;
  ray.dir_x = r.direction.x;
  ray.dir_y = r.direction.y;
  ray.dir_z = r.direction.z;
  ray.tnear = r.tMin;
  ray.tfar = r.tMax;
  ray.time = 0.0f;
  ray.mask = 0xFFFFFFFFu;
  ray.id = 0;
  ray.flags = 0;
  return ray;
}

// The committed scene (release it with rtcReleaseScene); `triangles` gets the count.
inline RTCScene buildRawEmbreeScene(RTCDevice device, const Scene& scene, size_t& triangles) {
  RTCScene raw = rtcNewScene(device);
  rtcSetSceneFlags(raw, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(raw, RTC_BUILD_QUALITY_MEDIUM);
  triangles = 0;
  for (uint32_t o = 0; o < scene.objects.size(); ++o) {
    const Object& obj = scene.objects[o];
    if (obj.triangles.empty()) continue;
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), obj.positions.size()));
    for (size_t i = 0; i < obj.positions.size(); ++i)
      for (int k = 0; k < 3; ++k) v[3 * i + k] = obj.positions[i][k];
    auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
        g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t),
        obj.triangles.size()));
    for (size_t i = 0; i < obj.triangles.size(); ++i)
      for (int k = 0; k < 3; ++k) idx[3 * i + k] = obj.triangles[i][k];
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(raw, g, o);
    rtcReleaseGeometry(g);
    triangles += obj.triangles.size();
  }
  rtcCommitScene(raw);
  return raw;
}

}  // namespace kiln
