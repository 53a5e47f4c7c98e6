// probe_lit.h: kiln bake's light for probe-lit objects, the objects too small for a useful
// lightmap at the bake's resolution (AtlasObject::probeLit, atlas.h). A viewer without kiln's
// probes (three.js with the output glTF alone) has nothing else to light them with, so the bake
// gives each one its own L2 radiance SH (bakeObjectProbe, probes/probe_baker.h: probes just
// outside its bounds' faces, the lightmaps' lighting mode and transport settings, the bake's
// tracer), written to the manifest ("probeSH", "probeOcclusion") and to the output glTF's node
// (extras.kiln.probeSH, .probeOcclusion); kiln render reads it from there
// (docs/lightmap_outputs.md, "Objects too small for a lightmap").
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <vector>

#include "lightmap/atlas.h"
#include "probes/probe_baker.h"
#include "src/light_modes.h"
#include "src/parallel.h"
#include "src/scene.h"
#include "src/tracer.h"

namespace kiln {

// The probe bake settings (rays, light and occlusion samples; the integrator's bounces, albedo
// boost and indirect intensity, lighting mode) that light the probe-lit objects of a lightmap
// bake with these transport settings: `kiln probes bake`'s defaults otherwise.
ProbeBakeSettings probeLitBakeSettings(LightingMode lightingMode, int bounces, float albedoBoost,
                                       float indirectIntensity);

// Bakes one ObjectProbe per probe-lit object of `layout` (nullopt for the others), over
// `tracer` (the lightmap bake's), keyed by `seed` and the object index: the same at any thread
// count. A distributed bake (src/distributed.h) splits the objects over the ranks and gathers
// them on rank 0 (the others' entries stay nullopt there). Adds the rays traced to `rays`.
// Returns false when cancelled.
bool bakeProbeLitObjects(const Scene& scene, const AtlasLayout& layout, const Tracer& tracer,
                         const ProbeBakeSettings& settings, uint64_t seed, bool showProgress,
                         ParallelOptions parallel,
                         std::vector<std::optional<ObjectProbe>>& out,
                         std::atomic<uint64_t>& rays);

}  // namespace kiln
