// output_gltf_test.cpp: the output glTF of `kiln bake` as engines load it
// (docs/lightmap_outputs.md, "The output glTF"): the MX_lightmap extension on every
// lightmapped node, its LDR page decoding to the EXR's values with the documented formula,
// --atlas-uv, the self-contained output folder and --glb; compressed (EXT_meshopt_compression)
// inputs and --scene.
#include <gtest/gtest.h>
#include <stb_image.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numbers>
#include <set>
#include <array>
#include <vector>

#include "lightmap/atlas.h"
#include "lightmap/gltf_writer.h"
#include "lightmap/ldr_encoding.h"
#include "lightmap/lightmap_writer.h"
#include "lightmap/uv_unwrap.h"
#include "src/gltf_loader.h"
#include "src/image.h"
#include "tests/gltf_test_scenes.h"
#include "tests/test_util.h"
#include "tests/unbaked_result.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

std::string cornellBox() { return test::scenesDir() + "/cornell_box.gltf"; }

Scene load(const std::string& path) {
  Result<Scene> s = loadScene(path);
  EXPECT_TRUE(s.ok()) << path << ": " << s.error();
  return s.ok() ? *s : Scene{};
}

Json readJson(const std::string& path) { return Json::parse(test::readTextFile(path)); }

std::vector<uint8_t> readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::vector<uint8_t>((std::istreambuf_iterator<char>(in)),
                              std::istreambuf_iterator<char>());
}

// A bake result without baking: the scene's UVs and atlas, pages filled by `fill(x, y, c)`,
// every texel valid.
template <class Fill>
LightmapBakeResult fakeResult(const Scene& scene, Fill fill, float resolution = 20.0f) {
  LightmapBakeResult r = test::unbakedResult(scene, resolution);
  for (LightmapPageResult& page : r.pages) {
    for (int y = 0; y < page.light.height; ++y)
      for (int x = 0; x < page.light.width; ++x)
        for (int c = 0; c < 3; ++c) page.light.at(x, y)[c] = fill(x, y, c);
    page.valid.assign(page.valid.size(), 1);
  }
  return r;
}

LightmapBakeResult constantResult(const Scene& scene, float value = 0.5f) {
  return fakeResult(scene, [value](int, int, int) { return value; });
}

// Every lightmapped node carries MX_lightmap as the contract says: its page's texture (the
// LDR PNG the manifest lists), the manifest's scaleOffset, the encoding's intensity.
void expectLightmapExtension(const Json& g, const Json& m, const Scene& scene, LdrEncoding ldr) {
  ASSERT_TRUE(g.contains("extensionsUsed"));
  EXPECT_NE(std::find(g["extensionsUsed"].begin(), g["extensionsUsed"].end(), "MX_lightmap"),
            g["extensionsUsed"].end());
  if (g.contains("extensionsRequired")) {
    EXPECT_EQ(std::find(g["extensionsRequired"].begin(), g["extensionsRequired"].end(),
                        "MX_lightmap"),
              g["extensionsRequired"].end());
  }
  const bool rgbm = ldr == LdrEncoding::Rgbm;
  std::map<int, int> pageTexture;
  int lightmapped = 0;
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const Json& node = g["nodes"][size_t(scene.objects[i].nodeIndex)];
    const int page = m["objects"][i]["lightmapIndex"];
    if (page < 0) {
      EXPECT_FALSE(node.contains("extensions") && node["extensions"].contains("MX_lightmap"));
      continue;
    }
    ++lightmapped;
    ASSERT_TRUE(node["extensions"].contains("MX_lightmap")) << scene.objects[i].name;
    const Json& x = node["extensions"]["MX_lightmap"];
    EXPECT_EQ(x["lightMapTexture"]["texCoord"], 1);
    const int texture = x["lightMapTexture"]["index"];
    if (pageTexture.count(page)) {
      EXPECT_EQ(pageTexture[page], texture);  // one texture per page
    }
    pageTexture[page] = texture;
    const Json& tex = g["textures"][size_t(texture)];
    const Json& image = g["images"][size_t(tex["source"].get<int>())];
    if (image.contains("uri")) {
      EXPECT_EQ(image["uri"], m["lightmaps"][size_t(page)]["files"]["lightLdr"]);
      EXPECT_EQ(image["uri"], "lightmap-" + std::to_string(page) + "_light_" +
                                  (rgbm ? "rgbm" : "dldr") + ".png");
    } else {
      EXPECT_TRUE(image.contains("bufferView"));  // a .glb
    }
    EXPECT_EQ(image["mimeType"], "image/png");
    const Json& sampler = g["samplers"][size_t(tex["sampler"].get<int>())];
    EXPECT_EQ(sampler["magFilter"], 9729);
    EXPECT_EQ(sampler["minFilter"], 9729);
    EXPECT_EQ(sampler["wrapS"], 33071);
    EXPECT_EQ(sampler["wrapT"], 33071);
    const Json& so = m["objects"][i]["scaleOffset"];
    EXPECT_EQ(x["scale"], Json({so[0], so[1]}));
    EXPECT_EQ(x["offset"], Json({so[2], so[3]}));
    EXPECT_EQ(x["intensity"].get<double>(), (rgbm ? 1.0 : 2.0) * std::numbers::pi);
    EXPECT_EQ(x["extras"]["kiln"]["page"], page);
    EXPECT_EQ(x["extras"]["kiln"]["encoding"], rgbm ? "rgbm" : "dldr");
    EXPECT_EQ(x["extras"]["kiln"]["range"], rgbm ? 8 : 2);
  }
  EXPECT_GT(lightmapped, 0);
  std::set<int> textures;  // a texture of its own per page
  for (const auto& [page, texture] : pageTexture) textures.insert(texture);
  EXPECT_EQ(textures.size(), pageTexture.size());
}

