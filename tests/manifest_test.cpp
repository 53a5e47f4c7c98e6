// manifest_test.cpp: kiln bake's manifest.json (lightmap/manifest.h): the writer and the reader
// agree (text -> Manifest -> the same text), the reader's errors name the file and the field,
// hostile sizes and scale/offsets are errors and not crashes (in the library and through
// `kiln bake --lock-atlas`). Unity interop: the manifest's unityScaleOffset finds the same
// texels as scaleOffset, and `kiln probes export --unity` evaluates, through Unity's ShadeSH9
// formula, to the .kprobe's E / pi, in glTF or Unity axes.
#include "lightmap/manifest.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "kiln/probe_runtime.h"
#include "kiln/probe_set.h"
#include "lightmap/atlas.h"
#include "src/gltf_loader.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

std::string kiln() { return std::string(test::kilnExe()) + " "; }

// A manifest with every key set, as a bake in Shadowmask mode with --ao, --directional and
// --ldr would write it.
Manifest fullManifest() {
  Manifest m;
  ManifestPage page0{256, 128, {}};
  page0.files.light = "lightmap-0_light.exr";
  page0.files.ao = "lightmap-0_ao.exr";
  page0.files.direction = "lightmap-0_direction.exr";
  page0.files.shadowmask = "lightmap-0_shadowmask.exr";
  page0.files.lightLdr = "lightmap-0_light_dldr.png";
  ManifestPage page1{64, 64, {}};
  page1.files.light = "lightmap-1_light.exr";
  m.lightmaps = {page0, page1};
  m.objects = {{"floor", 0, 0, vec4(0.2197f, 0.2148f, 0.0112f, 0.0117f)},
               {"lamp", 3, -1, vec4(1.0f, 1.0f, 0.0f, 0.0f)},
               {"wall", 5, 1, vec4(0.5f, 0.25f, 1.0f / 3.0f, 0.1f)}};
  m.settings = {{"resolution", 12.5},
                {"padding", 2},
                {"maxSize", 256},
                {"bounces", 3},
                {"albedoBoost", 1.5},
                {"indirectIntensity", 0.5},
                {"lightingMode", "shadowmask"},
                {"shadowColor", {0.42, 0.478, 0.627}},
                {"preset", nullptr},
                {"ldr", "dldr"}};
  ManifestLight sun;
  sun.name = "sun";
  sun.lightIndex = 0;
  sun.nodeIndex = 7;
  sun.mode = "mixed";
  sun.bakedDirect = false;
  sun.bakedIndirect = true;
  sun.shadowmaskChannel = 0;
  m.lights = std::vector<ManifestLight>{sun};
  m.gltf = "room.gltf";
  m.scene = "room.gltf";
  m.warnings = {"object 'wall' (nodeIndex 5): lightmap scaled down"};
  m.stats.texels = 1234;
  m.stats.invalidTexels = 5;
  m.stats.rays = 987654321012ull;
  return m;
}

