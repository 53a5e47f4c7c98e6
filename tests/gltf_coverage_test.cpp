// gltf_coverage_test.cpp: the glTF extensions and features kiln reads beyond the core
// (issue 18): KHR_mesh_quantization and EXT_meshopt_compression copies of the shipped Cornell
// box load like the original (and the quantized one bakes like it), KHR_texture_transform
// moves which texel is read, morph targets and skins load in the pose the file gives, scenes
// other than the default are chosen with LoadOptions::scene / --scene, and texture-source
// extensions (MSFT_texture_dds) in extensionsRequired are accepted only with a readable source.
#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include <stb/stb_image_write.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <algorithm>
#include <array>
#include <fstream>
#include <glm/gtc/constants.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <nlohmann/json.hpp>
#include <optional>

#ifdef KILN_HAVE_DRACO
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#endif

#include "lightmap/lightmap_baker.h"
#include "src/gltf_loader.h"
#include "tests/gltf_test_scenes.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

// Load options for glTF scene `n` (designated initializers would leave the other fields to
// -Wmissing-field-initializers).
LoadOptions sceneOption(int n) {
  LoadOptions o;
  o.scene = n;
  return o;
}

constexpr int kI8 = 5120, kU8 = 5121, kI16 = 5122, kU16 = 5123, kU32 = 5125, kF32 = 5126;

using test::append;
using test::readBytes;
using test::Shipped;
using test::writeBytes;
using test::writeMeshoptCornell;

Scene load(const std::string& path, LoadOptions options = {}) {
  auto r = loadScene(path, options);
  EXPECT_TRUE(r.ok()) << r.error();
  return r.ok() ? std::move(r).value() : Scene{};
}
std::string loadError(const std::string& path, LoadOptions options = {}) {
  auto r = loadScene(path, options);
  EXPECT_FALSE(r.ok());
  return r.ok() ? "" : r.error();
}
bool hasWarning(const Scene& s, const std::string& needle) {
  for (const auto& w : s.warnings)
    if (w.find(needle) != std::string::npos) return true;
  return false;
}

// ---- KHR_mesh_quantization ----------------------------------------------------------------------

// The Cornell box with every mesh's positions as SHORT (a child node carries the offset and the
// scale that undo the quantization), normals as normalized BYTE and both UV sets as normalized
// UNSIGNED_SHORT. *maxStep: the largest position step (metres per unit).
std::string writeQuantizedCornell(const std::string& dir, float* maxStep) {
  Shipped s;
  Json doc = s.doc;
  std::vector<uint8_t> bin;
  doc["bufferViews"] = Json::array();
  doc["accessors"] = Json::array();
  auto addAccessor = [&](const void* data, size_t bytes, int type, size_t count, const char* t,
                         bool normalized, int stride = 0) {
    Json v = {{"buffer", 0}, {"byteOffset", append(&bin, data, bytes)}, {"byteLength", bytes}};
    if (stride) v["byteStride"] = stride;
    doc["bufferViews"].push_back(v);
    Json a = {{"bufferView", doc["bufferViews"].size() - 1},
              {"componentType", type},
              {"count", count},
              {"type", t}};
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    return int(doc["accessors"].size() - 1);
  };
  *maxStep = 0.0f;
  std::vector<Json> meshTransform(doc["meshes"].size());
  for (size_t m = 0; m < doc["meshes"].size(); ++m) {
    Json& mesh = doc["meshes"][m];
    // One offset and step per mesh, over all its primitives' positions.
    vec3 lo(1e30f), hi(-1e30f);
    for (const Json& p : s.doc["meshes"][m]["primitives"]) {
      std::vector<float> pos = s.floats(p["attributes"]["POSITION"]);
      for (size_t i = 0; i < pos.size(); i += 3) {
        lo = glm::min(lo, vec3(pos[i], pos[i + 1], pos[i + 2]));
        hi = glm::max(hi, vec3(pos[i], pos[i + 1], pos[i + 2]));
      }
    }
    vec3 center = (lo + hi) * 0.5f;
    float step = std::max(maxComponent(hi - lo) * 0.5f / 32000.0f, 1e-6f);
    *maxStep = std::max(*maxStep, step);
    meshTransform[m] = {{"translation", {center.x, center.y, center.z}},
                        {"scale", {step, step, step}}};
    for (Json& p : mesh["primitives"]) {
      Json& attrs = p["attributes"];
      std::vector<float> pos = s.floats(attrs["POSITION"]);
      std::vector<int16_t> qp(pos.size() / 3 * 4, 0);  // padded to 8 bytes (vertex alignment)
      for (size_t v = 0; v < pos.size() / 3; ++v)
        for (int c = 0; c < 3; ++c)
          qp[4 * v + size_t(c)] = int16_t(std::lround((pos[3 * v + size_t(c)] - center[c]) / step));
      attrs["POSITION"] = addAccessor(qp.data(), qp.size() * 2, kI16, pos.size() / 3, "VEC3",
                                      false, 8);
      std::vector<float> nrm = s.floats(attrs["NORMAL"]);
      std::vector<int8_t> qn(nrm.size() / 3 * 4, 0);
      for (size_t v = 0; v < nrm.size() / 3; ++v)
        for (int c = 0; c < 3; ++c)
          qn[4 * v + size_t(c)] = int8_t(std::lround(nrm[3 * v + size_t(c)] * 127.0f));
      attrs["NORMAL"] = addAccessor(qn.data(), qn.size(), kI8, nrm.size() / 3, "VEC3", true, 4);
      for (const char* set : {"TEXCOORD_0", "TEXCOORD_1"}) {
        if (!attrs.contains(set)) continue;
        std::vector<float> uv = s.floats(attrs[set]);
        std::vector<uint16_t> qu(uv.size());
        for (size_t i = 0; i < uv.size(); ++i) {
          EXPECT_GE(uv[i], 0.0f);
          EXPECT_LE(uv[i], 1.0f);
          qu[i] = uint16_t(std::lround(std::clamp(uv[i], 0.0f, 1.0f) * 65535.0f));
        }
        attrs[set] = addAccessor(qu.data(), qu.size() * 2, kU16, uv.size() / 2, "VEC2", true);
      }
      std::vector<uint32_t> idx = s.indices(p["indices"]);
      p["indices"] = addAccessor(idx.data(), idx.size() * 4, kU32, idx.size(), "SCALAR", false);
    }
  }
  // Each mesh node takes the dequantization transform (the Cornell box's mesh nodes have
  // none of their own), so node indices, and with them the atlas's objects, stay the same.
  for (Json& node : doc["nodes"]) {
    if (!node.contains("mesh")) continue;
    EXPECT_FALSE(node.contains("translation") || node.contains("scale") ||
                 node.contains("rotation") || node.contains("matrix"));
    node.update(meshTransform[node["mesh"].get<size_t>()]);
  }
  doc["extensionsUsed"].push_back("KHR_mesh_quantization");
  doc["extensionsRequired"] = {"KHR_mesh_quantization"};
  doc["buffers"] = {{{"uri", "quantized.bin"}, {"byteLength", bin.size()}}};
  writeBytes(dir + "/quantized.bin", bin);
  std::string path = dir + "/quantized.gltf";
  test::writeTextFile(path, doc.dump(1));
  return path;
}

