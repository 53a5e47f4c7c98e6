// bake_output_test.cpp: kiln bake's outputs (lightmap_writer.h, gltf_writer.h) and the CLI:
// manifest schema and values, scaleOffset round trip through the written EXR, EXR
// orientation, the output glTF (lightmaps referenced, generated UV1 on rebuilt meshes in
// local space), atomicity (a failing or interrupted bake leaves earlier outputs
// byte-identical), determinism across thread counts, --lock-atlas, exit codes.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <tuple>
#include <vector>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_writer.h"
#include "lightmap/uv_unwrap.h"
#include "src/gltf_loader.h"
#include "src/image.h"
#include "src/light_modes.h"
#include "tests/test_util.h"
#include "tests/unbaked_result.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

std::string readBytes(const std::string& path) { return test::readTextFile(path); }

std::string cornellBox() { return test::scenesDir() + "/cornell_box.gltf"; }

// A bake result without baking: the scene's UVs and atlas, and pages where every texel of an
// object's rectangle holds (object index + 1, x, y) so that lookups can be checked exactly
// (integers below 2048 survive half floats).
LightmapBakeResult fakeResult(const Scene& scene, float resolution = 20.0f) {
  LightmapBakeResult r = test::unbakedResult(scene, resolution);
  for (size_t i = 0; i < r.layout.objects.size(); ++i) {
    const AtlasObject& o = r.layout.objects[i];
    if (o.lightmapIndex < 0) continue;
    Image& img = r.pages[size_t(o.lightmapIndex)].light;
    for (int y = o.texelMin.y; y < o.texelMin.y + o.texelSize.y; ++y)
      for (int x = o.texelMin.x; x < o.texelMin.x + o.texelSize.x; ++x) {
        img.at(x, y)[0] = float(i + 1);
        img.at(x, y)[1] = float(x);
        img.at(x, y)[2] = float(y);
      }
  }
  r.stats.texels = 123;
  r.stats.rays = 456;
  return r;
}

Scene load(const std::string& path) {
  Result<Scene> s = loadScene(path);
  EXPECT_TRUE(s.ok()) << s.error();
  return s.ok() ? *s : Scene{};
}

Json readJson(const std::string& path) { return Json::parse(test::readTextFile(path)); }

TEST(LightmapWriter, ManifestSchemaAndValues) {
  const Scene scene = load(cornellBox());
  const LightmapBakeResult r = fakeResult(scene);
  LightmapBakeSettings settings;
  settings.seed = 42;
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("bake_out");
  out.preset = "low";
  out.kilnVersion = "9.9.9";
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, settings, out).ok());

  const Json m = readJson(out.outDir + "/manifest.json");
  EXPECT_EQ(m["version"], 1);
  ASSERT_EQ(m["lightmaps"].size(), r.layout.pages.size());
  for (size_t i = 0; i < r.layout.pages.size(); ++i) {
    EXPECT_EQ(m["lightmaps"][i]["index"], i);
    EXPECT_EQ(m["lightmaps"][i]["width"], r.layout.pages[i].width);
    EXPECT_EQ(m["lightmaps"][i]["height"], r.layout.pages[i].height);
    const std::string light = m["lightmaps"][i]["files"]["light"];
    EXPECT_EQ(light, "lightmap-" + std::to_string(i) + "_light.exr");
    EXPECT_TRUE(fs::exists(out.outDir + "/" + light));
  }
  ASSERT_EQ(m["objects"].size(), scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const Json& o = m["objects"][i];
    EXPECT_EQ(o["node"], scene.objects[i].name);
    EXPECT_EQ(o["nodeIndex"], scene.objects[i].nodeIndex);
    EXPECT_EQ(o["lightmapIndex"], r.layout.objects[i].lightmapIndex);
    for (int k = 0; k < 4; ++k)
      EXPECT_EQ(o["scaleOffset"][size_t(k)].get<float>(), r.layout.objects[i].scaleOffset[k]);
  }
  const Json& s = m["settings"];
  EXPECT_EQ(s["seed"], 42);
  EXPECT_EQ(s["preset"], "low");
  EXPECT_EQ(s["kilnVersion"], "9.9.9");
  for (const char* key : {"resolution", "padding", "maxSize", "samplesPerTexel", "supersampling",
                          "bounces", "albedoBoost", "indirectIntensity", "ambientOcclusion",
                          "aoMaxDistance", "aoAmount", "denoise", "stitchSeams", "lockAtlas"})
    EXPECT_TRUE(s.contains(key)) << key;
  EXPECT_EQ(m["stats"]["texels"], 123);
  EXPECT_EQ(m["stats"]["rays"], 456);
  EXPECT_TRUE(m["warnings"].is_array());
  // No temporaries left behind.
  for (const auto& e : fs::directory_iterator(out.outDir))
    EXPECT_EQ(e.path().string().find(".kiln-tmp"), std::string::npos) << e.path();
}