TEST(OutputGltf, LightmapExtensionOnEveryLightmappedNode) {
  const Scene scene = load(cornellBox());
  const LightmapBakeResult r = constantResult(scene);
  for (LdrEncoding ldr : {LdrEncoding::None, LdrEncoding::Rgbm}) {
    LightmapOutputSettings out;
    out.outDir = test::makeTempDir("output_gltf");
    out.ldr = ldr;
    ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
    const Json g = readJson(out.outDir + "/cornell_box.gltf");
    const Json m = readJson(out.outDir + "/manifest.json");
    // No --ldr: the glTF's textures are dLDR pages.
    const LdrEncoding written = ldr == LdrEncoding::None ? LdrEncoding::Dldr : ldr;
    EXPECT_EQ(m["settings"]["ldr"], written == LdrEncoding::Rgbm ? "rgbm" : "dldr");
    expectLightmapExtension(g, m, scene, written);
    // Today's extras stay.
    EXPECT_EQ(g["extras"]["kiln"]["lightmaps"], m["lightmaps"]);
    for (size_t i = 0; i < scene.objects.size(); ++i)
      EXPECT_EQ(g["nodes"][size_t(scene.objects[i].nodeIndex)]["extras"]["kiln"]["lightmap"]
                 ["scaleOffset"],
                m["objects"][i]["scaleOffset"]);
  }
  // Without the output glTF, no LDR page unless asked for (today's behaviour).
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("output_gltf");
  out.writeGltf = false;
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out).ok());
  EXPECT_FALSE(fs::exists(out.outDir + "/lightmap-0_light_dldr.png"));
  EXPECT_EQ(readJson(out.outDir + "/manifest.json")["settings"]["ldr"], "none");
}

struct Png {
  int width = 0, height = 0, channels = 0;
  std::vector<uint8_t> bytes;
};

Png decodePng(const std::vector<uint8_t>& file) {
  Png png;
  unsigned char* data = stbi_load_from_memory(file.data(), int(file.size()), &png.width,
                                              &png.height, &png.channels, 0);
  EXPECT_NE(data, nullptr);
  if (!data) return png;
  png.bytes.assign(data, data + size_t(png.width) * png.height * png.channels);
  stbi_image_free(data);
  return png;
}

