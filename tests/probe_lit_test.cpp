// probe_lit_test.cpp: the light kiln bake gives probe-lit objects (objects too small for a
// lightmap, lightmap/probe_lit.h): physically right in a white furnace, the same at any thread
// count, carried by the manifest (written, read back, bad values refused) and the output glTF
// (the same numbers on the node as in the manifest), and what `kiln render` lights the object
// with.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>

#include "kiln/probe_runtime.h"
#include "lightmap/lightmap_baker.h"
#include "lightmap/manifest.h"
#include "src/image.h"
#include "src/sky.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

// |E(n) / pi - 1| allowed in the white furnace, per channel. Measured: at most 0.0042 over the
// normals below (the paths' Russian roulette); the margin covers Embree's differing bits
// between CPUs, which move individual paths, not the mean.
constexpr float kFurnaceTolerance = 0.01f;
// The Cornell box render's sum over pixels with the probe-lit faces lit, over the same with
// their probe light zeroed, at least: measured 1421.07 / 1392.05 = 1.021 (the short block's
// faces and the tall block's top, a small share of the view); a render that ignored the
// manifest's probe light would give 1.000.
constexpr double kRenderShare = 1.01;

// A 2 m white floor (double-sided, lightmapped) and a white 10 cm box above it that is too
// small for a lightmap at 10 texels per unit with minObjectTexels 50 (6 texels), under a
// uniform sky of radiance 1.
Scene furnaceScene() {
  Scene scene;
  const uint32_t white = test::addMaterial(scene, test::lambert(vec3(1.0f), vec3(0.0f), true));
  test::addQuad(scene, "floor", vec3(-1, 0, 1), vec3(1, 0, 1), vec3(1, 0, -1), vec3(-1, 0, -1),
                white);
  test::addBox(scene, "prop", vec3(-0.05f, 0.5f, -0.05f), vec3(0.05f, 0.6f, 0.05f), white, false);
  scene.sky = Sky::constant(vec3(1.0f));
  return scene;
}

LightmapBakeSettings furnaceSettings(int threads) {
  LightmapBakeSettings s;
  s.resolution = 10.0f;
  s.minObjectTexels = 50.0f;
  s.samplesPerTexel = 16;
  s.threads = threads;
  return s;
}

// White furnace: every surface is white and sees the uniform sky or other surfaces of radiance
// 1, so every direction brings radiance 1 and the irradiance is pi for every normal. The probe
// light's SH must say so (what is left: the Sobol quadrature of 4096 rays per probe and the
// paths' Russian roulette).
TEST(ProbeLit, WhiteFurnaceGivesPiForEveryNormal) {
  const Scene scene = furnaceScene();
  Result<LightmapBakeResult> baked = bakeLightmaps(scene, furnaceSettings(0));
  ASSERT_TRUE(baked.ok()) << baked.error();
  ASSERT_EQ(baked->objectProbes.size(), 2u);
  EXPECT_FALSE(baked->objectProbes[0].has_value());  // the floor has a lightmap
  EXPECT_GE(baked->layout.objects[0].lightmapIndex, 0);
  ASSERT_TRUE(baked->layout.objects[1].probeLit);
  ASSERT_TRUE(baked->objectProbes[1].has_value());
  const ShL2Rgb& sh = baked->objectProbes[1]->sh;
  const vec3 normals[] = {{1, 0, 0},  {-1, 0, 0}, {0, 1, 0},  {0, -1, 0},
                          {0, 0, 1},  {0, 0, -1}, {0.577350f, 0.577350f, 0.577350f},
                          {-0.577350f, -0.577350f, 0.577350f}};
  float worst = 0.0f;
  for (const vec3& n : normals) {
    const vec3 e = probeIrradiance(sh, n) / kPi;
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(e[c], 1.0f, kFurnaceTolerance) << "normal " << n.x << " " << n.y << " " << n.z;
      worst = std::max(worst, std::abs(e[c] - 1.0f));
    }
  }
  std::cout << "white furnace: max |E(n) / pi - 1| = " << worst << "\n";
  // Uniform light has no direction: bands 1 and 2 vanish next to c0 = sqrt(4 pi).
  EXPECT_NEAR(sh.c[0].g, std::sqrt(4.0f * kPi), 3.545f * kFurnaceTolerance);
  for (int i = 1; i < kShL2Count; ++i)
    EXPECT_LT(std::abs(sh.c[size_t(i)].g), 3.545f * kFurnaceTolerance) << "coefficient " << i;
  EXPECT_EQ(baked->objectProbes[1]->occlusion, glm::vec4(1.0f));  // no shadowmask lights
}