// atlasUV = uv1 x scale + offset, read from the written manifest and EXR, lands in the
// object's own texels: the value there names the object.
TEST(LightmapWriter, ScaleOffsetRoundTripThroughFiles) {
  const Scene scene = load(cornellBox());
  const LightmapBakeResult r = fakeResult(scene);
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("bake_out");
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
  const Json m = readJson(out.outDir + "/manifest.json");
  Result<Image> page = readHdrImage(out.outDir + "/lightmap-0_light.exr");
  ASSERT_TRUE(page.ok()) << page.error();
  int checked = 0;
  for (size_t i = 0; i < r.scene.objects.size(); ++i) {
    const Object& o = r.scene.objects[i];
    const Json& so = m["objects"][i]["scaleOffset"];
    ASSERT_EQ(m["objects"][i]["lightmapIndex"], 0);
    for (const uvec3& t : o.triangles) {
      // Triangle centroid and points near each corner (inside the triangle).
      const vec2 c = (o.uv1[t.x] + o.uv1[t.y] + o.uv1[t.z]) / 3.0f;
      for (vec2 uv : {c, glm::mix(c, o.uv1[t.x], 0.9f), glm::mix(c, o.uv1[t.y], 0.9f),
                      glm::mix(c, o.uv1[t.z], 0.9f)}) {
        const float au = uv.x * so[0].get<float>() + so[2].get<float>();
        const float av = uv.y * so[1].get<float>() + so[3].get<float>();
        const int x = int(std::floor(au * float(page->width)));
        const int y = int(std::floor(av * float(page->height)));
        ASSERT_TRUE(x >= 0 && y >= 0 && x < page->width && y < page->height);
        const vec3 v = page->rgb(x, y);
        EXPECT_EQ(v.r, float(i + 1)) << o.name << " uv " << uv.x << "," << uv.y;
        EXPECT_EQ(v.g, float(x));  // the file's (x, y) is the texel's: row 0 = v 0
        EXPECT_EQ(v.b, float(y));
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 60);
}

TEST(LightmapWriter, ExrIsHalfRgbInGltfOrientation) {
  const Scene scene = load(cornellBox());
  LightmapBakeResult r = fakeResult(scene);
  Image& img = r.pages[0].light;
  for (float& v : img.pixels) v = 0.0f;
  for (int x = 0; x < img.width; ++x) img.at(x, 0)[0] = 1.0f;  // first row = v 0 = top
  img.at(0, img.height - 1)[2] = 0.1f;                        // not a half: rounded
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("bake_out");
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
  Result<Image> back = readHdrImage(out.outDir + "/lightmap-0_light.exr");
  ASSERT_TRUE(back.ok());
  EXPECT_EQ(back->rgb(3, 0).r, 1.0f);
  EXPECT_EQ(back->rgb(3, 1).r, 0.0f);
  EXPECT_NE(back->rgb(0, img.height - 1).b, 0.1f);  // stored as half
  EXPECT_NEAR(back->rgb(0, img.height - 1).b, 0.1f, 1e-4f);
}

TEST(LightmapWriter, LdrAndAoFilesAreListed) {
  const Scene scene = load(cornellBox());
  LightmapBakeResult r = fakeResult(scene);
  for (LightmapPageResult& p : r.pages) {
    for (float& v : p.light.pixels) v = 0.25f;
    p.ambientOcclusion = Image(p.light.width, p.light.height, 1);
    p.direction = Image(p.light.width, p.light.height, 4);
  }
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("bake_out");
  out.ldr = LdrEncoding::Rgbm;
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
  const Json m = readJson(out.outDir + "/manifest.json");
  EXPECT_EQ(m["lightmaps"][0]["files"]["ao"], "lightmap-0_ao.exr");
  EXPECT_EQ(m["lightmaps"][0]["files"]["lightLdr"], "lightmap-0_light_rgbm.png");
  EXPECT_TRUE(fs::exists(out.outDir + "/lightmap-0_ao.exr"));
  EXPECT_EQ(m["lightmaps"][0]["files"]["direction"], "lightmap-0_direction.exr");
  EXPECT_FALSE(m["lightmaps"][0]["files"].contains("shadowmask"));  // none baked
  EXPECT_TRUE(fs::exists(out.outDir + "/lightmap-0_direction.exr"));
  EXPECT_TRUE(fs::exists(out.outDir + "/lightmap-0_light_rgbm.png"));
  EXPECT_EQ(m["settings"]["ldr"], "rgbm");
}

// A failing write (here: the input glTF is gone when the output glTF is built, after the
// EXRs were written) leaves the previous outputs byte-identical and no temporaries.
TEST(LightmapWriter, FailureLeavesEarlierOutputsIntact) {
  const std::string dir = test::makeTempDir("bake_out");
  const std::string scenePath = dir + "/in/cornell_box.gltf";
  fs::create_directories(dir + "/in");
  fs::copy_file(cornellBox(), scenePath);
  fs::copy_file(test::scenesDir() + "/cornell_box.bin", dir + "/in/cornell_box.bin");
  const Scene scene = load(scenePath);
  LightmapBakeResult r = fakeResult(scene);
  LightmapOutputSettings out;
  out.outDir = dir + "/out";
  ASSERT_TRUE(writeLightmapOutputs(scenePath, r, LightmapBakeSettings{}, out).ok());
  std::map<std::string, std::string> before;
  for (const auto& e : fs::directory_iterator(out.outDir))
    before[e.path().filename().string()] = readBytes(e.path().string());
  // EXR, dLDR PNG (the glTF's lightmap texture), manifest, glTF, its buffer copied
  EXPECT_EQ(before.size(), 5u);

  for (float& v : r.pages[0].light.pixels) v = 7.0f;  // different content
  fs::remove(scenePath);
  EXPECT_FALSE(writeLightmapOutputs(scenePath, r, LightmapBakeSettings{}, out).ok());
  std::map<std::string, std::string> after;
  for (const auto& e : fs::directory_iterator(out.outDir))
    after[e.path().filename().string()] = readBytes(e.path().string());
  EXPECT_EQ(before, after);
}

// The output glTF: the lightmaps on the root, each lightmapped node's index and
// scaleOffset, and buffers still found from the output directory.
TEST(GltfWriter, ReferencesLightmapsAndLoads) {
  const Scene scene = load(cornellBox());
  const LightmapBakeResult r = fakeResult(scene);
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("bake_out");
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
  const Json g = readJson(out.outDir + "/cornell_box.gltf");
  const Json m = readJson(out.outDir + "/manifest.json");
  EXPECT_EQ(g["extras"]["kiln"]["lightmaps"], m["lightmaps"]);
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const Json& node = g["nodes"][size_t(scene.objects[i].nodeIndex)];
    EXPECT_EQ(node["extras"]["kiln"]["lightmap"]["index"], m["objects"][i]["lightmapIndex"]);
    EXPECT_EQ(node["extras"]["kiln"]["lightmap"]["scaleOffset"], m["objects"][i]["scaleOffset"]);
  }
  const Scene again = load(out.outDir + "/cornell_box.gltf");
  ASSERT_EQ(again.objects.size(), scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i)
    EXPECT_EQ(again.objects[i].positions, scene.objects[i].positions);
}

// A scene without TEXCOORD_1: one mesh instanced by two nodes (one mirrored), two primitives
// (a list with an unused vertex and a strip). The output glTF gets one new mesh per node with
// the generated UV1 in local space; loading it gives the baked objects back.
TEST(GltfWriter, GeneratedUvsRebuildLocalMeshes) {
  const std::string dir = test::makeTempDir("bake_out");
  // Primitive 0: a unit quad as a list (vertex 4 unused); primitive 1: a strip quad at x=2.
  std::vector<float> pos = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 9, 9, 9,
                            2, 0, 0, 3, 0, 0, 2, 1, 0, 3, 1, 0};
  std::vector<float> col = {};
  for (int v = 0; v < 9; ++v) {
    col.insert(col.end(), {float(v) / 8.0f, 0.5f, 1.0f, 1.0f});
  }
  std::vector<uint16_t> listIdx = {0, 1, 2, 0, 2, 3};
  std::vector<uint16_t> stripIdx = {0, 1, 2, 3};
  std::string bin;
  auto append = [&](const void* p, size_t n) {
    while (bin.size() % 4) bin.push_back('\0');
    const size_t off = bin.size();
    bin.append(static_cast<const char*>(p), n);
    return off;
  };
  const size_t pos0 = append(pos.data(), 5 * 12), pos1 = append(pos.data() + 15, 4 * 12);
  const size_t col0 = append(col.data(), 5 * 16), col1 = append(col.data() + 20, 4 * 16);
  const size_t idx0 = append(listIdx.data(), 12), idx1 = append(stripIdx.data(), 8);
  test::writeTextFile(dir + "/two.bin", bin);
  Json g = {{"asset", {{"version", "2.0"}}}, {"scene", 0}};
  g["buffers"] = {{{"uri", "two.bin"}, {"byteLength", bin.size()}}};
  Json views = Json::array(), accessors = Json::array();
  auto add = [&](size_t off, size_t len, int comp, size_t count, const char* type) {
    views.push_back({{"buffer", 0}, {"byteOffset", off}, {"byteLength", len}});
    accessors.push_back({{"bufferView", views.size() - 1},
                         {"componentType", comp},
                         {"count", count},
                         {"type", type}});
    return int(accessors.size() - 1);
  };
  const int p0 = add(pos0, 60, 5126, 5, "VEC3"), p1 = add(pos1, 48, 5126, 4, "VEC3");
  accessors[size_t(p0)]["min"] = {0, 0, 0};
  accessors[size_t(p0)]["max"] = {9, 9, 9};
  accessors[size_t(p1)]["min"] = {2, 0, 0};
  accessors[size_t(p1)]["max"] = {3, 1, 0};
  const int c0 = add(col0, 80, 5126, 5, "VEC4"), c1 = add(col1, 64, 5126, 4, "VEC4");
  const int i0 = add(idx0, 12, 5123, 6, "SCALAR"), i1 = add(idx1, 8, 5123, 4, "SCALAR");
  g["bufferViews"] = views;
  g["accessors"] = accessors;
  g["meshes"] = {{{"name", "m"},
                  {"primitives",
                   {{{"attributes", {{"POSITION", p0}, {"COLOR_0", c0}}}, {"indices", i0}},
                    {{"attributes", {{"POSITION", p1}, {"COLOR_0", c1}}},
                     {"indices", i1},
                     {"mode", 5}}}}}};
  g["nodes"] = {{{"name", "a"}, {"mesh", 0}, {"translation", {0, 0, 1}}},
                {{"name", "b"}, {"mesh", 0}, {"scale", {-1, 2, 1}}, {"extras", {{"note", 1}}}}};
  g["scenes"] = {{{"nodes", {0, 1}}}};
  test::writeTextFile(dir + "/two.gltf", g.dump());

  const Scene scene = load(dir + "/two.gltf");
  ASSERT_EQ(scene.objects.size(), 2u);
  const LightmapBakeResult r = fakeResult(scene);
  ASSERT_TRUE(r.unwraps[0] && r.unwraps[1]);
  LightmapOutputSettings out;
  out.outDir = dir + "/out";
  ASSERT_TRUE(writeLightmapOutputs(dir + "/two.gltf", r, LightmapBakeSettings{}, out).ok());
  const Json o = readJson(out.outDir + "/two.gltf");
  EXPECT_EQ(o["meshes"].size(), 3u);  // the original (now unused) and one per node
  EXPECT_EQ(o["nodes"][0]["mesh"], 1);
  EXPECT_EQ(o["nodes"][1]["mesh"], 2);
  EXPECT_EQ(o["nodes"][1]["extras"]["note"], 1);  // other extras kept
  EXPECT_EQ(o["buffers"][0]["uri"], "two.bin");  // copied: the output is self-contained
  EXPECT_EQ(o["buffers"][1]["uri"], "two_lightmap_uv.bin");
  const Json m = readJson(out.outDir + "/manifest.json");
  EXPECT_TRUE(m["warnings"].empty()) << m["warnings"].dump();  // no fallback rebuild

  const Scene again = load(out.outDir + "/two.gltf");
  ASSERT_EQ(again.objects.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    const Object& a = r.scene.objects[i];
    const Object& b = again.objects[i];
    ASSERT_EQ(b.triangles.size(), a.triangles.size());
    ASSERT_EQ(b.uv1.size(), b.positions.size());
    for (size_t t = 0; t < a.triangles.size(); ++t)
      for (int k = 0; k < 3; ++k) {
        const vec3 pa = a.positions[a.triangles[t][k]], pb = b.positions[b.triangles[t][k]];
        EXPECT_NEAR(glm::length(pa - pb), 0.0f, 1e-5f) << "object " << i << " tri " << t;
        EXPECT_EQ(a.uv1[a.triangles[t][k]], b.uv1[b.triangles[t][k]]);
      }
    for (size_t t = 0; t < a.triangles.size(); ++t)  // same winding: same front side
      EXPECT_GT(glm::dot(a.faceNormal(uint32_t(t)), b.faceNormal(uint32_t(t))), 0.99f);
  }
  // COLOR_0 travelled with its vertices: the rebuilt strip's colours are the strip's.
  const Json& prim1 = o["meshes"][1]["primitives"][1];
  EXPECT_TRUE(prim1["attributes"].contains("COLOR_0"));
  EXPECT_EQ(prim1["mode"], 4);
}