TEST(GltfCoverage, QuantizedCornellBoxLoadsTheSameGeometry) {
  std::string dir = test::makeTempDir("kiln_quant");
  float step = 0.0f;
  Scene q = load(writeQuantizedCornell(dir, &step));
  Scene o = load(test::scenesDir() + "/cornell_box.gltf");
  ASSERT_EQ(q.objects.size(), o.objects.size());
  ASSERT_GT(step, 0.0f);
  for (size_t i = 0; i < o.objects.size(); ++i) {
    const Object &a = o.objects[i], &b = q.objects[i];
    EXPECT_EQ(a.name, b.name);
    ASSERT_EQ(a.positions.size(), b.positions.size()) << a.name;
    EXPECT_EQ(a.triangles, b.triangles) << a.name;
    for (size_t v = 0; v < a.positions.size(); ++v) {
      // Rounding moves each coordinate by at most half a step (plus float rounding).
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(a.positions[v][c], b.positions[v][c], 0.5f * step + 1e-6f) << a.name;
      // A BYTE normal component is within 0.5/127 before normalisation.
      EXPECT_GT(glm::dot(a.normals[v], b.normals[v]), std::cos(3.0f * 0.5f / 127.0f)) << a.name;
      EXPECT_NEAR(a.uv1[v].x, b.uv1[v].x, 0.5f / 65535.0f + 1e-6f);
      EXPECT_NEAR(a.uv1[v].y, b.uv1[v].y, 0.5f / 65535.0f + 1e-6f);
    }
  }
}

// Mean over the texels valid in both of |a - b| (RGB), and the mean texel value of `a`.
double meanDifference(const LightmapBakeResult& a, const LightmapBakeResult& b, double* mean) {
  double diff = 0.0, sum = 0.0;
  size_t n = 0;
  EXPECT_EQ(a.pages.size(), b.pages.size());
  for (size_t p = 0; p < std::min(a.pages.size(), b.pages.size()); ++p) {
    const auto &pa = a.pages[p], &pb = b.pages[p];
    EXPECT_EQ(pa.valid.size(), pb.valid.size());
    for (size_t i = 0; i < std::min(pa.valid.size(), pb.valid.size()); ++i) {
      if (!pa.valid[i] || !pb.valid[i]) continue;
      for (int c = 0; c < 3; ++c) {
        diff += std::abs(pa.light.pixels[3 * i + size_t(c)] - pb.light.pixels[3 * i + size_t(c)]);
        sum += pa.light.pixels[3 * i + size_t(c)];
      }
      ++n;
    }
  }
  EXPECT_GT(n, 500u);
  *mean = sum / double(3 * std::max<size_t>(n, 1));
  return diff / double(3 * std::max<size_t>(n, 1));
}