// The contract's decode (docs/lightmap_outputs.md): irradiance E = intensity x the sample,
// with the sample rgb (dLDR: sRGB-decoded; RGBM: rgb x a x 8, linear) reproduces pi x the EXR's
// E/pi within the encoding's rounding (ldr_encoding.h): dLDR's code is the nearest sRGB code,
// so E/pi lies between the decodes of code -+ 1/2; RGBM's error is at most
// 0.5 / 255 x M x 8 with M = a / 255. Texel values are exact halves, so the EXR holds them
// exactly; values above the range clamp to it.
TEST(OutputGltf, LdrPageDecodesToTheExrWithinItsQuantisation) {
  const Scene scene = load(cornellBox());
  for (LdrEncoding ldr : {LdrEncoding::Dldr, LdrEncoding::Rgbm}) {
    const bool rgbm = ldr == LdrEncoding::Rgbm;
    const float range = rgbm ? kRgbmRange : kDldrRange;
    // Values k / 512 (dLDR) or k / 256 (RGBM), k < 2048, a little past the range.
    const LightmapBakeResult r = fakeResult(scene, [&](int x, int y, int c) {
      const int k = (x * 7 + y * 131 + c * 523) % (rgbm ? 2048 + 64 : 1024 + 64);
      return std::min(float(k), 2047.0f) / (rgbm ? 256.0f : 512.0f);
    });
    LightmapOutputSettings out;
    out.outDir = test::makeTempDir("output_gltf");
    out.ldr = ldr;
    std::vector<std::string> warnings;
    ASSERT_TRUE(writeLightmapOutputs(cornellBox(), r, LightmapBakeSettings{}, out, &warnings).ok());
    const Json g = readJson(out.outDir + "/cornell_box.gltf");
    Result<Image> exr = readHdrImage(out.outDir + "/lightmap-0_light.exr");
    ASSERT_TRUE(exr.ok()) << exr.error();
    const Json& node0 = g["nodes"][size_t(scene.objects[0].nodeIndex)];
    ASSERT_EQ(node0["extensions"]["MX_lightmap"]["extras"]["kiln"]["page"], 0);
    const Json& texture = g["textures"][node0["extensions"]["MX_lightmap"]["lightMapTexture"]["index"]
                                            .get<size_t>()];
    const Png png = decodePng(readFile(
        out.outDir + "/" + g["images"][texture["source"].get<size_t>()]["uri"].get<std::string>()));
    ASSERT_EQ(png.width, exr->width);
    ASSERT_EQ(png.height, exr->height);
    ASSERT_EQ(png.channels, rgbm ? 4 : 3);
    const double intensity = node0["extensions"]["MX_lightmap"]["intensity"].get<double>();
    double worst = 0.0;
    for (int y = 0; y < png.height; ++y)
      for (int x = 0; x < png.width; ++x)
        for (int c = 0; c < 3; ++c) {
          const float v = exr->at(x, y)[c];
          ASSERT_EQ(v, r.pages[0].light.at(x, y)[c]);  // exact in half
          const double want = double(std::min(v, range));  // E/pi, clamped
          const uint8_t* s = &png.bytes[(size_t(y) * png.width + x) * size_t(png.channels)];
          if (rgbm) {
            const double sample = s[c] / 255.0 * (s[3] / 255.0) * 8.0;  // rgb x a x 8
            const double e = intensity * sample;                        // lux
            const double bound = 0.5 / 255.0 * (s[3] / 255.0) * 8.0;
            EXPECT_LE(std::abs(e / std::numbers::pi - want), bound + 1e-6) << x << "," << y;
            worst = std::max(worst, std::abs(e / std::numbers::pi - want) / bound);
          } else {
            const double e = intensity * double(srgbToLinear(s[c] / 255.0f));  // lux
            const double lo = 2.0 * srgbToLinear(std::max(0.0f, (s[c] - 0.5f) / 255.0f));
            const double hi = 2.0 * srgbToLinear(std::min(1.0f, (s[c] + 0.5f) / 255.0f));
            EXPECT_GE(want, lo - 1e-6) << x << "," << y;
            EXPECT_LE(want, hi + 1e-6) << x << "," << y;
            EXPECT_NEAR(e / std::numbers::pi, 2.0 * srgbToLinear(s[c] / 255.0f), 1e-6);
            worst = std::max(worst, std::abs(e / std::numbers::pi - want) / (hi - lo));
          }
        }
    EXPECT_GT(worst, 0.05);  // the bound is not slack: some texels come close to it
    // Values past 2 make dLDR clamp (~6% of the texels here): a warning suggests RGBM.
    bool clampWarning = false;
    for (const std::string& w : warnings) clampWarning |= w.find("--ldr rgbm") != std::string::npos;
    EXPECT_EQ(clampWarning, !rgbm);
    const Json m = readJson(out.outDir + "/manifest.json");
    bool inManifest = false;
    for (const Json& w : m["warnings"])
      inManifest |= w.get<std::string>().find("--ldr rgbm") != std::string::npos;
    EXPECT_EQ(inManifest, !rgbm);
  }
  // Within dLDR's range: no warning.
  LightmapOutputSettings out;
  out.outDir = test::makeTempDir("output_gltf");
  std::vector<std::string> warnings;
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), constantResult(scene, 1.99f),
                                   LightmapBakeSettings{}, out, &warnings)
                  .ok());
  EXPECT_TRUE(warnings.empty()) << warnings.front();
}

// Cornell box with a second node instancing the mesh of node 0 (own TEXCOORD_1): with
// --atlas-uv each node's TEXCOORD_1 is its atlas UV, the shared mesh is split, the transforms
// are identity.
std::string writeInstancedCornell(const std::string& dir) {
  Json g = readJson(cornellBox());
  Json twin = g["nodes"][0];
  twin["name"] = "floor_twin";
  twin["translation"] = {0, -3, 0};
  g["nodes"].push_back(twin);
  g["scenes"][0]["nodes"].push_back(g["nodes"].size() - 1);
  // Material 0 reads an occlusion texture with TEXCOORD_1: --atlas-uv warns about it.
  g["images"] = {{{"uri", "data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAIAAACQd1PeAAAA"
                          "DElEQVR4nGP438AAAAQBAYDFKhhdAAAAAElFTkSuQmCC"}}};
  g["textures"] = {{{"source", 0}}};
  g["materials"][0]["occlusionTexture"] = {{"index", 0}, {"texCoord", 1}};
  test::writeTextFile(dir + "/cornell_twin.gltf", g.dump());
  fs::copy_file(test::scenesDir() + "/cornell_box.bin", dir + "/cornell_box.bin");
  return dir + "/cornell_twin.gltf";
}