TEST(GltfWriter, RefusesToOverwriteTheInput) {
  const std::string dir = test::makeTempDir("bake_out");
  fs::copy_file(cornellBox(), dir + "/cornell_box.gltf");
  fs::copy_file(test::scenesDir() + "/cornell_box.bin", dir + "/cornell_box.bin");
  const Scene scene = load(dir + "/cornell_box.gltf");
  const std::string before = readBytes(dir + "/cornell_box.gltf");
  LightmapOutputSettings out;
  out.outDir = dir;
  const Status s = writeLightmapOutputs(dir + "/cornell_box.gltf", fakeResult(scene),
                                        LightmapBakeSettings{}, out);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.error().find("overwrite"), std::string::npos) << s.error();
  EXPECT_EQ(readBytes(dir + "/cornell_box.gltf"), before);
  EXPECT_FALSE(fs::exists(dir + "/manifest.json"));
}

// ---- the CLI ------------------------------------------------------------------------------

int kiln(const std::string& args, std::string* output = nullptr) {
  std::string out;
  const int code = test::runCommand(std::string(test::kilnExe()) + " " + args, &out);
  if (output) *output = out;
  return code;
}

TEST(BakeCommand, ExitCodes) {
  const std::string dir = test::makeTempDir("bake_cli");
  std::string out;
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --samples 0", &out), 2) << out;
  EXPECT_NE(out.find("--samples"), std::string::npos) << out;
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --preset ultra", &out), 2) << out;
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --resolution -1", &out), 2) << out;
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --ldr hdr", &out), 2) << out;
  EXPECT_EQ(kiln("bake " + cornellBox(), &out), 2) << out;  // --out missing
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --max-size 4 --padding 2", &out), 2)
      << out;
  EXPECT_NE(out.find("--max-size"), std::string::npos) << out;
  EXPECT_EQ(kiln("bake " + dir + "/missing.gltf --out " + dir, &out), 1) << out;
  EXPECT_EQ(kiln("bake " + cornellBox() + " --out " + dir + " --lock-atlas " + dir + "/none.json",
                 &out),
            1)
      << out;
  EXPECT_NE(out.find("none.json"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir + "/manifest.json"));
}