TEST(Manifest, TextReadsBackToTheSameText) {
  const Manifest m = fullManifest();
  const std::string text = manifestText(m);
  ASSERT_EQ(text.back(), '\n');
  Result<Manifest> back = readManifest(Json::parse(text), "m.json", ManifestUse::kLightmaps);
  ASSERT_TRUE(back.ok()) << back.error();
  EXPECT_EQ(manifestText(*back), text);
  // The typed settings the readers use.
  const ManifestSettingsFields& f = back->settingsFields;
  EXPECT_EQ(f.resolution, 12.5f);
  EXPECT_EQ(f.padding, 2);
  EXPECT_EQ(f.maxSize, 256);
  EXPECT_EQ(f.bounces, 3);
  EXPECT_EQ(f.albedoBoost, 1.5f);
  EXPECT_EQ(f.indirectIntensity, 0.5f);
  EXPECT_EQ(f.lightingMode, LightingMode::Shadowmask);
  EXPECT_EQ(f.shadowColor, vec3(0.42f, 0.478f, 0.627f));
  // Floats survive the text exactly.
  for (size_t i = 0; i < m.objects.size(); ++i)
    EXPECT_EQ(back->objects[i].scaleOffset, m.objects[i].scaleOffset) << i;
  EXPECT_EQ(back->lightmaps[0].files.shadowmask, "lightmap-0_shadowmask.exr");
  EXPECT_EQ(back->lightmaps[1].files.ao, "");
  ASSERT_TRUE(back->lights.has_value());
  EXPECT_EQ((*back->lights)[0].shadowmaskChannel, 0);
  EXPECT_EQ(back->stats.rays, 987654321012ull);

  // Pages listed out of order are read into index order.
  Json shuffled = Json::parse(text);
  std::swap(shuffled["lightmaps"][0], shuffled["lightmaps"][1]);
  Result<Manifest> reordered = readManifest(shuffled, "m.json", ManifestUse::kLightmaps);
  ASSERT_TRUE(reordered.ok()) << reordered.error();
  EXPECT_EQ(manifestText(*reordered), text);
}