// A scene without TEXCOORD_1 whose one mesh two nodes instance (generated UVs).
std::string writeGeneratedUvScene(const std::string& dir) {
  const float pos[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const uint16_t idx[] = {0, 1, 2, 0, 2, 3};
  std::string bin(reinterpret_cast<const char*>(pos), sizeof pos);
  bin.append(reinterpret_cast<const char*>(idx), sizeof idx);
  test::writeTextFile(dir + "/quad.bin", bin);
  Json g = {{"asset", {{"version", "2.0"}}}, {"scene", 0}};
  g["buffers"] = {{{"uri", "quad.bin"}, {"byteLength", bin.size()}}};
  g["bufferViews"] = {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
                      {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 12}}};
  g["accessors"] = {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"},
                     {"min", {0, 0, 0}}, {"max", {1, 1, 0}}},
                    {{"bufferView", 1}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}}};
  g["meshes"] = {{{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 1}}}}}};
  g["nodes"] = {{{"name", "a"}, {"mesh", 0}}, {{"name", "b"}, {"mesh", 0}, {"translation", {3, 0, 0}}}};
  g["scenes"] = {{{"nodes", {0, 1}}}};
  test::writeTextFile(dir + "/quad.gltf", g.dump());
  return dir + "/quad.gltf";
}

TEST(OutputGltf, AtlasUvWritesTheTransformIntoTexcoord1) {
  const std::string dir = test::makeTempDir("output_gltf");
  for (const std::string& path : {writeInstancedCornell(dir), writeGeneratedUvScene(dir)}) {
    const Scene scene = load(path);
    const LightmapBakeResult r = constantResult(scene);
    LightmapOutputSettings plain, atlas, glb;
    plain.outDir = dir + "/plain";
    atlas.outDir = dir + "/atlas";
    atlas.atlasUv = true;
    glb = atlas;
    glb.outDir = dir + "/glb";
    glb.glb = true;
    ASSERT_TRUE(writeLightmapOutputs(path, r, LightmapBakeSettings{}, plain).ok());
    ASSERT_TRUE(writeLightmapOutputs(path, r, LightmapBakeSettings{}, atlas).ok());
    ASSERT_TRUE(writeLightmapOutputs(path, r, LightmapBakeSettings{}, glb).ok());
    const std::string name = fs::path(path).stem().string() + ".gltf";
    const Json m = readJson(plain.outDir + "/manifest.json");
    const bool texcoord1 = readJson(path).contains("images");
    auto warnsAboutTexcoord1 = [](const Json& manifest) {
      for (const Json& w : manifest["warnings"])
        if (w.get<std::string>().find("materials[0] samples a texture with TEXCOORD_1") !=
            std::string::npos)
          return true;
      return false;
    };
    EXPECT_FALSE(warnsAboutTexcoord1(m));
    EXPECT_EQ(warnsAboutTexcoord1(readJson(atlas.outDir + "/manifest.json")), texcoord1);
    const Json g = readJson(atlas.outDir + "/" + name);
    const Scene a = load(plain.outDir + "/" + name), b = load(atlas.outDir + "/" + name);
    // The same as one .glb (its new vertex data merged into the BIN chunk).
    const Scene c = load(glb.outDir + "/" + fs::path(path).stem().string() + ".glb");
    ASSERT_EQ(c.objects.size(), scene.objects.size());
    for (size_t i = 0; i < scene.objects.size(); ++i) {
      EXPECT_EQ(c.objects[i].positions, b.objects[i].positions);
      EXPECT_EQ(c.objects[i].uv1, b.objects[i].uv1);
      EXPECT_EQ(c.objects[i].triangles, b.objects[i].triangles);
    }
    ASSERT_EQ(a.objects.size(), scene.objects.size());
    ASSERT_EQ(b.objects.size(), scene.objects.size());
    std::set<int> meshes;
    for (size_t i = 0; i < scene.objects.size(); ++i) {
      const Json& so = m["objects"][i]["scaleOffset"];
      const vec4 t(so[0].get<float>(), so[1].get<float>(), so[2].get<float>(), so[3].get<float>());
      const Object &oa = a.objects[i], &ob = b.objects[i];
      ASSERT_EQ(oa.uv1.size(), ob.uv1.size()) << oa.name;
      ASSERT_EQ(oa.positions, ob.positions) << oa.name;
      for (size_t v = 0; v < oa.uv1.size(); ++v) {
        const vec2 want(oa.uv1[v].x * t.x + t.z, oa.uv1[v].y * t.y + t.w);
        EXPECT_NEAR(ob.uv1[v].x, want.x, 1e-6f) << oa.name << " vertex " << v;
        EXPECT_NEAR(ob.uv1[v].y, want.y, 1e-6f) << oa.name << " vertex " << v;
      }
      const Json& node = g["nodes"][size_t(scene.objects[i].nodeIndex)];
      EXPECT_EQ(node["extensions"]["MX_lightmap"]["scale"], Json({1.0, 1.0}));
      EXPECT_EQ(node["extensions"]["MX_lightmap"]["offset"], Json({0.0, 0.0}));
      EXPECT_EQ(node["extras"]["kiln"]["lightmap"]["scaleOffset"], Json({1.0, 1.0, 0.0, 0.0}));
      meshes.insert(node["mesh"].get<int>());  // every lightmapped node has a mesh of its own
    }
    EXPECT_EQ(meshes.size(), scene.objects.size()) << path;
  }
}