TEST(GltfCoverage, QuantizedCornellBoxBakesLikeTheOriginal) {
  std::string dir = test::makeTempDir("kiln_quant_bake");
  float step = 0.0f;
  Scene q = load(writeQuantizedCornell(dir, &step));
  Scene o = load(test::scenesDir() + "/cornell_box.gltf");
  LightmapBakeSettings s;
  s.resolution = 16.0f;
  s.maxSize = 256;
  s.samplesPerTexel = 16;
  s.seed = 1;
  auto original = bakeLightmaps(o, s);
  ASSERT_TRUE(original.ok()) << original.error();
  // The original's atlas, locked (as --lock-atlas does), so that texels correspond: at 16
  // texels/m a chart size within a micrometre of a texel boundary may otherwise round either
  // way and shift the packing.
  Result<Manifest> manifest = readManifest(atlasToJson(original->layout, original->scene),
                                           "original's atlas", ManifestUse::kAtlas);
  ASSERT_TRUE(manifest.ok()) << manifest.error();
  s.lockedAtlas = LightmapBakeSettings::LockedAtlas{*manifest, "original's atlas"};
  auto quantized = bakeLightmaps(q, s);
  s.seed = 2;
  auto reseeded = bakeLightmaps(o, s);
  ASSERT_TRUE(quantized.ok() && reseeded.ok());
  // Texel coverage is not compared: the Cornell box's UV charts end exactly on texel edges,
  // where the original's float UVs overhang by ~1e-7 texel (746 texels, slivers included) and
  // the quantized ones fall just inside (580). The texels both cover are compared.
  double mean = 0.0, meanQuantized = 0.0, meanReseeded = 0.0;
  const double noise = meanDifference(*original, *reseeded, &mean);
  const double difference = meanDifference(*original, *quantized, &mean);
  meanDifference(*quantized, *original, &meanQuantized);
  meanDifference(*reseeded, *original, &meanReseeded);
  // Within noise: the quantized bake differs from the original by no more than two seeds of
  // the original differ (measured: about half as much, since the same seed repeats most
  // paths; only points that moved by micrometres take other paths)...
  EXPECT_GT(noise, 0.0);
  EXPECT_LT(difference, noise) << "noise " << noise << ", mean texel " << mean;
  // ...and no bias: the mean texel moves no more than a reseeded bake's does, plus 0.5%.
  EXPECT_LT(std::abs(meanQuantized - mean), std::abs(meanReseeded - mean) + 0.005 * mean)
      << meanQuantized << " " << mean << " " << meanReseeded;
}

TEST(GltfCoverage, QuantizationRulesAreChecked) {
  std::string dir = test::makeTempDir("kiln_quant_rules");
  // A quad whose POSITION (or NORMAL) has a component type KHR_mesh_quantization forbids.
  auto write = [&](int posType, bool posNormalized, int normalType, bool normalNormalized) {
    std::vector<uint8_t> bin;
    std::vector<uint32_t> p32 = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    std::vector<int16_t> p16(p32.begin(), p32.end());
    std::vector<int8_t> n8 = {0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0, 0, 0, 127, 0};
    std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3};
    size_t pOff = posType == kU32 ? append(&bin, p32.data(), 48) : append(&bin, p16.data(), 24);
    size_t pLen = posType == kU32 ? 48 : 24;
    size_t nOff = append(&bin, n8.data(), 16);
    size_t iOff = append(&bin, idx.data(), 12);
    Json doc = {{"asset", {{"version", "2.0"}}},
                {"buffers", {{{"uri", "q.bin"}, {"byteLength", bin.size()}}}},
                {"bufferViews",
                 {{{"buffer", 0}, {"byteOffset", pOff}, {"byteLength", pLen}},
                  {{"buffer", 0}, {"byteOffset", nOff}, {"byteLength", 16}, {"byteStride", 4}},
                  {{"buffer", 0}, {"byteOffset", iOff}, {"byteLength", 12}}}},
                {"accessors",
                 {{{"bufferView", 0}, {"componentType", posType}, {"count", 4}, {"type", "VEC3"},
                   {"normalized", posNormalized}},
                  {{"bufferView", 1}, {"componentType", normalType}, {"count", 4}, {"type", "VEC3"},
                   {"normalized", normalNormalized}},
                  {{"bufferView", 2}, {"componentType", kU16}, {"count", 6}, {"type", "SCALAR"}}}},
                {"meshes",
                 {{{"primitives",
                    {{{"attributes", {{"POSITION", 0}, {"NORMAL", 1}}}, {"indices", 2}}}}}}},
                {"nodes", {{{"mesh", 0}}}},
                {"extensionsUsed", {"KHR_mesh_quantization"}},
                {"extensionsRequired", {"KHR_mesh_quantization"}}};
    writeBytes(dir + "/q.bin", bin);
    test::writeTextFile(dir + "/q.gltf", doc.dump());
    return dir + "/q.gltf";
  };
  Scene ok = load(write(kI16, false, kI8, true));
  ASSERT_EQ(ok.objects.size(), 1u);
  EXPECT_EQ(ok.objects[0].positions[2], vec3(1, 1, 0));
  EXPECT_EQ(ok.objects[0].normals[0], vec3(0, 0, 1));
  std::string e = loadError(write(kU32, false, kI8, true));
  EXPECT_NE(e.find("accessors[0]"), std::string::npos) << e;
  EXPECT_NE(e.find("KHR_mesh_quantization"), std::string::npos) << e;
  e = loadError(write(kI16, false, kI8, false));  // normals must be normalized
  EXPECT_NE(e.find("accessors[1]"), std::string::npos) << e;
  EXPECT_NE(e.find("NORMAL"), std::string::npos) << e;
}