TEST(BakeCommand, BakesDeterministicallyAtAnyThreadCount) {
  const std::string dir = test::makeTempDir("bake_cli");
  const std::string common = "bake " + cornellBox() + " --preset preview --resolution 8 -q";
  std::string out;
  ASSERT_EQ(kiln(common + " --threads 1 --out " + dir + "/t1", &out), 0) << out;
  ASSERT_EQ(kiln(common + " --threads 3 --out " + dir + "/t3", &out), 0) << out;
  for (const char* f : {"lightmap-0_light.exr", "manifest.json", "cornell_box.gltf"})
    EXPECT_EQ(readBytes(dir + "/t1/" + f), readBytes(dir + "/t3/" + f)) << f;
  const Json m = readJson(dir + "/t1/manifest.json");
  EXPECT_EQ(m["settings"]["preset"], "preview");
  EXPECT_EQ(m["settings"]["resolution"], 8.0);
  // A different seed changes the lightmap.
  ASSERT_EQ(kiln(common + " --seed 5 --out " + dir + "/s5", &out), 0) << out;
  EXPECT_NE(readBytes(dir + "/t1/lightmap-0_light.exr"), readBytes(dir + "/s5/lightmap-0_light.exr"));
}

TEST(BakeCommand, LockAtlasReusesThePacking) {
  const std::string dir = test::makeTempDir("bake_cli");
  std::string out;
  ASSERT_EQ(kiln("bake " + cornellBox() + " --preset preview --resolution 8 -q --out " + dir +
                     "/a",
                 &out),
            0)
      << out;
  // Another resolution on the command line contradicts the locked atlas: bad usage.
  EXPECT_EQ(kiln("bake " + cornellBox() + " --preset preview --resolution 9 -q --out " + dir +
                     "/b --lock-atlas " + dir + "/a/manifest.json",
                 &out),
            2)
      << out;
  ASSERT_EQ(kiln("bake " + cornellBox() + " --preset preview --bounces 1 -q --out " + dir +
                     "/b --lock-atlas " + dir + "/a/manifest.json",
                 &out),
            0)
      << out;
  const Json a = readJson(dir + "/a/manifest.json"), b = readJson(dir + "/b/manifest.json");
  EXPECT_EQ(a["objects"], b["objects"]);
  EXPECT_EQ(a["lightmaps"], b["lightmaps"]);
  EXPECT_EQ(b["settings"]["lockAtlas"], dir + "/a/manifest.json");
}

// Ctrl-C in the middle of a bake: exit 130, the earlier outputs byte-identical.
TEST(BakeCommand, InterruptLeavesOutputsIntact) {
  const std::string dir = test::makeTempDir("bake_cli");
  std::string out;
  ASSERT_EQ(kiln("bake " + cornellBox() + " --preset preview --resolution 8 -q --out " + dir, &out),
            0)
      << out;
  std::map<std::string, std::string> before;
  for (const auto& e : fs::directory_iterator(dir))
    before[e.path().filename().string()] = readBytes(e.path().string());
  // Long enough that SIGINT after 1.5 s lands in the light stage. --foreground: timeout
  // signals the child alone (otherwise it also signals its process group, and a second
  // SIGINT kills kiln outright, as a second Ctrl-C is meant to).
  const int code = test::runCommand(
      "timeout --foreground --preserve-status -s INT 1.5 " + std::string(test::kilnExe()) + " bake " +
          cornellBox() + " --samples 100000 --resolution 40 --threads 1 -q --out " + dir,
      &out);
  EXPECT_EQ(code, 130) << out;
  EXPECT_NE(out.find("interrupted"), std::string::npos) << out;
  std::map<std::string, std::string> after;
  for (const auto& e : fs::directory_iterator(dir))
    after[e.path().filename().string()] = readBytes(e.path().string());
  EXPECT_EQ(before, after);
}