// A .glb input (kiln's own .glb of the Cornell box) baked again: as a .gltf its binary chunk
// becomes "<scene>.bin" beside it; as a .glb into its own folder it is refused.
TEST(OutputGltf, GlbInput) {
  const std::string dir = test::makeTempDir("output_gltf");
  const Scene scene = load(cornellBox());
  LightmapOutputSettings first;
  first.outDir = dir + "/a";
  first.glb = true;
  ASSERT_TRUE(writeLightmapOutputs(cornellBox(), constantResult(scene), LightmapBakeSettings{},
                                   first)
                  .ok());
  const std::string glbPath = dir + "/a/cornell_box.glb";
  const Scene fromGlb = load(glbPath);
  LightmapOutputSettings second;
  second.outDir = dir + "/b";
  ASSERT_TRUE(writeLightmapOutputs(glbPath, constantResult(fromGlb), LightmapBakeSettings{},
                                   second)
                  .ok());
  const Json g = readJson(dir + "/b/cornell_box.gltf");
  EXPECT_EQ(g["buffers"][0]["uri"], "cornell_box.bin");
  EXPECT_TRUE(fs::exists(dir + "/b/cornell_box.bin"));
  const Scene again = load(dir + "/b/cornell_box.gltf");
  ASSERT_EQ(again.objects.size(), scene.objects.size());
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    EXPECT_EQ(again.objects[i].positions, scene.objects[i].positions);
    EXPECT_EQ(again.objects[i].uv1, scene.objects[i].uv1);
  }
  const std::vector<uint8_t> before = readFile(glbPath);
  LightmapOutputSettings third = first;  // --glb into the input's folder
  const Status s = writeLightmapOutputs(glbPath, constantResult(fromGlb), LightmapBakeSettings{},
                                        third);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.error().find("overwrite"), std::string::npos) << s.error();
  EXPECT_EQ(readFile(glbPath), before);
}

// Every URI of a glTF resolves to a file inside `dir` (data: URIs aside).
void expectSelfContained(const std::string& gltfPath) {
  const Json g = readJson(gltfPath);
  const fs::path dir = fs::canonical(fs::path(gltfPath).parent_path());
  int files = 0;
  for (const char* key : {"buffers", "images"})
    for (const Json& e : g.value(key, Json::array())) {
      if (!e.contains("uri")) continue;
      std::string uri = e["uri"];
      if (uri.rfind("data:", 0) == 0) continue;
      std::string decoded;  // percent-decoding
      for (size_t i = 0; i < uri.size(); ++i)
        if (uri[i] == '%' && i + 2 < uri.size()) {
          decoded += char(std::stoi(uri.substr(i + 1, 2), nullptr, 16));
          i += 2;
        } else {
          decoded += uri[i];
        }
      const fs::path file = dir / decoded;
      ASSERT_TRUE(fs::is_regular_file(file)) << uri;
      const std::string canonical = fs::canonical(file).string();
      EXPECT_EQ(canonical.rfind(dir.string() + "/", 0), 0u) << uri << " -> " << canonical;
      ++files;
    }
  EXPECT_GT(files, 0);
}

// The courtyard (a PNG texture), copied to a folder that is deleted after the bake, with extra
// images: one in a subfolder with a space in its name, one outside the scene's folder whose
// name clashes with kiln's own dLDR page, one data: URI. The output loads on its own.
std::string writeCourtyardWithImages(const std::string& dir) {
  fs::create_directories(dir + "/in/tex dir");
  fs::create_directories(dir + "/elsewhere");
  for (const char* f : {"courtyard.bin", "leaves.png"})
    fs::copy_file(test::scenesDir() + "/" + f, dir + "/in/" + f);
  fs::copy_file(test::scenesDir() + "/leaves.png", dir + "/in/tex dir/leaves 2.png");
  fs::copy_file(test::scenesDir() + "/leaves.png", dir + "/elsewhere/lightmap-0_light_dldr.png");
  Json g = readJson(test::scenesDir() + "/courtyard.gltf");
  g["images"].push_back({{"uri", "tex%20dir/leaves%202.png"}});
  g["images"].push_back({{"uri", "../elsewhere/lightmap-0_light_dldr.png"}});
  g["images"].push_back({{"uri", "data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAIAAA"
                                 "CQd1PeAAAADElEQVR4nGP438AAAAQBAYDFKhhdAAAAAElFTkSuQmCC"}});
  for (size_t i = 1; i <= 3; ++i)
    g["textures"].push_back({{"source", g["images"].size() - 4 + i}});
  test::writeTextFile(dir + "/in/courtyard.gltf", g.dump(1));
  return dir + "/in/courtyard.gltf";
}

int kiln(const std::string& args, std::string* output) {
  return test::runCommand(std::string(test::kilnExe()) + " " + args, output);
}