// ---- EXT_meshopt_compression --------------------------------------------------------------------

void expectSameGeometry(const Scene& a, const Scene& b, float posTolerance, float cosNormal) {
  ASSERT_EQ(a.objects.size(), b.objects.size());
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const Object &x = a.objects[i], &y = b.objects[i];
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.triangles, y.triangles) << x.name;
    EXPECT_EQ(x.uv0, y.uv0) << x.name;
    EXPECT_EQ(x.uv1, y.uv1) << x.name;
    ASSERT_EQ(x.positions.size(), y.positions.size()) << x.name;
    for (size_t v = 0; v < x.positions.size(); ++v) {
      if (posTolerance == 0.0f) {
        EXPECT_EQ(x.positions[v], y.positions[v]) << x.name;
        EXPECT_EQ(x.normals[v], y.normals[v]) << x.name;
      } else {
        EXPECT_LE(glm::length(x.positions[v] - y.positions[v]), posTolerance) << x.name;
        EXPECT_GE(glm::dot(x.normals[v], y.normals[v]), cosNormal) << x.name;
      }
    }
  }
}

TEST(GltfCoverage, MeshoptCornellBoxLoadsIdentically) {
  std::string dir = test::makeTempDir("kiln_meshopt");
  Scene o = load(test::scenesDir() + "/cornell_box.gltf");
  // Without filters meshopt is lossless: the same scene, bit for bit (so the same bake).
  expectSameGeometry(o, load(writeMeshoptCornell(dir, false, false)), 0.0f, 1.0f);
  expectSameGeometry(o, load(writeMeshoptCornell(dir, false, true)), 0.0f, 1.0f);
  // EXPONENTIAL with a 24-bit mantissa keeps floats to 2^-23 relative; OCTAHEDRAL at 8 bits
  // keeps directions within about 1 degree.
  expectSameGeometry(o, load(writeMeshoptCornell(dir, true, false)), 1e-6f,
                     std::cos(glm::radians(1.5f)));
}