// Every check of the reader: a mutation of a good manifest and the start of the error it must
// give (file: field: ...).
TEST(Manifest, ReaderErrorsNameTheFileAndTheField) {
  const Json good = manifestJson(fullManifest());
  struct Case {
    std::function<void(Json&)> mutate;
    std::string error;  // expected prefix after "m.json: "
  };
  const std::vector<Case> cases = {
      {[](Json& j) { j = Json::array(); }, "expected a JSON object"},
      {[](Json& j) { j["version"] = 2; }, "version: expected 1"},
      {[](Json& j) { j.erase("version"); }, "version: expected 1"},
      {[](Json& j) { j["lightmaps"] = Json::object(); }, "lightmaps: expected an array"},
      {[](Json& j) { j.erase("objects"); }, "objects: expected an array"},
      {[](Json& j) { j["lightmaps"][1] = 3; }, "lightmaps[1]: expected an object"},
      {[](Json& j) { j["lightmaps"][1]["index"] = 0; }, "lightmaps[1].index: expected a unique"},
      {[](Json& j) { j["lightmaps"][1]["index"] = 2; }, "lightmaps[1].index"},
      {[](Json& j) { j["lightmaps"][1]["index"] = -1; }, "lightmaps[1].index"},
      {[](Json& j) { j["lightmaps"][0]["width"] = 0; }, "lightmaps[0].width: expected an integer"},
      {[](Json& j) { j["lightmaps"][0]["height"] = 65537; }, "lightmaps[0].height"},
      {[](Json& j) { j["lightmaps"][0]["height"] = 1ull << 40; }, "lightmaps[0].height"},
      {[](Json& j) { j["lightmaps"][0]["height"] = 18446744073709551615ull; },
       "lightmaps[0].height"},
      {[](Json& j) { j["lightmaps"][0]["width"] = 64.5; }, "lightmaps[0].width"},
      {[](Json& j) { j["lightmaps"][0]["width"] = 512; },
       "lightmaps[0].width: 512 exceeds settings.maxSize 256"},
      {[](Json& j) { j["lightmaps"][0].erase("files"); }, "lightmaps[0].files.light"},
      {[](Json& j) { j["lightmaps"][0]["files"]["light"] = 7; }, "lightmaps[0].files.light"},
      {[](Json& j) { j["lightmaps"][0]["files"]["ao"] = "../../etc/passwd"; },
       "lightmaps[0].files.ao: expected a file name in the manifest's folder"},
      {[](Json& j) { j["lightmaps"][0]["files"]["shadowmask"] = "/tmp/x.exr"; },
       "lightmaps[0].files.shadowmask"},
      {[](Json& j) { j["objects"][2] = "wall"; }, "objects[2]: expected an object"},
      {[](Json& j) { j["objects"][2]["nodeIndex"] = -3; }, "objects[2].nodeIndex"},
      {[](Json& j) { j["objects"][2]["nodeIndex"] = 1ll << 31; }, "objects[2].nodeIndex"},
      {[](Json& j) { j["objects"][2]["nodeIndex"] = 0; },
       "objects[2].nodeIndex: node 0 listed twice"},
      {[](Json& j) { j["objects"][2].erase("node"); }, "objects[2].node"},
      {[](Json& j) { j["objects"][2]["lightmapIndex"] = 2; },
       "objects[2].lightmapIndex: expected -1 or a page index below 2"},
      {[](Json& j) { j["objects"][2]["lightmapIndex"] = -2; }, "objects[2].lightmapIndex"},
      {[](Json& j) { j["objects"][2].erase("scaleOffset"); },
       "objects[2].scaleOffset: expected 4 finite numbers"},
      {[](Json& j) {
         j["objects"][2]["scaleOffset"] = {1, 1, 0};
       },
       "objects[2].scaleOffset"},
      {[](Json& j) { j["objects"][2]["scaleOffset"][3] = 1e39; }, "objects[2].scaleOffset"},
      {[](Json& j) { j["objects"][2]["scaleOffset"][0] = "1"; }, "objects[2].scaleOffset"},
      {[](Json& j) { j["objects"][1]["scaleOffset"] = nullptr; }, "objects[1].scaleOffset"},
      {[](Json& j) { j["settings"] = 1; }, "settings: expected an object"},
      {[](Json& j) { j["settings"]["resolution"] = 0; }, "settings.resolution"},
      {[](Json& j) { j["settings"]["resolution"] = 1e300; }, "settings.resolution"},
      {[](Json& j) { j["settings"]["padding"] = -1; }, "settings.padding"},
      {[](Json& j) { j["settings"]["maxSize"] = 100000; }, "settings.maxSize"},
      {[](Json& j) { j["settings"]["maxSize"] = 2.5; }, "settings.maxSize"},
      {[](Json& j) { j["settings"]["bounces"] = -1; }, "settings.bounces"},
      {[](Json& j) { j["settings"]["albedoBoost"] = 0; }, "settings.albedoBoost"},
      {[](Json& j) { j["settings"]["indirectIntensity"] = -1; }, "settings.indirectIntensity"},
      {[](Json& j) { j["settings"]["lightingMode"] = "fancy"; }, "settings.lightingMode"},
      {[](Json& j) {
         j["settings"]["shadowColor"] = {1, 2};
       },
       "settings.shadowColor"},
      {[](Json& j) { j["lights"] = 1; }, "lights: expected an array"},
      {[](Json& j) { j["lights"][0]["name"] = 1; }, "lights[0].name"},
      {[](Json& j) { j["lights"][0]["bakedDirect"] = 1; }, "lights[0].bakedDirect"},
      {[](Json& j) { j["lights"][0]["shadowmaskChannel"] = 4; }, "lights[0].shadowmaskChannel"},
      {[](Json& j) { j["lights"][0]["lightIndex"] = "0"; }, "lights[0].lightIndex"},
      {[](Json& j) { j["gltf"] = 1; }, "gltf"},
      {[](Json& j) { j["warnings"][0] = 1; }, "warnings[0]"},
      {[](Json& j) { j["stats"]["rays"] = -1; }, "stats.rays"},
  };
  for (size_t c = 0; c < cases.size(); ++c) {
    Json j = good;
    cases[c].mutate(j);
    Result<Manifest> r = readManifest(j, "m.json", ManifestUse::kLightmaps);
    ASSERT_FALSE(r.ok()) << "case " << c << ": " << j.dump();
    EXPECT_EQ(r.error().rfind("m.json: " + cases[c].error, 0), 0u)
        << "case " << c << ": " << r.error();
  }
  // The atlas alone needs neither a version nor files, but checks them when present.
  Json atlasOnly = good;
  atlasOnly.erase("version");
  for (Json& p : atlasOnly["lightmaps"]) p.erase("files");
  EXPECT_TRUE(readManifest(atlasOnly, "m.json", ManifestUse::kAtlas).ok());
  atlasOnly["version"] = 3;
  EXPECT_FALSE(readManifest(atlasOnly, "m.json", ManifestUse::kAtlas).ok());
}