// The probe light is keyed by the seed and the object, never by the thread that bakes it.
TEST(ProbeLit, SameBitsAtAnyThreadCount) {
  const Scene scene = furnaceScene();
  Result<LightmapBakeResult> one = bakeLightmaps(scene, furnaceSettings(1));
  Result<LightmapBakeResult> two = bakeLightmaps(scene, furnaceSettings(2));
  ASSERT_TRUE(one.ok() && two.ok());
  ASSERT_TRUE(one->objectProbes[1] && two->objectProbes[1]);
  EXPECT_EQ(std::memcmp(&one->objectProbes[1]->sh, &two->objectProbes[1]->sh, sizeof(ShL2Rgb)), 0);
  // Another seed gives other numbers: the seed reaches the probe light.
  LightmapBakeSettings seeded = furnaceSettings(2);
  seeded.seed = 7;
  Result<LightmapBakeResult> other = bakeLightmaps(scene, seeded);
  ASSERT_TRUE(other.ok() && other->objectProbes[1]);
  EXPECT_NE(std::memcmp(&one->objectProbes[1]->sh, &other->objectProbes[1]->sh, sizeof(ShL2Rgb)),
            0);
}

// The manifest reader takes probeSH and probeOcclusion back and refuses bad ones by name.
TEST(ProbeLit, ManifestRoundTripAndErrors) {
  Manifest m;
  m.lightmaps = {{16, 16, {}}};
  m.lightmaps[0].files.light = "lightmap-0_light.exr";
  m.objects = {{"floor", 0, 0, vec4(1.0f, 1.0f, 0.0f, 0.0f)},
               {"cup", 1, -1, vec4(1.0f, 1.0f, 0.0f, 0.0f), true}};
  ShL2Rgb sh;
  for (int i = 0; i < kShL2Count; ++i) sh.c[size_t(i)] = vec3(0.5f + i, -0.25f * i, 1.0f / (i + 3));
  m.objects[1].probeSh = sh;
  m.objects[1].probeOcclusion = vec4(1.0f, 0.25f, 0.0f, 1.0f);
  const Json j = Json::parse(manifestText(m));
  ASSERT_EQ(j["objects"][1]["probeSH"].size(), 27u);
  EXPECT_FLOAT_EQ(j["objects"][1]["probeSH"][3].get<float>(), 1.5f);  // c1.r: coefficient-major
  EXPECT_FALSE(j["objects"][0].contains("probeSH"));
  Result<Manifest> back = readManifest(j, "m.json", ManifestUse::kLightmaps);
  ASSERT_TRUE(back.ok()) << back.error();
  ASSERT_TRUE(back->objects[1].probeSh && back->objects[1].probeOcclusion);
  EXPECT_EQ(std::memcmp(&*back->objects[1].probeSh, &sh, sizeof sh), 0);
  EXPECT_EQ(*back->objects[1].probeOcclusion, vec4(1.0f, 0.25f, 0.0f, 1.0f));
  EXPECT_EQ(manifestText(*back), manifestText(m));

  const struct {
    void (*mutate)(Json&);
    const char* error;
  } cases[] = {
      {[](Json& doc) { doc["objects"][1]["probeSH"].erase(26); },
       "objects[1].probeSH: expected 27 finite numbers"},
      {[](Json& doc) { doc["objects"][1]["probeSH"][4] = "x"; },
       "objects[1].probeSH: expected 27 finite numbers"},
      {[](Json& doc) { doc["objects"][0]["probeSH"] = doc["objects"][1]["probeSH"]; },
       "objects[0].probeSH: only a probe-lit object has one"},
      {[](Json& doc) { doc["objects"][1]["probeOcclusion"][1] = 1.5; },
       "objects[1].probeOcclusion: expected 4 numbers in [0, 1]"},
  };
  for (const auto& c : cases) {
    Json bad = j;
    c.mutate(bad);
    Result<Manifest> r = readManifest(bad, "m.json", ManifestUse::kLightmaps);
    ASSERT_FALSE(r.ok()) << c.error;
    EXPECT_EQ(r.error().rfind(std::string("m.json: ") + c.error, 0), 0u) << r.error();
  }
}