TEST(GltfCoverage, MeshoptHostileInputIsRefused) {
  std::string dir = test::makeTempDir("kiln_meshopt_bad");
  std::string path = writeMeshoptCornell(dir, false, false);
  Json doc = Json::parse(test::readTextFile(path));
  auto rewrite = [&](auto change) {
    Json d = doc;
    change(d);
    test::writeTextFile(dir + "/bad.gltf", d.dump());
    return loadError(dir + "/bad.gltf");
  };
  // A count far beyond what its compressed bytes can hold: refused before any allocation.
  std::string e = rewrite([](Json& d) {
    d["bufferViews"][0]["byteLength"] = 12ull << 30;
    d["buffers"][1]["byteLength"] = 13ull << 30;
    d["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = 1ull << 30;
  });
  EXPECT_NE(e.find("bufferViews[0].extensions.EXT_meshopt_compression"), std::string::npos) << e;
  EXPECT_NE(e.find("compressed bytes"), std::string::npos) << e;
  // Truncated data: meshopt's decoder reports it.
  e = rewrite([](Json& d) {
    auto& ext = d["bufferViews"][0]["extensions"]["EXT_meshopt_compression"];
    ext["byteLength"] = ext["byteLength"].get<int>() / 2;
  });
  EXPECT_NE(e.find("meshopt could not decode"), std::string::npos) << e;
  // A plain bufferView on the data-less fallback buffer.
  e = rewrite([](Json& d) { d["bufferViews"][0].erase("extensions"); });
  EXPECT_NE(e.find("fallback buffer without data"), std::string::npos) << e;
  e = rewrite([](Json& d) {
    d["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["mode"] = "LINES";
  });
  EXPECT_NE(e.find("bufferViews[1].extensions.EXT_meshopt_compression.mode"), std::string::npos)
      << e;
}

// ---- KHR_draco_mesh_compression ------------------------------------------------------------------

#ifdef KILN_HAVE_DRACO
// The Cornell box with every primitive Draco-encoded (no quantization: lossless) into the one
// buffer; the primitives' accessors have no bufferView, as the extension has it.
std::string writeDracoCornell(const std::string& dir) {
  Shipped s;
  Json doc = s.doc;
  std::vector<uint8_t> bin;
  doc["bufferViews"] = Json::array();
  doc["accessors"] = Json::array();
  for (Json& mesh : doc["meshes"])
    for (Json& p : mesh["primitives"]) {
      Json& attrs = p["attributes"];
      std::vector<uint32_t> idx = s.indices(p["indices"]);
      const size_t faces = idx.size() / 3;
      draco::TriangleSoupMeshBuilder builder;
      builder.Start(int(faces));
      std::vector<std::pair<std::string, int>> ids;
      for (auto it = attrs.begin(); it != attrs.end(); ++it) {
        const std::string name = it.key();
        const std::vector<float> v = s.floats(it.value());
        const int comps = name == "POSITION" || name == "NORMAL" ? 3 : 2;
        const auto type = name == "POSITION" ? draco::GeometryAttribute::POSITION
                          : name == "NORMAL" ? draco::GeometryAttribute::NORMAL
                                             : draco::GeometryAttribute::TEX_COORD;
        const int id = builder.AddAttribute(type, int8_t(comps), draco::DT_FLOAT32);
        for (size_t f = 0; f < faces; ++f)
          builder.SetAttributeValuesForFace(id, draco::FaceIndex(uint32_t(f)),
                                            &v[comps * idx[3 * f]], &v[comps * idx[3 * f + 1]],
                                            &v[comps * idx[3 * f + 2]]);
        ids.emplace_back(name, id);
      }
      std::unique_ptr<draco::Mesh> m = builder.Finalize();
      draco::Encoder encoder;
      draco::EncoderBuffer out;
      EXPECT_TRUE(encoder.EncodeMeshToBuffer(*m, &out).ok());
      doc["bufferViews"].push_back(
          {{"buffer", 0}, {"byteOffset", append(&bin, out.data(), out.size())}, {"byteLength", out.size()}});
      Json dracoAttrs = Json::object();
      for (const auto& [name, id] : ids) {
        dracoAttrs[name] = m->attribute(id)->unique_id();
        doc["accessors"].push_back({{"componentType", kF32},
                                    {"count", m->num_points()},
                                    {"type", name == "POSITION" || name == "NORMAL" ? "VEC3" : "VEC2"}});
        attrs[name] = doc["accessors"].size() - 1;
      }
      doc["accessors"].push_back({{"componentType", kU32}, {"count", 3 * faces}, {"type", "SCALAR"}});
      p["indices"] = doc["accessors"].size() - 1;
      p["extensions"] = {{"KHR_draco_mesh_compression",
                          {{"bufferView", doc["bufferViews"].size() - 1}, {"attributes", dracoAttrs}}}};
    }
  doc["extensionsUsed"].push_back("KHR_draco_mesh_compression");
  doc["extensionsRequired"] = {"KHR_draco_mesh_compression"};
  doc["buffers"] = {{{"uri", "draco.bin"}, {"byteLength", bin.size()}}};
  writeBytes(dir + "/draco.bin", bin);
  test::writeTextFile(dir + "/draco.gltf", doc.dump(1));
  return dir + "/draco.gltf";
}

// An object's triangles as corner data (position, normal, uv1), each triangle rotated to start
// at its smallest corner (winding kept), sorted: equal for the same surface whatever the
// vertex numbering.
std::vector<std::array<float, 24>> triangleSoup(const Object& o) {
  std::vector<std::array<float, 24>> out;
  for (uvec3 t : o.triangles) {
    std::array<std::array<float, 8>, 3> c;
    for (int k = 0; k < 3; ++k) {
      uint32_t v = t[k];
      c[size_t(k)] = {o.positions[v].x, o.positions[v].y, o.positions[v].z, o.normals[v].x,
                      o.normals[v].y,   o.normals[v].z,   o.uv1[v].x,       o.uv1[v].y};
    }
    size_t first = size_t(std::min_element(c.begin(), c.end()) - c.begin());
    std::array<float, 24> tri;
    for (size_t k = 0; k < 3; ++k)
      std::copy(c[(first + k) % 3].begin(), c[(first + k) % 3].end(), tri.begin() + 8 * long(k));
    out.push_back(tri);
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(GltfCoverage, DracoCornellBoxLoadsTheSameSurfaces) {
  std::string dir = test::makeTempDir("kiln_draco");
  Scene o = load(test::scenesDir() + "/cornell_box.gltf");
  Scene d = load(writeDracoCornell(dir));
  ASSERT_EQ(o.objects.size(), d.objects.size());
  for (size_t i = 0; i < o.objects.size(); ++i) {
    EXPECT_EQ(o.objects[i].name, d.objects[i].name);
    EXPECT_EQ(triangleSoup(o.objects[i]), triangleSoup(d.objects[i])) << o.objects[i].name;
  }
  // A truncated Draco stream is an error naming the primitive, not a crash.
  Json doc = Json::parse(test::readTextFile(dir + "/draco.gltf"));
  doc["bufferViews"][0]["byteLength"] = doc["bufferViews"][0]["byteLength"].get<int>() / 3;
  test::writeTextFile(dir + "/bad.gltf", doc.dump());
  std::string e = loadError(dir + "/bad.gltf");
  EXPECT_NE(e.find("meshes[0].primitives[0].extensions.KHR_draco_mesh_compression"),
            std::string::npos) << e;
}
#endif

// ---- a small builder for the remaining cases -----------------------------------------------------

struct Builder {
  Json doc = {{"asset", {{"version", "2.0"}}},
              {"bufferViews", Json::array()},
              {"accessors", Json::array()},
              {"meshes", Json::array()},
              {"nodes", Json::array()},
              {"scenes", {{{"nodes", Json::array()}}}},
              {"scene", 0}};
  std::vector<uint8_t> bin;
  int add(const void* data, size_t bytes, int type, size_t count, const char* t) {
    doc["bufferViews"].push_back(
        {{"buffer", 0}, {"byteOffset", append(&bin, data, bytes)}, {"byteLength", bytes}});
    doc["accessors"].push_back({{"bufferView", doc["bufferViews"].size() - 1},
                                {"componentType", type},
                                {"count", count},
                                {"type", t}});
    return int(doc["accessors"].size() - 1);
  }
  int vec3s(const std::vector<vec3>& v) { return add(v.data(), v.size() * 12, kF32, v.size(), "VEC3"); }
  int node(Json n, int sceneIndex = 0) {
    doc["nodes"].push_back(n);
    int i = int(doc["nodes"].size() - 1);
    if (sceneIndex >= 0) doc["scenes"][size_t(sceneIndex)]["nodes"].push_back(i);
    return i;
  }
  // A 2 m ground quad at y = 0 facing up, with UVs (x, z) / 2 + 0.5; `extra` attributes added.
  int groundMesh(Json extraAttributes = Json::object(), Json meshExtras = Json::object()) {
    std::vector<vec3> p = {{-1, 0, -1}, {-1, 0, 1}, {1, 0, 1}, {1, 0, -1}};
    std::vector<vec2> uv = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};
    std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3};
    Json attrs = {{"POSITION", vec3s(p)},
                  {"NORMAL", vec3s(std::vector<vec3>(4, vec3(0, 1, 0)))},
                  {"TEXCOORD_0", add(uv.data(), 32, kF32, 4, "VEC2")}};
    attrs.update(extraAttributes);
    Json prim = {{"attributes", attrs}, {"indices", add(idx.data(), 12, kU16, 6, "SCALAR")}};
    Json mesh = {{"primitives", {prim}}};
    mesh.update(meshExtras);
    doc["meshes"].push_back(mesh);
    return int(doc["meshes"].size() - 1);
  }
  std::string write(const std::string& dir, const std::string& name) {
    doc["buffers"] = {{{"uri", name + ".bin"}, {"byteLength", bin.size()}}};
    writeBytes(dir + "/" + name + ".bin", bin);
    test::writeTextFile(dir + "/" + name + ".gltf", doc.dump(1));
    return dir + "/" + name + ".gltf";
  }
};

float minY(const Scene& s) {
  float y = 1e30f;
  for (const auto& o : s.objects)
    for (vec3 p : o.positions) y = std::min(y, p.y);
  return y;
}
float maxY(const Scene& s) {
  float y = -1e30f;
  for (const auto& o : s.objects)
    for (vec3 p : o.positions) y = std::max(y, p.y);
  return y;
}

// ---- morph targets and skins ---------------------------------------------------------------------

TEST(GltfCoverage, MorphedGroundLoadsAtItsWeights) {
  std::string dir = test::makeTempDir("kiln_morph");
  auto write = [&](Json meshWeights, Json nodeWeights) {
    Builder b;
    int delta = b.vec3s(std::vector<vec3>(4, vec3(0, 5, 0)));
    Json meshExtras = Json::object();
    if (!meshWeights.is_null()) meshExtras["weights"] = meshWeights;
    int mesh = b.groundMesh(Json::object(), meshExtras);
    b.doc["meshes"][size_t(mesh)]["primitives"][0]["targets"] = {{{"POSITION", delta}}};
    Json node = {{"mesh", mesh}, {"name", "ground"}};
    if (!nodeWeights.is_null()) node["weights"] = nodeWeights;
    b.node(node);
    return b.write(dir, "morph");
  };
  // The case: a weight-1 morph of +5 m loads at y = 5.
  Scene s = load(write({1.0}, nullptr));
  EXPECT_EQ(minY(s), 5.0f);
  EXPECT_EQ(maxY(s), 5.0f);
  EXPECT_EQ(s.objects[0].normals[0], vec3(0, 1, 0));
  // The node's weights win over the mesh's defaults; no weights at all = the base shape.
  EXPECT_EQ(maxY(load(write({1.0}, {0.5}))), 2.5f);
  EXPECT_EQ(maxY(load(write(nullptr, nullptr))), 0.0f);
  std::string e = loadError(write({1.0, 0.0}, nullptr));
  EXPECT_NE(e.find("meshes[0].weights"), std::string::npos) << e;
  EXPECT_NE(e.find("2 weights"), std::string::npos) << e;
}

TEST(GltfCoverage, SkinnedGroundLoadsInItsPose) {
  std::string dir = test::makeTempDir("kiln_skin");
  // inverseBind: the joint's bind-pose inverse (none = identity).
  auto write = [&](std::optional<glm::mat4> inverseBind, vec3 jointTranslation) {
    Builder b;
    std::vector<uint8_t> joints(16, 0);
    std::vector<float> weights = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
    int mesh = b.groundMesh({{"JOINTS_0", b.add(joints.data(), 16, kU8, 4, "VEC4")},
                             {"WEIGHTS_0", b.add(weights.data(), 64, kF32, 4, "VEC4")}});
    Json skin = {{"joints", {1}}};
    if (inverseBind)
      skin["inverseBindMatrices"] = b.add(glm::value_ptr(*inverseBind), 64, kF32, 1, "MAT4");
    b.doc["skins"] = {skin};
    // The skinned node's own transform is ignored (glTF 2.0, "Skins").
    b.node({{"mesh", mesh}, {"skin", 0}, {"name", "ground"}, {"translation", {0, 100, 0}}});
    b.node({{"name", "joint"},
            {"translation", {jointTranslation.x, jointTranslation.y, jointTranslation.z}}});
    return b.write(dir, "skin");
  };
  // The case: a joint at +5 m carries the ground to y = 5.
  Scene s = load(write(std::nullopt, vec3(0, 5, 0)));
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(minY(s), 5.0f);
  EXPECT_EQ(maxY(s), 5.0f);
  EXPECT_EQ(s.objects[0].normals[0], vec3(0, 1, 0));
  // Bound at y = 2 (inverse bind = translate -2), posed at 5: moved by 3.
  Scene t = load(write(glm::translate(glm::mat4(1.0f), vec3(0, -2, 0)), vec3(0, 5, 0)));
  EXPECT_EQ(maxY(t), 3.0f);
  EXPECT_EQ(minY(t), 3.0f);
}

TEST(GltfCoverage, SkinErrorsNameTheElement) {
  std::string dir = test::makeTempDir("kiln_skin_bad");
  Builder b;
  std::vector<uint8_t> joints = {3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
  std::vector<float> weights = {1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
  int mesh = b.groundMesh({{"JOINTS_0", b.add(joints.data(), 16, kU8, 4, "VEC4")},
                           {"WEIGHTS_0", b.add(weights.data(), 64, kF32, 4, "VEC4")}});
  b.doc["skins"] = {{{"joints", {1}}}};
  b.node({{"mesh", mesh}, {"skin", 0}});
  b.node({{"name", "joint"}});
  std::string e = loadError(b.write(dir, "skin"));
  EXPECT_NE(e.find("meshes[0].primitives[0]"), std::string::npos) << e;
  EXPECT_NE(e.find("JOINTS_0[0] = 3"), std::string::npos) << e;
}

// ---- KHR_texture_transform -------------------------------------------------------------------------

TEST(GltfCoverage, TextureTransformChangesTheTexelRead) {
  std::string dir = test::makeTempDir("kiln_ktt");
  // 2 x 2 texels: red (top left), green (top right), blue (bottom left), white with alpha 0
  // (bottom right); nearest filtering, so each lookup returns one texel exactly.
  std::vector<uint8_t> px = {255, 0, 0, 255, 0, 255, 0, 255, 0, 0, 255, 255, 255, 255, 255, 0};
  ASSERT_NE(stbi_write_png((dir + "/t.png").c_str(), 2, 2, 4, px.data(), 8), 0);
  auto write = [&](Json transform) {
    Builder b;
    int mesh = b.groundMesh();
    Json info = {{"index", 0}};
    if (!transform.is_null()) info["extensions"] = {{"KHR_texture_transform", transform}};
    b.doc["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", info}}},
                           {"emissiveTexture", info},
                           {"emissiveFactor", {1, 1, 1}}}};
    b.doc["meshes"][size_t(mesh)]["primitives"][0]["material"] = 0;
    b.doc["textures"] = {{{"source", 0}, {"sampler", 0}}};
    b.doc["samplers"] = {{{"magFilter", 9728}, {"minFilter", 9728}}};
    b.doc["images"] = {{{"uri", "t.png"}}};
    b.doc["extensionsUsed"] = {"KHR_texture_transform"};
    b.node({{"mesh", mesh}});
    return b.write(dir, "ktt");
  };
  // Triangle 0 is (v0, v1, v2) with UVs (0,0) (0,1) (1,1); barycentrics (0.5, 0.25) put the
  // lookup at UV (0.25, 0.75): the blue texel.
  const vec2 bary(0.5f, 0.25f);
  const vec4 red(1, 0, 0, 1), green(0, 1, 0, 1), blue(0, 0, 1, 1), clear(1, 1, 1, 0);
  EXPECT_EQ(load(write(nullptr)).baseColorAt(0, 0, bary), blue);
  // Offset (0.5, 0): UV (0.75, 0.75), the bottom-right texel, whose alpha 0 cuts it out.
  Scene s = load(write({{"offset", {0.5, 0.0}}}));
  EXPECT_EQ(s.baseColorAt(0, 0, bary), clear);
  EXPECT_EQ(s.emissionAt(0, 0, bary), vec3(1, 1, 1));
  // Scale (1, 0.5): UV (0.25, 0.375), the top-left texel.
  EXPECT_EQ(load(write({{"scale", {1.0, 0.5}}})).baseColorAt(0, 0, bary), red);
  // Rotation 90 degrees: (u, v) -> (v, -u) = (0.75, -0.25), wrapped (0.75, 0.75).
  EXPECT_EQ(load(write({{"rotation", glm::half_pi<double>()}})).baseColorAt(0, 0, bary), clear);
  // Rotation -90 degrees: (u, v) -> (-v, u) = (-0.75, 0.25), wrapped (0.25, 0.25).
  EXPECT_EQ(load(write({{"rotation", -glm::half_pi<double>()}})).baseColorAt(0, 0, bary), red);
  // The extension's texCoord overrides the textureInfo's.
  Scene t = load(write({{"texCoord", 1}, {"offset", {0.5, 0.0}}}));
  EXPECT_EQ(t.materials[0].baseColorTexCoord, 1);
  EXPECT_EQ(t.materials[0].emissiveTexCoord, 1);
  (void)green;
  std::string e = loadError(write({{"offset", {0.5}}}));
  EXPECT_NE(e.find("baseColorTexture.extensions.KHR_texture_transform.offset"), std::string::npos)
      << e;
}