TEST(BakeCommand, GeneratedUvSceneAndSummary) {
  const std::string dir = test::makeTempDir("bake_cli");
  std::string out;
  // two_rooms has meshes without TEXCOORD_1 (or not): either way the output glTF loads and
  // every lightmapped object of it has lightmap UVs.
  ASSERT_EQ(kiln("bake " + test::scenesDir() + "/two_rooms.gltf --preset preview --resolution 4 "
                 "--ldr dldr --out " + dir,
                 &out),
            0)
      << out;
  EXPECT_NE(out.find("rays/s"), std::string::npos) << out;
  Result<Scene> again = loadScene(dir + "/two_rooms.gltf");
  ASSERT_TRUE(again.ok()) << again.error();
  for (const Object& o : again->objects) {
    if (isLightmapped(o)) {
      EXPECT_EQ(o.uv1.size(), o.positions.size()) << o.name;
    }
  }
  EXPECT_TRUE(fs::exists(dir + "/lightmap-0_light_dldr.png"));
}

// ---- mixed lighting through the CLI (docs/mixed_lighting.md) -------------------------------

// A 4 m x 4 m floor (x in [0, 4], z in [-4, 0], y = 0, facing +y, TEXCOORD_1 = (x / 4, -z / 4))
// under a double-sided blocker at y = 0.5 covering x < 1 (not lightmapped, casts shadows), and
// seven lights: a mixed sun straight down, four mixed point lights without range (all five
// overlap: one gets no shadowmask channel), a realtime and a baked point light. Returns the
// .gltf path. `lightingMode`: the scene's extras.kiln.lightingMode, none when empty.
std::string writeMixedScene(const std::string& dir, const std::string& lightingMode) {
  const float floorPos[] = {0, 0, 0, 4, 0, 0, 4, 0, -4, 0, 0, -4};
  const float blockPos[] = {-1, 0.5f, 1, 1, 0.5f, 1, 1, 0.5f, -5, -1, 0.5f, -5};
  const float normals[] = {0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0};
  const float uv1[] = {0, 0, 1, 0, 1, 1, 0, 1};
  const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
  std::string bin;
  for (auto [data, size] : {std::pair<const void*, size_t>{floorPos, 48},
                            {blockPos, 48},
                            {normals, 48},
                            {uv1, 32},
                            {indices, 12}})
    bin.append(static_cast<const char*>(data), size);
  test::writeTextFile(dir + "/mixed.bin", bin);
  Json views = Json::array(), accessors = Json::array();
  size_t offset = 0;
  for (auto [size, comp, count, type] : {std::tuple{48, 5126, 4, "VEC3"},
                                         {48, 5126, 4, "VEC3"},
                                         {48, 5126, 4, "VEC3"},
                                         {32, 5126, 4, "VEC2"},
                                         {12, 5123, 6, "SCALAR"}}) {
    views.push_back({{"buffer", 0}, {"byteOffset", offset}, {"byteLength", size}});
    accessors.push_back({{"bufferView", views.size() - 1},
                         {"componentType", comp},
                         {"count", count},
                         {"type", type}});
    offset += size_t(size);
  }
  accessors[0]["min"] = {0, 0, -4};
  accessors[0]["max"] = {4, 0, 0};
  accessors[1]["min"] = {-1, 0.5, -5};
  accessors[1]["max"] = {1, 0.5, 1};
  auto light = [](const char* name, const char* type, double intensity, const char* mode) {
    return Json{{"name", name},
                {"type", type},
                {"intensity", intensity},
                {"extras", {{"kiln", {{"mode", mode}}}}}};
  };
  auto at = [](int lightIndex, Json translation) {
    return Json{{"name", "L" + std::to_string(lightIndex)},
                {"translation", translation},
                {"extensions", {{"KHR_lights_punctual", {{"light", lightIndex}}}}}};
  };
  Json sunNode = at(0, {0, 10, 0});
  sunNode["rotation"] = {-0.70710678, 0, 0, 0.70710678};  // -Z (its light) turned to -Y
  Json sceneExtras = Json::object();
  if (!lightingMode.empty()) sceneExtras = {{"kiln", {{"lightingMode", lightingMode}}}};
  const Json doc = {
      {"asset", {{"version", "2.0"}}},
      {"scene", 0},
      {"buffers", {{{"uri", "mixed.bin"}, {"byteLength", bin.size()}}}},
      {"bufferViews", views},
      {"accessors", accessors},
      {"materials", {{{"name", "grey"}}, {{"name", "blocker"}, {"doubleSided", true}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}, {"NORMAL", 2}, {"TEXCOORD_1", 3}}},
            {"indices", 4},
            {"material", 0}}}}},
        {{"primitives",
          {{{"attributes", {{"POSITION", 1}, {"NORMAL", 2}}}, {"indices", 4}, {"material", 1}}}}}}},
      {"extensionsUsed", {"KHR_lights_punctual"}},
      {"extensions",
       {{"KHR_lights_punctual",
         {{"lights",
           {light("sun", "directional", 3.0, "mixed"), light("lampA", "point", 20.0, "mixed"),
            light("lampB", "point", 10.0, "mixed"), light("lampC", "point", 5.0, "mixed"),
            light("lampD", "point", 2.0, "mixed"), light("fill", "point", 50.0, "realtime"),
            light("bulb", "point", 4.0, "baked")}}}}}},
      {"nodes",
       {{{"name", "floor"}, {"mesh", 0}},
        {{"name", "blocker"}, {"mesh", 1}, {"extras", {{"kiln", {{"scaleInLightmap", 0}}}}}},
        sunNode,
        at(1, {0.5, 2, -2}),
        at(2, {3.5, 2, -0.5}),
        at(3, {3.5, 2, -3.5}),
        at(4, {2, 2, -2}),
        at(5, {2, 3, -2}),
        at(6, {3, 1, -1})}},
      {"scenes", {{{"nodes", {0, 1, 2, 3, 4, 5, 6, 7, 8}}, {"extras", sceneExtras}}}}};
  const std::string path = dir + "/mixed.gltf";
  test::writeTextFile(path, doc.dump(1));
  return path;
}