TEST(OutputGltf, OutputFolderIsSelfContainedAndGlbLoads) {
  const std::string dir = test::makeTempDir("output_gltf");
  const std::string scene = writeCourtyardWithImages(dir);
  const Scene input = load(scene);
  const std::vector<uint8_t> leaves = readFile(dir + "/in/leaves.png");
  std::string out;
  const std::string common = "bake \"" + scene + "\" --preset preview --resolution 2 -q --out ";
  ASSERT_EQ(kiln(common + dir + "/out", &out), 0) << out;
  ASSERT_EQ(kiln(common + dir + "/glb --glb --ldr rgbm", &out), 0) << out;
  // Refuses to write over its input (exit 1, nothing written).
  EXPECT_EQ(kiln(common + dir + "/in", &out), 1) << out;
  EXPECT_NE(out.find("overwrite"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir + "/in/manifest.json"));
  fs::remove_all(dir + "/in");
  fs::remove_all(dir + "/elsewhere");

  // .gltf: every URI inside the folder; the textures copied byte for byte; the clash renamed.
  expectSelfContained(dir + "/out/courtyard.gltf");
  const Json g = readJson(dir + "/out/courtyard.gltf");
  EXPECT_EQ(g["buffers"][0]["uri"], "courtyard.bin");
  EXPECT_EQ(g["images"][0]["uri"], "leaves.png");
  EXPECT_EQ(g["images"][1]["uri"], "tex%20dir/leaves%202.png");
  EXPECT_EQ(g["images"][2]["uri"], "lightmap-0_light_dldr_2.png");  // not kiln's page
  EXPECT_EQ(g["images"][3]["uri"].get<std::string>().rfind("data:image/png", 0), 0u);
  for (const char* f : {"leaves.png", "tex dir/leaves 2.png", "lightmap-0_light_dldr_2.png"})
    EXPECT_EQ(readFile(dir + "/out/" + f), leaves) << f;
  const Scene a = load(dir + "/out/courtyard.gltf");
  for (const std::string& w : a.warnings) EXPECT_EQ(w.find("not found"), std::string::npos) << w;

  // .glb: one file, parsed back by hand: header, 4-byte aligned chunks, one buffer.
  EXPECT_FALSE(fs::exists(dir + "/glb/courtyard.bin"));
  EXPECT_FALSE(fs::exists(dir + "/glb/leaves.png"));
  const std::vector<uint8_t> file = readFile(dir + "/glb/courtyard.glb");
  auto u32 = [&](size_t at) {
    uint32_t v;
    std::memcpy(&v, file.data() + at, 4);
    return v;
  };
  ASSERT_GE(file.size(), 28u);
  EXPECT_EQ(std::memcmp(file.data(), "glTF", 4), 0);
  EXPECT_EQ(u32(4), 2u);
  EXPECT_EQ(u32(8), file.size());
  const uint32_t jsonLength = u32(12);
  EXPECT_EQ(jsonLength % 4, 0u);
  EXPECT_EQ(std::memcmp(file.data() + 16, "JSON", 4), 0);
  ASSERT_LE(20 + size_t(jsonLength) + 8, file.size());
  const size_t binAt = 20 + jsonLength;
  const uint32_t binLength = u32(binAt);
  EXPECT_EQ(binLength % 4, 0u);
  EXPECT_EQ(std::memcmp(file.data() + binAt + 4, "BIN\0", 4), 0);
  EXPECT_EQ(binAt + 8 + binLength, file.size());
  const Json j = Json::parse(file.begin() + 20, file.begin() + 20 + jsonLength);
  ASSERT_EQ(j["buffers"].size(), 1u);
  EXPECT_FALSE(j["buffers"][0].contains("uri"));
  EXPECT_LE(j["buffers"][0]["byteLength"].get<size_t>(), binLength);
  const uint8_t* bin = file.data() + binAt + 8;
  for (const Json& v : j["bufferViews"])
    EXPECT_LE(v.value("byteOffset", size_t(0)) + v["byteLength"].get<size_t>(), binLength);
  for (const Json& acc : j["accessors"]) {
    const Json& v = j["bufferViews"][acc["bufferView"].get<size_t>()];
    const size_t offset = v.value("byteOffset", size_t(0)) + acc.value("byteOffset", size_t(0));
    const int type = acc["componentType"];
    EXPECT_EQ(offset % size_t(type == 5126 || type == 5125 ? 4 : type >= 5122 ? 2 : 1), 0u);
  }
  for (size_t i = 0; i < j["images"].size(); ++i) {
    const Json& image = j["images"][i];
    EXPECT_FALSE(image.contains("uri")) << i;
    ASSERT_TRUE(image.contains("bufferView")) << i;
    EXPECT_EQ(image["mimeType"], "image/png");
    const Json& v = j["bufferViews"][image["bufferView"].get<size_t>()];
    const uint8_t* p = bin + v.value("byteOffset", size_t(0));
    const std::vector<uint8_t> bytes(p, p + v["byteLength"].get<size_t>());
    if (i < 3) {
      EXPECT_EQ(bytes, leaves) << i;
    } else if (i > 3) {  // kiln's RGBM pages, as written beside the .glb
      EXPECT_EQ(bytes, readFile(dir + "/glb/lightmap-" + std::to_string(i - 4) + "_light_rgbm.png"))
          << i;
    }
  }
  const Json m = readJson(dir + "/glb/manifest.json");
  EXPECT_EQ(m["gltf"], "courtyard.glb");
  expectLightmapExtension(j, m, input, LdrEncoding::Rgbm);

  // Both load with kiln's own loader: the same geometry and TEXCOORD_1 as the input's.
  const Scene b = load(dir + "/glb/courtyard.glb");
  EXPECT_EQ(a.warnings.size(), b.warnings.size());
  ASSERT_EQ(a.objects.size(), input.objects.size());
  ASSERT_EQ(b.objects.size(), input.objects.size());
  for (size_t i = 0; i < input.objects.size(); ++i) {
    EXPECT_EQ(a.objects[i].positions, b.objects[i].positions) << input.objects[i].name;
    EXPECT_EQ(a.objects[i].triangles, b.objects[i].triangles) << input.objects[i].name;
    EXPECT_EQ(a.objects[i].uv1, b.objects[i].uv1) << input.objects[i].name;
    EXPECT_EQ(a.objects[i].uv0, b.objects[i].uv0) << input.objects[i].name;
  }
  EXPECT_EQ(a.materials.size(), b.materials.size());
}