// ---- scenes -------------------------------------------------------------------------------------------

std::string writeThreeScenes(const std::string& dir) {
  Builder b;
  int mesh = b.groundMesh();
  b.doc["scenes"] = {{{"nodes", Json::array()}}, {{"nodes", Json::array()}}, {{"nodes", Json::array()}}};
  b.node({{"mesh", mesh}, {"name", "first"}}, 0);
  b.node({{"mesh", mesh}, {"name", "second"}, {"translation", {0, 2, 0}}}, 1);
  b.node({{"mesh", mesh}, {"name", "third"}}, 2);
  return b.write(dir, "scenes");
}

TEST(GltfCoverage, SceneOptionChoosesTheScene) {
  std::string dir = test::makeTempDir("kiln_scenes");
  std::string path = writeThreeScenes(dir);
  Scene d = load(path);
  ASSERT_EQ(d.objects.size(), 1u);
  EXPECT_EQ(d.objects[0].name, "first");
  EXPECT_TRUE(hasWarning(d, "scene 0 of 3 loaded")) << (d.warnings.empty() ? "" : d.warnings[0]);
  EXPECT_TRUE(hasWarning(d, "--scene"));
  Scene s = load(path, sceneOption(1));
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "second");
  EXPECT_EQ(maxY(s), 2.0f);
  EXPECT_FALSE(hasWarning(s, "--scene"));
  std::string e = loadError(path, sceneOption(3));
  EXPECT_NE(e.find("scene 3"), std::string::npos) << e;
  EXPECT_NE(e.find("3 scene(s)"), std::string::npos) << e;
}