// kiln bake on the Cornell box with the short block's faces, the tall block's top and the lamp
// too small for a lightmap: the manifest and the output glTF carry the same probe light for
// exactly the probe-lit nodes, and kiln render of the output lights them with the manifest's:
// with every probeSH set to 0 in the manifest, the image loses their light.
TEST(ProbeLit, BakeWritesManifestAndGltfAndRenderReadsThem) {
  const std::string dir = test::makeTempDir("kiln_probe_lit");
  const std::string scene = test::scenesDir() + "/cornell_box.gltf";
  std::string out;
  ASSERT_EQ(test::runCommand(std::string(test::kilnExe()) + " bake \"" + scene + "\" --out \"" +
                                 dir + "\" --preset preview --resolution 60 "
                                 "--min-object-texels 150 --quiet",
                             &out),
            0)
      << out;
  const Json manifest = Json::parse(test::readTextFile(dir + "/manifest.json"));
  const Json gltf = Json::parse(test::readTextFile(dir + "/cornell_box.gltf"));
  int probeLit = 0;
  for (const Json& o : manifest["objects"]) {
    const Json& node = gltf["nodes"][o["nodeIndex"].get<size_t>()];
    const bool lit = o.value("probeLit", false);
    const Json* kiln = node.contains("extras") && node["extras"].contains("kiln")
                           ? &node["extras"]["kiln"]
                           : nullptr;
    if (!lit) {
      EXPECT_FALSE(o.contains("probeSH")) << o.dump();
      EXPECT_FALSE(kiln && kiln->contains("probeSH")) << node.dump();
      continue;
    }
    ++probeLit;
    ASSERT_TRUE(o.contains("probeSH")) << o.dump();
    ASSERT_EQ(o["probeSH"].size(), 27u);
    ASSERT_TRUE(kiln && kiln->contains("probeSH")) << node.dump();
    EXPECT_EQ((*kiln)["probeSH"], o["probeSH"]);
    EXPECT_FALSE(node.contains("extensions") && node["extensions"].contains("MX_lightmap"));
    // Lit by the ceiling lamp through the room: E(+y) > 0 and c0 > 0 in every channel.
    ShL2Rgb sh;
    for (int i = 0; i < kShL2Count; ++i)
      for (int c = 0; c < 3; ++c) sh.c[size_t(i)][c] = o["probeSH"][size_t(3 * i + c)].get<float>();
    const vec3 up = probeIrradiance(sh, vec3(0, 1, 0));
    EXPECT_GT(glm::min(up.r, glm::min(up.g, up.b)), 0.0f) << o["node"];
  }
  EXPECT_EQ(probeLit, 7) << manifest["objects"].dump();  // 5 short faces, tall top, lamp
  // kiln render of the output glTF with its lightmaps (no warning about unlit nodes or unknown
  // keys), then with the probe light zeroed in a copy of the manifest.
  auto render = [&](const std::string& lightmaps) {
    const std::string exr = lightmaps + "/render.exr";
    EXPECT_EQ(test::runCommand(std::string(test::kilnExe()) + " render \"" + dir +
                                   "/cornell_box.gltf\" --lightmaps \"" + lightmaps +
                                   "\" --size 64,64 --out \"" + lightmaps +
                                   "/render.png\" --linear \"" + exr + "\" --quiet",
                               &out),
              0)
        << out;
    EXPECT_EQ(out.find("warning"), std::string::npos) << out;
    Result<Image> image = readHdrImage(exr);
    EXPECT_TRUE(image.ok()) << (image.ok() ? "" : image.error());
    double sum = 0.0;
    if (image.ok())
      for (size_t i = 0; i < image->pixels.size(); ++i)
        if (int(i % size_t(image->channels)) < 3) sum += double(image->pixels[i]);
    return sum;
  };
  const double lit = render(dir);
  const std::string zeroed = dir + "/zeroed";
  fs::create_directories(zeroed);
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.is_regular_file()) fs::copy_file(entry.path(), zeroed / entry.path().filename());
  Json dark = manifest;
  for (Json& o : dark["objects"])
    if (o.contains("probeSH")) o["probeSH"] = std::vector<float>(27, 0.0f);
  test::writeTextFile(zeroed + "/manifest.json", dark.dump(2));
  const double unlit = render(zeroed);
  std::cout << "render sums: with the probe light " << lit << ", without " << unlit << "\n";
  EXPECT_GT(lit, kRenderShare * unlit);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace kiln