// ---- compressed inputs, --scene -----------------------------------------------------------------

// Every triangle of a scene as its three world positions, rotated to start at its smallest
// vertex (a rebuilt mesh may renumber vertices, never reorder a triangle's corners), sorted.
std::vector<std::array<float, 9>> triangleSet(const Scene& s) {
  std::vector<std::array<float, 9>> out;
  for (const Object& o : s.objects)
    for (const uvec3& t : o.triangles) {
      std::array<vec3, 3> c = {o.positions[t.x], o.positions[t.y], o.positions[t.z]};
      auto less = [](vec3 a, vec3 b) {
        return std::array<float, 3>{a.x, a.y, a.z} < std::array<float, 3>{b.x, b.y, b.z};
      };
      int first = 0;
      for (int k = 1; k < 3; ++k)
        if (less(c[size_t(k)], c[size_t(first)])) first = k;
      std::array<float, 9> tri;
      for (int k = 0; k < 3; ++k)
        for (int d = 0; d < 3; ++d) tri[size_t(3 * k + d)] = c[size_t((first + k) % 3)][d];
      out.push_back(tri);
    }
  std::sort(out.begin(), out.end());
  return out;
}

void expectSameTriangles(const Scene& a, const Scene& b, const std::string& what) {
  const auto x = triangleSet(a), y = triangleSet(b);
  ASSERT_EQ(x.size(), y.size()) << what;
  float worst = 0.0f;
  for (size_t t = 0; t < x.size(); ++t)
    for (size_t k = 0; k < 9; ++k) worst = std::max(worst, std::abs(x[t][k] - y[t][k]));
  EXPECT_LE(worst, 1e-6f) << what;
}

bool manifestWarns(const std::string& outDir, const std::string& needle) {
  const Json m = readJson(outDir + "/manifest.json");
  for (const Json& w : m["warnings"])
    if (w.get<std::string>().find(needle) != std::string::npos) return true;
  return false;
}

// The meshopt Cornell box (a fallback buffer without data), without TEXCOORD_1 when
// `dropUv1` (kiln generates lightmap UVs, so the writer rebuilds every mesh), as a .gltf.
std::string writeMeshoptCornell(const std::string& dir, bool dropUv1, const std::string& name) {
  const std::string src = test::writeMeshoptCornell(dir, false, false);
  Json g = readJson(src);
  EXPECT_FALSE(g["buffers"][1].contains("uri"));  // the data-less fallback
  if (dropUv1)
    for (Json& mesh : g["meshes"])
      for (Json& p : mesh["primitives"]) p["attributes"].erase("TEXCOORD_1");
  test::writeTextFile(dir + "/" + name + ".gltf", g.dump(1));
  return dir + "/" + name + ".gltf";
}