// The output glTF marks each KHR_lights_punctual light: extras.kiln.baked is the manifest's
// bakedDirect (its direct light is in the lightmaps, a viewer must not add it again) and
// extras.kiln.mode its mode. Returns the marks by light name.
std::map<std::string, bool> expectBakedLightMarks(const std::string& outDir,
                                                  const std::string& gltfName) {
  const Json g = readJson(outDir + "/" + gltfName), m = readJson(outDir + "/manifest.json");
  std::map<std::string, bool> marks;
  EXPECT_FALSE(m["lights"].empty());
  for (const Json& l : m["lights"]) {
    const Json& node = g["nodes"][l["nodeIndex"].get<size_t>()];
    const size_t index = node["extensions"]["KHR_lights_punctual"]["light"];
    const Json& k = g["extensions"]["KHR_lights_punctual"]["lights"][index]["extras"]["kiln"];
    EXPECT_EQ(k["baked"], l["bakedDirect"]) << l["name"];
    EXPECT_EQ(k["mode"], l["mode"]) << l["name"];
    marks[l["name"]] = k["baked"];
  }
  return marks;
}

// kiln bake in Shadowmask mode with --directional and --shadow-color: the manifest records the
// mode, the colour and every light with the plan's channel; the shadowmask is 1 in full light
// and 0 in hard shadow; the light and direction pages hold the baked lights' direct light and
// its direction (--bounces 0: nothing else reaches the floor).
TEST(BakeCommand, ShadowmaskDirectionalEndToEnd) {
  const std::string dir = test::makeTempDir("bake_mixed");
  // The scene asks for baked-indirect; the command line wins.
  const std::string scene = writeMixedScene(dir, "baked-indirect");
  std::string out;
  ASSERT_EQ(kiln("bake " + scene + " --out " + dir +
                     "/out --lighting-mode shadowmask "
                     "--directional --shadow-color 0.1,0.25,0.5 --resolution 8 --samples 4 "
                     "--bounces 0 -q",
                 &out),
            0)
      << out;
  // The fifth overlapping mixed light is baked fully, with a warning naming it.
  EXPECT_NE(out.find("kiln: warning: light 'lampD'"), std::string::npos) << out;
  // ... and marked baked in the output glTF, like the baked light; the other mixed lights and
  // the realtime one stay realtime.
  const std::map<std::string, bool> marks = expectBakedLightMarks(dir + "/out", "mixed.gltf");
  EXPECT_EQ(marks, (std::map<std::string, bool>{{"sun", false},
                                                {"lampA", false},
                                                {"lampB", false},
                                                {"lampC", false},
                                                {"lampD", true},
                                                {"fill", false},
                                                {"bulb", true}}));

  const Json m = readJson(dir + "/out/manifest.json");
  EXPECT_EQ(m["settings"]["lightingMode"], "shadowmask");
  EXPECT_EQ(m["settings"]["directional"], true);
  ASSERT_EQ(m["settings"]["shadowColor"].size(), 3u);
  EXPECT_EQ(m["settings"]["shadowColor"][0].get<float>(), 0.1f);
  EXPECT_EQ(m["settings"]["shadowColor"][1].get<float>(), 0.25f);
  EXPECT_EQ(m["settings"]["shadowColor"][2].get<float>(), 0.5f);
  EXPECT_EQ(m["settings"]["shadowColor"][0].get<double>(), 0.1);  // written as "0.1"

  // Every light, with the plan's mode and channel: the sun first, then by intensity; lampD
  // (the weakest of five overlapping) none; realtime and baked lights none.
  Result<Scene> loaded = loadScene(scene);
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  const LightModePlan plan = planLightModes(*loaded, LightingMode::Shadowmask);
  const std::vector<std::string> names = {"sun",   "lampA", "lampB", "lampC",
                                          "lampD", "fill",  "bulb"};
  const std::vector<std::string> modes = {"mixed", "mixed",    "mixed", "mixed",
                                          "mixed", "realtime", "baked"};
  const std::vector<int> channels = {0, 1, 2, 3, -1, -1, -1};
  EXPECT_EQ(plan.shadowmaskChannel, channels);
  ASSERT_EQ(m["lights"].size(), names.size()) << m["lights"].dump();
  for (size_t l = 0; l < names.size(); ++l) {
    const Json& e = m["lights"][l];
    EXPECT_EQ(e["name"], names[l]);
    EXPECT_EQ(e["lightIndex"], loaded->lights[l].lightIndex);
    EXPECT_EQ(e["nodeIndex"], loaded->lights[l].nodeIndex);
    EXPECT_EQ(e["mode"], modes[l]) << names[l];
    EXPECT_EQ(e["shadowmaskChannel"], channels[l]) << names[l];
    EXPECT_EQ(e["bakedDirect"], bool(plan.bakeDirect[l])) << names[l];
    EXPECT_EQ(e["bakedIndirect"], bool(plan.bakeIndirect[l])) << names[l];
  }
  EXPECT_EQ(m["lights"][4]["bakedDirect"], true);  // lampD fell back to baked
  EXPECT_EQ(m["lights"][5]["bakedIndirect"], false);

  // The files, 4 channels each, the page's size.
  ASSERT_EQ(m["lightmaps"].size(), 1u);
  const Json& files = m["lightmaps"][0]["files"];
  ASSERT_EQ(files["shadowmask"], "lightmap-0_shadowmask.exr");
  ASSERT_EQ(files["direction"], "lightmap-0_direction.exr");
  Result<Image> mask = readHdrImage(dir + "/out/lightmap-0_shadowmask.exr");
  Result<Image> direction = readHdrImage(dir + "/out/lightmap-0_direction.exr");
  Result<Image> light = readHdrImage(dir + "/out/lightmap-0_light.exr");
  ASSERT_TRUE(mask.ok() && direction.ok() && light.ok());
  EXPECT_EQ(mask->channels, 4);
  EXPECT_EQ(direction->channels, 4);
  for (const Image* img : {&*mask, &*direction, &*light}) {
    EXPECT_EQ(img->width, m["lightmaps"][0]["width"]);
    EXPECT_EQ(img->height, m["lightmaps"][0]["height"]);
  }

  // Texels found through the manifest's scaleOffset; (x, z) -> uv1 = (x / 4, -z / 4). The
  // expected values are taken at the texel's centre, mapped back to the floor.
  const Json& floor = m["objects"][0];
  ASSERT_EQ(floor["node"], "floor");
  ASSERT_EQ(floor["lightmapIndex"], 0);
  const vec4 so(floor["scaleOffset"][0].get<float>(), floor["scaleOffset"][1].get<float>(),
                floor["scaleOffset"][2].get<float>(), floor["scaleOffset"][3].get<float>());
  const int w = mask->width, h = mask->height;
  struct Texel {
    int x, y;
    vec3 centre;  // world
  };
  auto texelAt = [&](float x, float z) {
    const vec2 atlas = vec2(x / 4.0f, -z / 4.0f) * vec2(so.x, so.y) + vec2(so.z, so.w);
    Texel t{int(std::floor(atlas.x * float(w))), int(std::floor(atlas.y * float(h))), vec3(0.0f)};
    const vec2 uv =
        ((vec2(float(t.x), float(t.y)) + 0.5f) / vec2(float(w), float(h)) - vec2(so.z, so.w)) /
        vec2(so.x, so.y);
    t.centre = vec3(4.0f * uv.x, 0.0f, -4.0f * uv.y);
    return t;
  };
  const vec3 lampD(2, 2, -2), bulb(3, 1, -1);
  // Irradiance on the floor (normal +y) from a point light of I candela at q, unshadowed.
  auto pointE = [](vec3 q, float candela, vec3 p) {
    const vec3 d = q - p;
    return candela * d.y / std::pow(glm::length(d), 3.0f);
  };

  // Under the blocker, straight below lampA: the sun (channel 0) and lampA (1) are blocked,
  // lampB and lampC (2, 3) pass beside the blocker's edge. Only the bulb's direct light is
  // baked here (lampD is blocked too), so the direction is the bulb's, directionality 1.
  const Texel shadow = texelAt(0.45f, -2.1f);
  const float* ms = mask->at(shadow.x, shadow.y);
  EXPECT_NEAR(ms[0], 0.0f, 1e-3f);
  EXPECT_NEAR(ms[1], 0.0f, 1e-3f);
  EXPECT_NEAR(ms[2], 1.0f, 1e-3f);
  EXPECT_NEAR(ms[3], 1.0f, 1e-3f);
  const float eShadow = pointE(bulb, 4.0f, shadow.centre);
  EXPECT_NEAR(light->rgb(shadow.x, shadow.y).g, eShadow * kInvPi, 0.01f * eShadow * kInvPi);
  const vec4 ds(direction->at(shadow.x, shadow.y)[0], direction->at(shadow.x, shadow.y)[1],
                direction->at(shadow.x, shadow.y)[2], direction->at(shadow.x, shadow.y)[3]);
  const vec3 toBulb = glm::normalize(bulb - shadow.centre);
  EXPECT_LT(glm::length(2.0f * vec3(ds) - 1.0f - toBulb), 0.01f);
  EXPECT_NEAR(ds.w, toBulb.y * 0.5f + 0.5f, 0.005f);

  // In full light: every channel 1; the light holds lampD's and the bulb's direct light and
  // the direction their irradiance-weighted mean.
  const Texel lit = texelAt(3.05f, -2.1f);
  for (int c = 0; c < 4; ++c) EXPECT_NEAR(mask->at(lit.x, lit.y)[c], 1.0f, 1e-3f) << c;
  const float eD = pointE(lampD, 2.0f, lit.centre), eB = pointE(bulb, 4.0f, lit.centre);
  EXPECT_NEAR(light->rgb(lit.x, lit.y).g, (eD + eB) * kInvPi, 0.01f * (eD + eB) * kInvPi);
  const vec3 dominant =
      (eD * glm::normalize(lampD - lit.centre) + eB * glm::normalize(bulb - lit.centre)) /
      (eD + eB);
  const float* dl = direction->at(lit.x, lit.y);
  EXPECT_LT(glm::length(2.0f * vec3(dl[0], dl[1], dl[2]) - 1.0f - dominant), 0.01f);
  EXPECT_LT(glm::length(dominant), 0.99f);  // two directions: directionality below 1
  std::printf(
      "shadow texel (%d, %d): mask %.3f %.3f %.3f %.3f; lit texel (%d, %d): light %.4f "
      "(expected %.4f), directionality %.3f\n",
      shadow.x, shadow.y, ms[0], ms[1], ms[2], ms[3], lit.x, lit.y, light->rgb(lit.x, lit.y).g,
      (eD + eB) * kInvPi, glm::length(dominant));
  fs::remove_all(dir);
}

