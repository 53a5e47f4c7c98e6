// bake_output_test.cpp: kiln bake's outputs (lightmap_writer.h, gltf_writer.h) and the CLI:
// manifest schema and values, scaleOffset round trip through the written EXR, EXR
// orientation, the output glTF (lightmaps referenced, generated UV1 on rebuilt meshes in
// local space), atomicity (a failing or interrupted bake leaves earlier outputs
// byte-identical), determinism across thread counts, --lock-atlas, exit codes.
#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_writer.h"
#include "lightmap/uv_unwrap.h"
#include "src/gltf_loader.h"
#include "src/image.h"
#include "tests/test_util.h"

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
  LightmapBakeResult r;
  r.scene = scene;
  Result<std::vector<std::optional<UnwrapResult>>> uvs =
      generateMissingLightmapUvs(r.scene, resolution);
  EXPECT_TRUE(uvs.ok()) << uvs.error();
  r.unwraps = *uvs;
  AtlasSettings atlas;
  atlas.resolution = resolution;
  Result<AtlasLayout> layout = packAtlas(r.scene, atlas);
  EXPECT_TRUE(layout.ok()) << layout.error();
  r.layout = *layout;
  for (const AtlasPage& p : r.layout.pages) {
    LightmapPageResult page;
    page.light = Image(p.width, p.height, 3);
    page.valid.assign(size_t(p.width) * p.height, 0);
    r.pages.push_back(std::move(page));
  }
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
  EXPECT_EQ(before.size(), 3u);  // EXR, manifest, glTF

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
  EXPECT_EQ(o["buffers"][0]["uri"], "../two.bin");
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

}  // namespace
}  // namespace kiln