// A meshopt-compressed input (whose fallback buffer has no data) gets an output glTF with the
// input's triangles: meshes whose lightmap UVs kiln writes are rebuilt from the decoded
// vertices (never from the compressed bytes), the others stay compressed.
TEST(OutputGltf, MeshoptInputKeepsItsTriangles) {
  const std::string dir = test::makeTempDir("output_gltf_meshopt");
  for (bool dropUv1 : {false, true}) {
    const std::string path = writeMeshoptCornell(dir, dropUv1, dropUv1 ? "no_uv1" : "uv1");
    const Scene scene = load(path);
    const LightmapBakeResult r = constantResult(scene);
    for (bool atlasUv : {false, true})
      for (bool glb : {false, true}) {
        LightmapOutputSettings out;
        out.outDir = dir + "/" + fs::path(path).stem().string() + (atlasUv ? "_atlas" : "") +
                     (glb ? "_glb" : "");
        out.atlasUv = atlasUv;
        out.glb = glb;
        const std::string what = out.outDir;
        const Status st = writeLightmapOutputs(path, r, LightmapBakeSettings{}, out);
        ASSERT_TRUE(st.ok()) << what << ": " << st.error();
        const std::string file =
            out.outDir + "/" + fs::path(path).stem().string() + (glb ? ".glb" : ".gltf");
        const Scene back = load(file);
        ASSERT_EQ(back.objects.size(), scene.objects.size()) << what;
        expectSameTriangles(scene, back, what);
        const Json m = readJson(out.outDir + "/manifest.json");
        const bool rebuilt = dropUv1 || atlasUv;
        EXPECT_EQ(manifestWarns(out.outDir, "could not be traced"), rebuilt) << what;
        for (size_t i = 0; i < scene.objects.size(); ++i) {
          const Object &in = r.scene.objects[i], &o = back.objects[i];
          if (m["objects"][i]["lightmapIndex"].get<int>() < 0) continue;
          // TEXCOORD_1 is there and is the bake's (atlas-transformed with --atlas-uv), per
          // triangle corner (rebuilt meshes renumber their vertices).
          ASSERT_EQ(o.uv1.size(), o.positions.size()) << what << " " << o.name;
          ASSERT_EQ(o.triangles.size(), in.triangles.size()) << what << " " << o.name;
          const Json& so = m["objects"][i]["scaleOffset"];
          const vec4 t = atlasUv ? vec4(so[0].get<float>(), so[1].get<float>(),
                                        so[2].get<float>(), so[3].get<float>())
                                 : vec4(1, 1, 0, 0);
          float worst = 0.0f;
          for (size_t k = 0; k < in.triangles.size(); ++k)
            for (int c = 0; c < 3; ++c) {
              const vec2 want = in.uv1[in.triangles[k][c]] * vec2(t.x, t.y) + vec2(t.z, t.w);
              const vec2 got = o.uv1[o.triangles[k][c]];
              worst = std::max({worst, std::abs(got.x - want.x), std::abs(got.y - want.y)});
            }
          EXPECT_LE(worst, 1e-6f) << what << " " << o.name;
        }
        if (glb) continue;
        // The compressed data and the data-less fallback buffer pass through as they were.
        const Json g = readJson(file);
        ASSERT_GE(g["buffers"].size(), 2u) << what;
        EXPECT_FALSE(g["buffers"][1].contains("uri")) << what;
        EXPECT_TRUE(g["buffers"][1]["extensions"]["EXT_meshopt_compression"]["fallback"]) << what;
      }
  }
}

// The same through the CLI, as `kiln bake` runs it: bake, write, load back.
TEST(OutputGltf, CliBakesAMeshoptInputWithoutFallbackData) {
  const std::string dir = test::makeTempDir("output_gltf_meshopt_cli");
  const std::string path = writeMeshoptCornell(dir, true, "box");
  std::string out;
  // --min-object-texels 0: every object gets generated UVs (at 2 texels per unit the default
  // would leave the small ceiling light to probes, without UVs).
  ASSERT_EQ(kiln("bake \"" + path + "\" --preset preview --resolution 2 --min-object-texels 0 "
                 "-q --out " + dir + "/out",
                 &out),
            0)
      << out;
  const Scene back = load(dir + "/out/box.gltf");
  expectSameTriangles(load(path), back, "cli");
  for (const Object& o : back.objects) EXPECT_EQ(o.uv1.size(), o.positions.size()) << o.name;
}

// --scene 1: the output's "scene" is the baked one, and the output loads as that scene.
TEST(OutputGltf, OutputSceneIsTheBakedScene) {
  const std::string dir = test::makeTempDir("output_gltf_scene");
  Json g = readJson(writeMeshoptCornell(dir, true, "box"));
  g["scenes"].insert(g["scenes"].begin(), Json{{"name", "floor only"}, {"nodes", {0}}});
  g["scene"] = 0;  // the default is the one-node scene
  test::writeTextFile(dir + "/two.gltf", g.dump(1));
  const std::string path = dir + "/two.gltf";
  LoadOptions second;
  second.scene = 1;
  Result<Scene> s = loadScene(path, second);
  ASSERT_TRUE(s.ok()) << s.error();
  ASSERT_GT(s->objects.size(), 1u);
  for (bool glb : {false, true}) {
    LightmapOutputSettings out;
    out.outDir = dir + (glb ? "/glb" : "/gltf");
    out.glb = glb;
    const Status st = writeLightmapOutputs(path, constantResult(*s), LightmapBakeSettings{}, out);
    ASSERT_TRUE(st.ok()) << st.error();
    const std::string file = out.outDir + (glb ? "/two.glb" : "/two.gltf");
    if (!glb) {
      EXPECT_EQ(readJson(file)["scene"], 1);
    }
    const Scene back = load(file);  // its default scene
    EXPECT_EQ(back.objects.size(), s->objects.size());
    expectSameTriangles(*s, back, file);
  }
}

}  // namespace
}  // namespace kiln