// One light instanced by four nodes that, with the sun, overlap in Shadowmask mode: the last
// instance gets no channel and is baked fully, so it gets a copy of the light marked baked
// while the other instances' light stays realtime.
TEST(BakeCommand, LightInstancesBakedDifferentlyGetLightsOfTheirOwn) {
  const std::string dir = test::makeTempDir("bake_mixed");
  const std::string scene = writeMixedScene(dir, "shadowmask");
  Json doc = readJson(scene);
  for (size_t n = 3; n <= 6; ++n) doc["nodes"][n]["extensions"]["KHR_lights_punctual"]["light"] = 1;
  test::writeTextFile(scene, doc.dump());
  std::string out;
  ASSERT_EQ(kiln("bake " + scene + " --out " + dir +
                     "/out --resolution 4 --samples 1 --bounces 0 --ldr rgbm -q",
                 &out),
            0)
      << out;
  expectBakedLightMarks(dir + "/out", "mixed.gltf");  // each instance's light as baked
  const Json g = readJson(dir + "/out/mixed.gltf"), m = readJson(dir + "/out/manifest.json");
  const Json& lights = g["extensions"]["KHR_lights_punctual"]["lights"];
  ASSERT_EQ(lights.size(), 8u);  // the seven and one copy of lampA
  EXPECT_EQ(lights[7]["name"], "lampA");
  EXPECT_EQ(lights[7]["extras"]["kiln"]["baked"], true);
  EXPECT_EQ(lights[1]["extras"]["kiln"]["baked"], false);
  int baked = 0;
  for (const Json& l : m["lights"]) baked += l["name"] == "lampA" && l["bakedDirect"] == true;
  EXPECT_EQ(baked, 1);
  fs::remove_all(dir);
}