TEST(GltfCoverage, CliSceneOption) {
  std::string dir = test::makeTempDir("kiln_scenes_cli");
  std::string path = writeThreeScenes(dir);
  std::string out;
  ASSERT_EQ(test::runCommand(std::string(test::kilnExe()) + " info --json --scene 2 " + path, &out), 0)
      << out;
  EXPECT_NE(out.find("\"third\""), std::string::npos) << out;
  EXPECT_EQ(out.find("\"first\""), std::string::npos) << out;
  EXPECT_NE(test::runCommand(std::string(test::kilnExe()) + " info --scene 5 " + path, &out), 0);
  EXPECT_NE(out.find("scene 5 was asked for"), std::string::npos) << out;
}

// ---- texture-source extensions ---------------------------------------------------------------

TEST(GltfCoverage, TextureDdsRequiredNeedsACoreSource) {
  std::string dir = test::makeTempDir("kiln_dds");
  std::vector<uint8_t> px(16, 255);
  ASSERT_NE(stbi_write_png((dir + "/t.png").c_str(), 2, 2, 4, px.data(), 8), 0);
  auto write = [&](bool textures, bool source) {
    Builder b;
    int mesh = b.groundMesh();
    b.node({{"mesh", mesh}});
    b.doc["extensionsUsed"] = {"MSFT_texture_dds"};
    b.doc["extensionsRequired"] = {"MSFT_texture_dds"};
    if (textures) {
      b.doc["images"] = {{{"uri", "t.png"}}, {{"uri", "t.dds"}}};
      Json t = {{"extensions", {{"MSFT_texture_dds", {{"source", 1}}}}}};
      if (source) t["source"] = 0;
      b.doc["textures"] = {t};
      b.doc["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}};
      b.doc["meshes"][size_t(mesh)]["primitives"][0]["material"] = 0;
    }
    return b.write(dir, "dds");
  };
  // The gas station's case: required, but no texture at all.
  Scene none = load(write(false, false));
  EXPECT_EQ(none.objects.size(), 1u);
  EXPECT_TRUE(hasWarning(none, "MSFT_texture_dds is listed but no texture uses it"));
  Scene png = load(write(true, true));
  EXPECT_EQ(png.textures.size(), 1u);
  EXPECT_TRUE(hasWarning(png, "reads the 'source' image"));
  std::string e = loadError(write(true, false));
  EXPECT_NE(e.find("textures[0]"), std::string::npos) << e;
  EXPECT_NE(e.find("MSFT_texture_dds"), std::string::npos) << e;
}

}  // namespace
}  // namespace kiln