// A scene of two unit quads on one page, and its manifest.
struct TwoQuads {
  Scene scene;
  AtlasLayout layout;
};
TwoQuads twoQuads() {
  TwoQuads t;
  test::addMaterial(t.scene, test::lambert(vec3(0.5f)));
  test::addQuad(t.scene, "floor", vec3(0, 0, 0), vec3(4, 0, 0), vec3(4, 0, -4), vec3(0, 0, -4), 0);
  test::addQuad(t.scene, "box", vec3(0, 1, 0), vec3(1, 1, 0), vec3(1, 1, -1), vec3(0, 1, -1), 0);
  for (uint32_t i = 0; i < t.scene.objects.size(); ++i) t.scene.objects[i].nodeIndex = int(i);
  AtlasSettings settings;
  settings.resolution = 8.0f;
  Result<AtlasLayout> layout = packAtlas(t.scene, settings);
  EXPECT_TRUE(layout.ok()) << layout.error();
  t.layout = *layout;
  return t;
}

// The hostile lock-atlas manifest's scale/offset (../shared/hostile): the texel rectangle
// lies ~2^31 texels away, where int arithmetic overflowed; it is an error naming the object.
TEST(Manifest, HostileScaleOffsetIsAnErrorNotAnOverflow) {
  const TwoQuads t = twoQuads();
  ASSERT_EQ(t.layout.objects[1].lightmapIndex, 0);
  const Json good = manifestJson(atlasManifest(t.layout, t.scene));
  ASSERT_TRUE(atlasFromManifest(good, t.scene).ok());
  const std::vector<std::array<double, 4>> hostile = {
      {15836149.0, 0.4145407974720001, 15519426.0, 0.027104591950774193},
      {1e30, 1e30, 0.0, 0.0},
      {1.0, 1.0, -1e30, 0.0},
      {-1e30, 1.0, 1e30, 0.0},
      {1e-30, 1e-30, 0.5, 0.5},  // a rectangle of no texels
      {0.5, 0.5, 0.75, 0.0},     // half outside the page
  };
  for (const auto& so : hostile) {
    Json j = good;
    j["objects"][1]["scaleOffset"] = so;
    Result<AtlasLayout> r = atlasFromManifest(j, t.scene);
    ASSERT_FALSE(r.ok()) << so[0] << " " << so[2];
    EXPECT_EQ(r.error(),
              "lock-atlas manifest: objects[1]: object 'box' (nodeIndex 1): scaleOffset "
              "puts its UV1 rectangle outside lightmap 0 (did its TEXCOORD_1 change?)");
  }
}