// The scene's extras.kiln.lightingMode applies when the command line gives none: Subtractive
// bakes every non-realtime light fully, writes no shadowmask and records the default shadow
// colour.
TEST(BakeCommand, SceneLightingModeAndDefaultShadowColor) {
  const std::string dir = test::makeTempDir("bake_mixed");
  const std::string scene = writeMixedScene(dir, "subtractive");
  std::string out;
  // --ldr rgbm: the lights make E/pi up to 3.4, which dLDR would clamp (with a warning).
  ASSERT_EQ(kiln("bake " + scene + " --out " + dir +
                     "/out --resolution 4 --samples 4 "
                     "--bounces 0 --ldr rgbm -q",
                 &out),
            0)
      << out;
  EXPECT_EQ(out.find("warning"), std::string::npos) << out;
  const Json m = readJson(dir + "/out/manifest.json");
  EXPECT_EQ(m["settings"]["lightingMode"], "subtractive");
  const LightmapBakeSettings defaults;
  for (int c = 0; c < 3; ++c)
    EXPECT_EQ(m["settings"]["shadowColor"][size_t(c)].get<float>(), defaults.shadowColor[c]);
  EXPECT_FALSE(m["lightmaps"][0]["files"].contains("shadowmask"));
  EXPECT_FALSE(m["lightmaps"][0]["files"].contains("direction"));
  ASSERT_EQ(m["lights"].size(), 7u);
  for (size_t l = 0; l < 7; ++l) {
    const bool realtime = m["lights"][l]["mode"] == "realtime";
    EXPECT_EQ(m["lights"][l]["shadowmaskChannel"], -1);
    EXPECT_EQ(m["lights"][l]["bakedDirect"], !realtime);
  }
  // Subtractive: every mixed light is marked baked in the output glTF.
  for (const auto& [name, baked] : expectBakedLightMarks(dir + "/out", "mixed.gltf"))
    EXPECT_EQ(baked, name != "fill") << name;
  fs::remove_all(dir);
}

// The scene's extras.kiln.shadowColor sets the shadow colour; --shadow-color wins over it; a
// negative component in the scene is bad input naming the element.
TEST(BakeCommand, SceneShadowColorAndCommandLineWins) {
  const std::string dir = test::makeTempDir("bake_mixed");
  const std::string scene = writeMixedScene(dir, "subtractive");
  Json doc = readJson(scene);
  doc["scenes"][0]["extras"]["kiln"]["shadowColor"] = {0.2, 0.3, 0.4};
  test::writeTextFile(scene, doc.dump());
  const std::string common = " --resolution 4 --samples 4 --bounces 0 -q";
  std::string out;
  ASSERT_EQ(kiln("bake " + scene + " --out " + dir + "/a" + common, &out), 0) << out;
  const Json a = readJson(dir + "/a/manifest.json");
  EXPECT_EQ(a["settings"]["shadowColor"][0].get<float>(), 0.2f);
  EXPECT_EQ(a["settings"]["shadowColor"][1].get<float>(), 0.3f);
  EXPECT_EQ(a["settings"]["shadowColor"][2].get<float>(), 0.4f);
  ASSERT_EQ(kiln("bake " + scene + " --out " + dir + "/b --shadow-color 0.5,0.5,0.5" + common,
                 &out),
            0)
      << out;
  const Json b = readJson(dir + "/b/manifest.json");
  for (size_t c = 0; c < 3; ++c) EXPECT_EQ(b["settings"]["shadowColor"][c].get<float>(), 0.5f);
  doc["scenes"][0]["extras"]["kiln"]["shadowColor"] = {0.2, -0.3, 0.4};
  test::writeTextFile(scene, doc.dump());
  EXPECT_EQ(kiln("bake " + scene + " --out " + dir + "/c" + common, &out), 1);
  EXPECT_NE(out.find("scenes[0].extras.kiln.shadowColor"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir + "/c/manifest.json"));
  fs::remove_all(dir);
}

TEST(BakeCommand, BadShadowColorIsBadUsage) {
  const std::string dir = test::makeTempDir("bake_mixed");
  const std::string scene = writeMixedScene(dir, "");
  for (const char* bad : {"1,2", "1,2,3,4", "-0.1,0,0", "nan,0,0", "0,inf,0", "a,b,c", "1,,2",
                          "0.5", "", "1,2,3x", "1e39,0,0"}) {
    std::string out;
    EXPECT_EQ(kiln("bake " + scene + " --out " + dir + "/out --shadow-color '" + bad + "'", &out),
              2)
        << bad << ": " << out;
    EXPECT_NE(out.find("--shadow-color"), std::string::npos) << bad << ": " << out;
  }
  EXPECT_FALSE(fs::exists(dir + "/out"));
  // Spaces around the numbers are fine.
  std::string out;
  EXPECT_EQ(kiln("bake " + scene + " --out " + dir +
                     "/ok --shadow-color ' 0.2, 0.3 ,0.4' "
                     "--resolution 2 --samples 1 --bounces 0 -q",
                 &out),
            0)
      << out;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace kiln
