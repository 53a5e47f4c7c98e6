// unbaked_result.h: a lightmap bake result without baking, for tests of what is written from
// one (output files, the output glTF): the scene's lightmap UVs (generated where missing) and
// atlas at `resolution`, and pages of zeros with every texel invalid. Tests fill the pages.
#pragma once

#include <gtest/gtest.h>

#include <optional>
#include <vector>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_baker.h"
#include "lightmap/uv_unwrap.h"

namespace kiln::test {

inline LightmapBakeResult unbakedResult(const Scene& scene, float resolution) {
  LightmapBakeResult r;
  r.scene = scene;
  Result<std::vector<std::optional<UnwrapResult>>> uvs =
      generateMissingLightmapUvs(r.scene, resolution);
  EXPECT_TRUE(uvs.ok()) << uvs.error();
  if (uvs.ok()) r.unwraps = *uvs;
  AtlasSettings atlas;
  atlas.resolution = resolution;
  Result<AtlasLayout> layout = packAtlas(r.scene, atlas);
  EXPECT_TRUE(layout.ok()) << layout.error();
  if (layout.ok()) r.layout = *layout;
  for (const AtlasPage& p : r.layout.pages) {
    LightmapPageResult page;
    page.light = Image(p.width, p.height, 3);
    page.valid.assign(size_t(p.width) * p.height, 0);
    r.pages.push_back(std::move(page));
  }
  return r;
}

}  // namespace kiln::test