// kiln bake --lock-atlas with the hostile scale/offset in a real bake's manifest: exit 1, the
// manifest file and the object named, nothing written.
TEST(ManifestCli, LockAtlasWithHostileScaleOffsetIsBadInput) {
  const std::string scene = test::scenesDir() + "/cornell_box.gltf";
  const std::string dir = test::makeTempDir("manifest_cli");
  std::string out;
  ASSERT_EQ(test::runCommand(kiln() + "bake " + scene + " --preset preview --resolution 4 -q " +
                                 "--out " + dir + "/a",
                             &out),
            0)
      << out;
  Json m = Json::parse(test::readTextFile(dir + "/a/manifest.json"));
  size_t lit = 0;
  while (lit < m["objects"].size() && m["objects"][lit]["lightmapIndex"] < 0) ++lit;
  ASSERT_LT(lit, m["objects"].size());
  m["objects"][lit]["scaleOffset"] = {15836149.0, 0.4145407974720001, 15519426.0,
                                      0.027104591950774193};
  test::writeTextFile(dir + "/hostile.json", m.dump());
  EXPECT_EQ(test::runCommand(kiln() + "bake " + scene + " -q --out " + dir + "/b --lock-atlas " +
                                 dir + "/hostile.json",
                             &out),
            1)
      << out;
  EXPECT_NE(out.find("hostile.json: objects[" + std::to_string(lit) + "]: object '"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("outside lightmap"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir + "/b/manifest.json"));
  // A page size beyond the bound is named by the reader.
  m = Json::parse(test::readTextFile(dir + "/a/manifest.json"));
  m["lightmaps"][0]["width"] = 1ll << 33;
  test::writeTextFile(dir + "/huge.json", m.dump());
  EXPECT_EQ(test::runCommand(kiln() + "bake " + scene + " -q --out " + dir + "/b --lock-atlas " +
                                 dir + "/huge.json",
                             &out),
            1)
      << out;
  EXPECT_NE(out.find("huge.json: lightmaps[0].width: expected an integer in 1..65536"),
            std::string::npos)
      << out;
  fs::remove_all(dir);
}

// The hostile file itself (../shared/hostile/README.md), when ../shared is there.
TEST(ManifestCli, SharedHostileLockAtlasManifest) {
  const std::string base = test::sharedDir() + "/hostile/lock-atlas-int-overflow-segv";
  if (!fs::exists(base + ".manifest.json")) GTEST_SKIP() << base << ".manifest.json is absent";
  const std::string dir = test::makeTempDir("manifest_hostile");
  std::string out;
  EXPECT_EQ(test::runCommand(kiln() + "bake " + base + ".scene.gltf -q --out " + dir +
                                 "/out --lock-atlas " + base + ".manifest.json",
                             &out),
            1)
      << out;
  EXPECT_NE(out.find("lock-atlas-int-overflow-segv.manifest.json: objects[1]: object 'box'"),
            std::string::npos)
      << out;
  EXPECT_FALSE(fs::exists(dir + "/out/manifest.json"));
  fs::remove_all(dir);
}

// ---- Unity interop -------------------------------------------------------------------------

// unityScaleOffset on a real bake (two_rooms, several pages): for random UV1 points of every
// lightmapped object's UV1 rectangle, glTF's lookup (atlasUV = uv1 * s + o, v down, row 0 at
// the top) and Unity's (uv1 with v flipped, atlasUV = uv1_u * s_u + o_u, v up, row 0 of the
// file at v = 1) land on the same point of the page, up to float rounding, so on the same texel.
TEST(ManifestCli, UnityScaleOffsetFindsTheSameTexels) {
  const std::string dir = test::makeTempDir("manifest_unity");
  std::string out;
  ASSERT_EQ(test::runCommand(kiln() + "bake " + test::scenesDir() +
                                 "/two_rooms.gltf --preset preview --resolution 8 --samples 1 "
                                 "--bounces 0 --max-size 128 -q --out " +
                                 dir,
                             &out),
            0)
      << out;
  const Json raw = Json::parse(test::readTextFile(dir + "/manifest.json"));
  Result<Manifest> m = readManifestFile(dir + "/manifest.json", ManifestUse::kLightmaps);
  ASSERT_TRUE(m.ok()) << m.error();
  ASSERT_GT(m->lightmaps.size(), 1u);
  // The output glTF carries every object's UV1 (generated ones included).
  Result<Scene> scene = loadScene(dir + "/two_rooms.gltf");
  ASSERT_TRUE(scene.ok()) << scene.error();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int checked = 0, onEdge = 0;
  for (size_t i = 0; i < m->objects.size(); ++i) {
    const ManifestObject& o = m->objects[i];
    const Json& u = raw["objects"][i]["unityScaleOffset"];
    ASSERT_EQ(u.size(), 4u);
    const vec4 unity(u[0].get<float>(), u[1].get<float>(), u[2].get<float>(), u[3].get<float>());
    // The formula, independently: scale and ox unchanged, oy_u = 1 - sy - oy.
    EXPECT_EQ(unity.x, o.scaleOffset.x);
    EXPECT_EQ(unity.y, o.scaleOffset.y);
    EXPECT_EQ(unity.z, o.scaleOffset.z);
    EXPECT_NEAR(unity.w, 1.0 - double(o.scaleOffset.y) - o.scaleOffset.w, 1e-7);
    if (o.lightmapIndex < 0) continue;
    const Object* object = nullptr;
    for (const Object& so : scene->objects)
      if (so.nodeIndex == o.nodeIndex) object = &so;
    ASSERT_NE(object, nullptr) << o.node;
    ASSERT_EQ(object->uv1.size(), object->positions.size()) << o.node;
    const auto [lo, hi] = uv1Bounds(*object);
    const ManifestPage& page = m->lightmaps[size_t(o.lightmapIndex)];
    const float w = float(page.width), h = float(page.height);
    for (int k = 0; k < 200; ++k) {
      const vec2 uv1(float(lo.x + (hi.x - lo.x) * unit(rng)),
                     float(lo.y + (hi.y - lo.y) * unit(rng)));
      // glTF: texel column x, row y counted from the top (the first image row).
      const vec2 ag =
          uv1 * vec2(o.scaleOffset.x, o.scaleOffset.y) + vec2(o.scaleOffset.z, o.scaleOffset.w);
      const vec2 gltfTexel(ag.x * w, ag.y * h);
      // Unity: the importer's uv1 (v flipped), Unity's lookup, row counted from the bottom.
      const vec2 uv1Unity(uv1.x, 1.0f - uv1.y);
      const vec2 au = uv1Unity * vec2(unity.x, unity.y) + vec2(unity.z, unity.w);
      const vec2 unityTexel(au.x * w, (1.0f - au.y) * h);  // row from the top
      EXPECT_NEAR(unityTexel.x, gltfTexel.x, 1e-3f) << o.node;
      EXPECT_NEAR(unityTexel.y, gltfTexel.y, 1e-3f) << o.node;
      // Inside the page, on the same texel (unless within float rounding of a texel edge).
      EXPECT_GE(gltfTexel.x, 0.0f);
      EXPECT_LE(gltfTexel.x, w);
      EXPECT_GE(gltfTexel.y, 0.0f);
      EXPECT_LE(gltfTexel.y, h);
      const auto nearEdge = [](float t) { return std::abs(t - std::round(t)) < 1e-3f; };
      if (nearEdge(gltfTexel.x) || nearEdge(gltfTexel.y)) {
        ++onEdge;
        continue;
      }
      EXPECT_EQ(int(std::floor(unityTexel.x)), int(std::floor(gltfTexel.x)));
      EXPECT_EQ(int(std::floor(unityTexel.y)), int(std::floor(gltfTexel.y)));
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
  EXPECT_LT(onEdge, checked / 50);
  fs::remove_all(dir);
}

// Unity's ShadeSH9 (UnityCG.cginc: SHEvalLinearL0L1 + SHEvalLinearL2) on the exported
// constants of one probe, for a unit normal n in the export's axes, in double:
//   x1.c = dot(SHAc, (n, 1)); vB = n.xyzz * n.yzzx; x2.c = dot(SHBc, vB);
//   x3 = SHC.rgb * (n.x^2 - n.y^2); result = x1 + x2 + x3.
glm::dvec3 shadeSh9(const Json& p, glm::dvec3 n) {
  auto v4 = [&](const char* key) {
    const Json& a = p.at(key);
    return glm::dvec4(a[0].get<double>(), a[1].get<double>(), a[2].get<double>(),
                      a[3].get<double>());
  };
  const glm::dvec4 n1(n, 1.0);
  const glm::dvec3 x1(glm::dot(v4("SHAr"), n1), glm::dot(v4("SHAg"), n1), glm::dot(v4("SHAb"), n1));
  const glm::dvec4 vB = glm::dvec4(n.x, n.y, n.z, n.z) * glm::dvec4(n.y, n.z, n.z, n.x);
  const glm::dvec3 x2(glm::dot(v4("SHBr"), vB), glm::dot(v4("SHBg"), vB), glm::dot(v4("SHBb"), vB));
  const glm::dvec3 x3 = glm::dvec3(v4("SHC")) * (n.x * n.x - n.y * n.y);
  return x1 + x2 + x3;
}

// Float rounding bound of one channel of shadeSh9: a few float ulps of the sum of |terms|.
double shadeSh9Tolerance(const Json& p, int c) {
  double sum = 0.0;
  for (const char* key : {"SHAr", "SHAg", "SHAb", "SHBr", "SHBg", "SHBb"})
    if (key[3] == "rgb"[c])
      for (int k = 0; k < 4; ++k) sum += std::abs(p.at(key)[size_t(k)].get<double>());
  sum += std::abs(p.at("SHC")[size_t(c)].get<double>());
  return 1e-6 * sum + 1e-9;
}

TEST(ManifestCli, ProbesExportUnityEvaluatesToIrradianceOverPi) {
  const std::string dir = test::makeTempDir("manifest_probes_unity");
  // Eight probes in the Cornell box, off its symmetry plane (x = 0.28 is not 0), so that
  // mirroring x matters.
  Json positions = {{"positions", Json::array()}};
  for (int i = 0; i < 8; ++i)
    positions["positions"].push_back({0.28 + (i & 1 ? 0.07 : -0.07), 0.43 + (i & 2 ? 0.07 : -0.07),
                                      0.28 + (i & 4 ? 0.09 : -0.05)});
  test::writeTextFile(dir + "/pos.json", positions.dump());
  const std::string kprobe = dir + "/box.kprobe";
  std::string out;
  ASSERT_EQ(test::runCommand(kiln() + "probes bake " + test::scenesDir() +
                                 "/cornell_box.gltf --positions " + dir + "/pos.json --out " +
                                 kprobe + " --rays 256 --visibility-resolution 0 --quiet",
                             &out),
            0)
      << out;
  Result<ProbeSet> set = loadProbeFile(kprobe);
  ASSERT_TRUE(set.ok()) << set.error();
  ASSERT_EQ(set->probeCount(), 8);
  ASSERT_EQ(test::runCommand(
                kiln() + "probes export " + kprobe + " --unity --out " + dir + "/unity.json", &out),
            0)
      << out;
  ASSERT_EQ(test::runCommand(kiln() + "probes export " + kprobe + " --unity --axes gltf --out " +
                                 dir + "/gltf.json",
                             &out),
            0)
      << out;
  const Json unity = Json::parse(test::readTextFile(dir + "/unity.json"));
  const Json gltf = Json::parse(test::readTextFile(dir + "/gltf.json"));
  EXPECT_EQ(unity["axes"], "unity");
  EXPECT_EQ(gltf["axes"], "gltf");
  ASSERT_EQ(unity["sh9"].size(), 8u);
  ASSERT_EQ(gltf["sh9"].size(), 8u);

  // Per probe, many normals: ShadeSH9 of the export = the .kprobe's E(n) / pi; in Unity axes
  // with the mirrored normal (-x, y, z).
  std::mt19937 rng(3);
  std::normal_distribution<double> gauss;
  for (int i = 0; i < 8; ++i) {
    const vec3 p = set->positions[size_t(i)];
    for (int c = 0; c < 3; ++c) {
      EXPECT_EQ(gltf["positions"][i][c].get<float>(), p[c]);
      EXPECT_EQ(unity["positions"][i][c].get<float>(), c == 0 ? -p.x : p[c]);
    }
    for (int k = 0; k < 200; ++k) {
      glm::dvec3 n(gauss(rng), gauss(rng), gauss(rng));
      n = glm::normalize(n);
      const glm::dvec3 expected = glm::dvec3(set->sh[size_t(i)].irradiance(vec3(n))) / double(kPi);
      const glm::dvec3 inGltf = shadeSh9(gltf["sh9"][i], n);
      const glm::dvec3 inUnity = shadeSh9(unity["sh9"][i], glm::dvec3(-n.x, n.y, n.z));
      for (int c = 0; c < 3; ++c) {
        const double tol = shadeSh9Tolerance(gltf["sh9"][i], c) + 1e-6 * std::abs(expected[c]);
        EXPECT_NEAR(inGltf[c], expected[c], tol) << "probe " << i << " channel " << c;
        EXPECT_NEAR(inUnity[c], expected[c], tol) << "probe " << i << " channel " << c;
      }
    }
  }

  // A point between the probes: kiln's query at the glTF point and normal, and Unity's
  // blend at the mirrored point and normal (barycentric weights of the exported Unity
  // positions of the query's cell, the exported constants blended with them, ShadeSH9).
  const glm::dvec3 point(0.3, 0.45, 0.3);
  for (const glm::dvec3& nRaw : {glm::dvec3(0, 1, 0), glm::dvec3(1, 0, 0), glm::dvec3(-1, -1, 1),
                                 glm::dvec3(0.3, -0.2, -1)}) {
    const glm::dvec3 n = glm::normalize(nRaw);
    char args[160];
    std::snprintf(args, sizeof args, " %.9g %.9g %.9g %.9g %.9g %.9g", point.x, point.y, point.z,
                  n.x, n.y, n.z);
    ASSERT_EQ(
        test::runCommand(kiln() + "probes query " + kprobe + args + " --json --blend plain", &out),
        0)
        << out;
    const Json q = Json::parse(out);
    ASSERT_FALSE(q["outer"].get<bool>());
    glm::dvec3 corner[4];
    for (int k = 0; k < 4; ++k) {
      const Json& up = unity["positions"][q["probes"][k].get<int>()];
      corner[k] = glm::dvec3(up[0].get<double>(), up[1].get<double>(), up[2].get<double>());
    }
    // Barycentric coordinates of the Unity point in the Unity tetrahedron.
    const glm::dvec3 pu(-point.x, point.y, point.z);
    const glm::dmat3 t(corner[0] - corner[3], corner[1] - corner[3], corner[2] - corner[3]);
    const glm::dvec3 b3 = glm::inverse(t) * (pu - corner[3]);
    const double bary[4] = {b3.x, b3.y, b3.z, 1.0 - b3.x - b3.y - b3.z};
    glm::dvec3 blended(0.0);
    for (int k = 0; k < 4; ++k) {
      EXPECT_GE(bary[k], -1e-6);
      blended +=
          bary[k] * shadeSh9(unity["sh9"][q["probes"][k].get<int>()], glm::dvec3(-n.x, n.y, n.z));
    }
    for (int c = 0; c < 3; ++c) {
      const double e = q["irradiance"][c].get<double>() / double(kPi);
      EXPECT_NEAR(blended[c], e, 1e-5 * std::abs(e) + 1e-7)
          << "normal " << n.x << " " << n.y << " " << n.z << " channel " << c;
    }
  }

  // Bad usage: --axes without --unity, --unity with --visibility-moments.
  EXPECT_EQ(test::runCommand(kiln() + "probes export " + kprobe + " --axes gltf", &out), 2) << out;
  EXPECT_EQ(
      test::runCommand(kiln() + "probes export " + kprobe + " --unity --visibility-moments", &out),
      2)
      << out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace kiln
