// gltf_loader_test.cpp: the glTF loader on small files written by the tests (one test per kind
// of bad input, exact numbers for transforms, indices, normals, materials, textures, lights,
// extras), a mutation sweep that must never crash, and the project's and shared scenes.
#include "src/gltf_loader.h"

#include <gtest/gtest.h>
#include <stb/stb_image_write.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr int kU8 = 5121, kU16 = 5123, kU32 = 5125, kF32 = 5126;

// Builds a glTF document and its binary buffer in memory, then writes .gltf + .bin or .glb.
struct GltfBuilder {
  Json doc = {{"asset", {{"version", "2.0"}}}};
  std::vector<uint8_t> bin;

  GltfBuilder() {
    doc["buffers"] = Json::array();
    doc["bufferViews"] = Json::array();
    doc["accessors"] = Json::array();
    doc["meshes"] = Json::array();
    doc["nodes"] = Json::array();
    doc["scenes"] = Json::array({{{"nodes", Json::array()}}});
    doc["scene"] = 0;
  }

  int addView(const void* data, size_t bytes, int stride = 0) {
    while (bin.size() % 4) bin.push_back(0);
    size_t offset = bin.size();
    bin.insert(bin.end(), static_cast<const uint8_t*>(data),
               static_cast<const uint8_t*>(data) + bytes);
    Json v = {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}};
    if (stride) v["byteStride"] = stride;
    doc["bufferViews"].push_back(v);
    return int(doc["bufferViews"].size() - 1);
  }
  int addAccessor(int view, int componentType, size_t count, const char* type, size_t offset = 0,
                  bool normalized = false) {
    Json a = {
        {"bufferView", view}, {"componentType", componentType}, {"count", count}, {"type", type}};
    if (offset) a["byteOffset"] = offset;
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    return int(doc["accessors"].size() - 1);
  }
  int addVec3(const std::vector<vec3>& v) {
    return addAccessor(addView(v.data(), v.size() * 12), kF32, v.size(), "VEC3");
  }
  int addVec2(const std::vector<vec2>& v) {
    return addAccessor(addView(v.data(), v.size() * 8), kF32, v.size(), "VEC2");
  }
  template <typename T>
  int addIndices(const std::vector<T>& idx) {
    int type = sizeof(T) == 1 ? kU8 : sizeof(T) == 2 ? kU16 : kU32;
    return addAccessor(addView(idx.data(), idx.size() * sizeof(T)), type, idx.size(), "SCALAR");
  }
  int addMesh(const Json& primitives, const std::string& name = "") {
    Json m = {{"primitives", primitives}};
    if (!name.empty()) m["name"] = name;
    doc["meshes"].push_back(m);
    return int(doc["meshes"].size() - 1);
  }
  // Adds a node (to the scene's roots when `root`); returns its index.
  int addNode(Json node, bool root = true) {
    doc["nodes"].push_back(node);
    int i = int(doc["nodes"].size() - 1);
    if (root) doc["scenes"][0]["nodes"].push_back(i);
    return i;
  }

  std::string writeGltf(const std::string& dir, const std::string& name = "scene") {
    Json d = doc;
    if (!bin.empty()) {
      d["buffers"] = Json::array({{{"uri", name + ".bin"}, {"byteLength", bin.size()}}});
      std::ofstream(dir + "/" + name + ".bin", std::ios::binary)
          .write(reinterpret_cast<const char*>(bin.data()), std::streamsize(bin.size()));
    }
    std::string path = dir + "/" + name + ".gltf";
    test::writeTextFile(path, d.dump(1));
    return path;
  }
  // `byteLength` overrides the buffer's declared length (to test a short BIN chunk).
  std::string writeGlb(const std::string& dir, const std::string& name = "scene",
                       size_t byteLength = 0) {
    Json d = doc;
    std::vector<uint8_t> b = bin;
    while (b.size() % 4) b.push_back(0);
    if (!b.empty())
      d["buffers"] = Json::array({{{"byteLength", byteLength ? byteLength : bin.size()}}});
    std::string json = d.dump();
    while (json.size() % 4) json += ' ';
    std::vector<uint8_t> out;
    auto u32 = [&](uint32_t v) {
      for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
    };
    uint32_t total = 12 + 8 + uint32_t(json.size()) + (b.empty() ? 0 : 8 + uint32_t(b.size()));
    out.insert(out.end(), {'g', 'l', 'T', 'F'});
    u32(2);
    u32(total);
    u32(uint32_t(json.size()));
    u32(0x4E4F534A);
    out.insert(out.end(), json.begin(), json.end());
    if (!b.empty()) {
      u32(uint32_t(b.size()));
      u32(0x004E4942);
      out.insert(out.end(), b.begin(), b.end());
    }
    std::string path = dir + "/" + name + ".glb";
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(out.data()), std::streamsize(out.size()));
    return path;
  }
};

// The unit quad in the XY plane facing +Z: (0,0,0) (1,0,0) (1,1,0) (0,1,0).
const std::vector<vec3> kQuad = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
const std::vector<uint16_t> kQuadIndices = {0, 1, 2, 0, 2, 3};

// A builder holding one quad mesh (with normals) on one root node.
GltfBuilder quadScene(Json node = Json::object(), bool normals = true) {
  GltfBuilder b;
  Json prim = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}}};
  if (normals) prim["attributes"]["NORMAL"] = b.addVec3(std::vector<vec3>(4, vec3(0, 0, 1)));
  prim["indices"] = b.addIndices(kQuadIndices);
  int mesh = b.addMesh(Json::array({prim}), "quad");
  node["mesh"] = mesh;
  if (!node.contains("name")) node["name"] = "quadNode";
  b.addNode(node);
  return b;
}

vec3 faceNormal(const Object& o, size_t t) {
  uvec3 tri = o.triangles[t];
  return glm::normalize(
      glm::cross(o.positions[tri.y] - o.positions[tri.x], o.positions[tri.z] - o.positions[tri.x]));
}

void expectVec3Near(vec3 a, vec3 b, float tol = 1e-5f) {
  EXPECT_NEAR(a.x, b.x, tol);
  EXPECT_NEAR(a.y, b.y, tol);
  EXPECT_NEAR(a.z, b.z, tol);
}

bool contains(const std::vector<std::string>& list, const std::string& needle) {
  for (const auto& s : list)
    if (s.find(needle) != std::string::npos) return true;
  return false;
}

class GltfLoaderTest : public ::testing::Test {
 protected:
  void SetUp() override { dir = test::makeTempDir("kiln_gltf"); }
  void TearDown() override { fs::remove_all(dir); }

  Scene loadOk(const std::string& path, const LoadOptions& options = {}) {
    Result<Scene> r = loadScene(path, options);
    EXPECT_TRUE(r.ok()) << r.error();
    return r.ok() ? std::move(r).value() : Scene{};
  }
  // Loads `path`, expects failure, and checks the message starts with the path and names
  // every one of `elements`; then checks that `kiln info` exits with 1 and prints it.
  void expectError(const std::string& path, std::initializer_list<std::string> elements) {
    Result<Scene> r = loadScene(path);
    ASSERT_FALSE(r.ok()) << "loaded " << path << " but should have failed";
    EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
    for (const auto& e : elements) EXPECT_NE(r.error().find(e), std::string::npos) << r.error();
    // The CLI reports the same input as bad input: exit code 1, the message on stderr.
    std::string output;
    int code = test::runCommand(std::string(test::kilnExe()) + " info '" + path + "'", &output);
    EXPECT_EQ(code, 1) << output;
    EXPECT_NE(output.find("kiln: error: " + path + ": "), std::string::npos) << output;
  }
  std::string dir;
};

// ---- positive cases -------------------------------------------------------------------------

TEST_F(GltfLoaderTest, QuadLoadsWithDefaults) {
  Scene s = loadOk(quadScene().writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 1u);
  const Object& o = s.objects[0];
  EXPECT_EQ(o.name, "quadNode");
  EXPECT_EQ(o.nodeIndex, 0);
  EXPECT_EQ(o.meshIndex, 0);
  ASSERT_EQ(o.triangles.size(), 2u);
  EXPECT_EQ(o.triangles[0], uvec3(0, 1, 2));
  EXPECT_EQ(o.triangles[1], uvec3(0, 2, 3));
  EXPECT_TRUE(o.uv0.empty());
  EXPECT_TRUE(o.uv1.empty());
  EXPECT_TRUE(o.settings.isStatic);
  EXPECT_EQ(o.settings.scaleInLightmap, 1.0f);
  EXPECT_TRUE(s.warnings.empty());
  expectVec3Near(s.bounds.min, vec3(0, 0, 0));
  expectVec3Near(s.bounds.max, vec3(1, 1, 0));
  EXPECT_EQ(s.path, dir + "/scene.gltf");
}

TEST_F(GltfLoaderTest, TranslatedRotatedScaledQuadIsInWorldSpace) {
  // 90 degrees about +Y maps +X to -Z and +Z to +X.
  float h = std::sqrt(0.5f);
  Json node = {{"translation", {1, 2, 3}}, {"rotation", {0, h, 0, h}}, {"scale", {2, 2, 2}}};
  Scene s = loadOk(quadScene(node).writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 1u);
  const Object& o = s.objects[0];
  expectVec3Near(o.positions[0], vec3(1, 2, 3));
  expectVec3Near(o.positions[1], vec3(1, 2, 1));
  expectVec3Near(o.positions[2], vec3(1, 4, 1));
  expectVec3Near(o.positions[3], vec3(1, 4, 3));
  for (vec3 n : o.normals) {
    expectVec3Near(n, vec3(1, 0, 0));
    EXPECT_NEAR(glm::length(n), 1.0f, 1e-6f);
  }
  expectVec3Near(faceNormal(o, 0), vec3(1, 0, 0));
}

TEST_F(GltfLoaderTest, HierarchyComposesParentAndChildMatrices) {
  GltfBuilder b = quadScene({{"translation", {0, 0, 5}}});
  // Make the quad node a child of a parent given as a matrix (translate (10, 0, 0), scale y 3).
  b.doc["scenes"][0]["nodes"] = Json::array();
  Json parent = {{"matrix", {1, 0, 0, 0, 0, 3, 0, 0, 0, 0, 1, 0, 10, 0, 0, 1}}, {"children", {0}}};
  b.addNode(parent);
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 1u);
  expectVec3Near(s.objects[0].positions[2], vec3(11, 3, 5));
  expectVec3Near(s.objects[0].normals[0], vec3(0, 0, 1));
}

TEST_F(GltfLoaderTest, NonUniformScaleUsesInverseTransposeForNormals) {
  // A 45-degree slope y = x (normal (1, -1, 0)/sqrt2) scaled by x 2 -> slope y = x / 2,
  // whose normal is (1, -2, 0)/sqrt5.
  GltfBuilder b;
  std::vector<vec3> p = {{0, 0, 0}, {0, 0, -1}, {1, 1, -1}, {1, 1, 0}};
  vec3 n = glm::normalize(vec3(1, -1, 0));  // the front side of this winding
  Json prim = {{"attributes", {{"POSITION", b.addVec3(p)}, {"NORMAL", b.addVec3({n, n, n, n})}}},
               {"indices", b.addIndices(kQuadIndices)}};
  b.addNode({{"mesh", b.addMesh(Json::array({prim}))}, {"scale", {2, 1, 1}}});
  Scene s = loadOk(b.writeGltf(dir));
  expectVec3Near(s.objects[0].normals[0], glm::normalize(vec3(1, -2, 0)));
  expectVec3Near(faceNormal(s.objects[0], 0), glm::normalize(vec3(1, -2, 0)));
}

TEST_F(GltfLoaderTest, MirroredNodeFlipsWindingSoFrontStaysFront) {
  Scene s = loadOk(quadScene({{"scale", {-1, 1, 1}}}).writeGltf(dir));
  const Object& o = s.objects[0];
  expectVec3Near(o.positions[1], vec3(-1, 0, 0));
  // The quad still faces +Z: winding flipped (0, 2, 1) and the normal by the inverse transpose.
  EXPECT_EQ(o.triangles[0], uvec3(0, 2, 1));
  expectVec3Near(faceNormal(o, 0), vec3(0, 0, 1));
  expectVec3Near(faceNormal(o, 1), vec3(0, 0, 1));
  expectVec3Near(o.normals[0], vec3(0, 0, 1));
}

TEST_F(GltfLoaderTest, IndexTypesGiveIdenticalTriangles) {
  std::vector<std::vector<uvec3>> results;
  for (int type : {kU8, kU16, kU32}) {
    GltfBuilder b;
    Json prim = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}}};
    std::vector<uint32_t> i32(kQuadIndices.begin(), kQuadIndices.end());
    if (type == kU8) prim["indices"] = b.addIndices(std::vector<uint8_t>(i32.begin(), i32.end()));
    if (type == kU16) prim["indices"] = b.addIndices(kQuadIndices);
    if (type == kU32) prim["indices"] = b.addIndices(i32);
    b.addNode({{"mesh", b.addMesh(Json::array({prim}))}});
    Scene s = loadOk(b.writeGltf(dir, "idx" + std::to_string(type)));
    ASSERT_EQ(s.objects.size(), 1u);
    results.push_back(s.objects[0].triangles);
  }
  ASSERT_EQ(results[0].size(), 2u);
  EXPECT_EQ(results[0], results[1]);
  EXPECT_EQ(results[1], results[2]);
  EXPECT_EQ(results[0][1], uvec3(0, 2, 3));
}

TEST_F(GltfLoaderTest, NonIndexedStripAndFanBecomeTriangles) {
  GltfBuilder b;
  // Non-indexed list: 6 vertices, 2 triangles.
  std::vector<vec3> list = {kQuad[0], kQuad[1], kQuad[2], kQuad[0], kQuad[2], kQuad[3]};
  Json listPrim = {{"attributes", {{"POSITION", b.addVec3(list)}}}};
  // Strip 0 1 3 2 -> (0 1 3), (3 1 2): both CCW seen from +Z.
  Json stripPrim = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}},
                    {"indices", b.addIndices(std::vector<uint16_t>{0, 1, 3, 2})},
                    {"mode", 5}};
  // Fan 0 1 2 3 -> (1 2 0), (2 3 0).
  Json fanPrim = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}}, {"mode", 6}};
  b.addNode({{"mesh", b.addMesh(Json::array({listPrim}))}, {"name", "list"}});
  b.addNode({{"mesh", b.addMesh(Json::array({stripPrim}))}, {"name", "strip"}});
  b.addNode({{"mesh", b.addMesh(Json::array({fanPrim}))}, {"name", "fan"}});
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 3u);
  for (const Object& o : s.objects) {
    ASSERT_EQ(o.triangles.size(), 2u) << o.name;
    for (size_t t = 0; t < 2; ++t) expectVec3Near(faceNormal(o, t), vec3(0, 0, 1));
    EXPECT_NEAR(o.surfaceArea(), 1.0f, 1e-6f);
  }
  EXPECT_EQ(s.objects[1].triangles[0], uvec3(0, 1, 3));
  EXPECT_EQ(s.objects[1].triangles[1], uvec3(3, 1, 2));
  EXPECT_EQ(s.objects[2].triangles[0], uvec3(1, 2, 0));
  EXPECT_EQ(s.objects[2].triangles[1], uvec3(2, 3, 0));
}

TEST_F(GltfLoaderTest, GeneratedNormalsOfFlatQuadEqualFaceNormal) {
  float h = std::sqrt(0.5f);
  // Rotated 90 degrees about X: +Z -> -Y.
  Scene s = loadOk(quadScene({{"rotation", {h, 0, 0, h}}}, false).writeGltf(dir));
  const Object& o = s.objects[0];
  ASSERT_EQ(o.normals.size(), 4u);
  for (vec3 n : o.normals) expectVec3Near(n, vec3(0, -1, 0));
  expectVec3Near(faceNormal(o, 0), vec3(0, -1, 0));
  ASSERT_EQ(s.warnings.size(), 1u);
  EXPECT_NE(s.warnings[0].find("'quad'"), std::string::npos) << s.warnings[0];
  EXPECT_NE(s.warnings[0].find("NORMAL"), std::string::npos) << s.warnings[0];
}

TEST_F(GltfLoaderTest, GeneratedNormalsAreAngleAndAreaWeighted) {
  // Two faces of a box edge sharing vertices: the shared vertices' normal is the average of
  // +Z and +X (equal areas, equal right angles), the others keep their face normal.
  GltfBuilder b;
  std::vector<vec3> p = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {1, 0, -1}, {1, 1, -1}};
  std::vector<uint16_t> idx = {0, 1, 2, 0, 2, 3, 1, 4, 5, 1, 5, 2};
  Json prim = {{"attributes", {{"POSITION", b.addVec3(p)}}}, {"indices", b.addIndices(idx)}};
  b.addNode({{"mesh", b.addMesh(Json::array({prim}))}});
  Scene s = loadOk(b.writeGltf(dir));
  const Object& o = s.objects[0];
  expectVec3Near(o.normals[0], vec3(0, 0, 1));
  expectVec3Near(o.normals[4], vec3(1, 0, 0));
  // Vertex 1: angles 90 (+Z, one triangle) vs 45 + 45 (+X, two triangles) -> equal weights.
  expectVec3Near(o.normals[1], glm::normalize(vec3(1, 0, 1)));
}

TEST_F(GltfLoaderTest, NanVerticesAndZeroAreaTrianglesAreDroppedAndCounted) {
  GltfBuilder b;
  float nan = std::numeric_limits<float>::quiet_NaN();
  std::vector<vec3> p = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {nan, 0, 0}, {2, 0, 0}};
  // Good, uses NaN, collinear, repeated index.
  std::vector<uint16_t> idx = {0, 1, 2, 0, 1, 3, 0, 1, 4, 0, 0, 2};
  Json prim = {{"attributes", {{"POSITION", b.addVec3(p)}}}, {"indices", b.addIndices(idx)}};
  b.addNode({{"mesh", b.addMesh(Json::array({prim}), "broken")}, {"name", "thing"}});
  Scene s = loadOk(b.writeGltf(dir));
  const Object& o = s.objects[0];
  ASSERT_EQ(o.triangles.size(), 1u);
  EXPECT_EQ(o.positions.size(), 3u);  // unreferenced (and NaN) vertices are removed
  for (vec3 v : o.positions) EXPECT_TRUE(isFinite(v));
  EXPECT_TRUE(contains(s.warnings, "dropped 1 triangle(s) with NaN/Inf positions and 2 zero-area"))
      << (s.warnings.empty() ? "" : s.warnings.back());
  EXPECT_TRUE(contains(s.warnings, "'thing'"));
  EXPECT_FALSE(s.bounds.empty());
  expectVec3Near(s.bounds.max, vec3(1, 1, 0));
}

TEST_F(GltfLoaderTest, PrimitivesConcatenateWithPerTriangleMaterials) {
  GltfBuilder b;
  Json p0 = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}},
             {"indices", b.addIndices(kQuadIndices)},
             {"material", 1}};
  Json p1 = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}},
             {"indices", b.addIndices(std::vector<uint8_t>{0, 1, 2})}};
  b.doc["materials"] = {{{"name", "a"}}, {{"name", "b"}}};
  b.addNode({{"mesh", b.addMesh(Json::array({p0, p1}))}});
  Scene s = loadOk(b.writeGltf(dir));
  const Object& o = s.objects[0];
  ASSERT_EQ(o.triangles.size(), 3u);
  EXPECT_EQ(o.positions.size(), 7u);  // 4 + the 3 vertices the second primitive uses
  EXPECT_EQ(o.triangles[2], uvec3(4, 5, 6));
  ASSERT_EQ(s.materials.size(), 3u);  // a, b, glTF's default
  EXPECT_EQ(o.triangleMaterial, (std::vector<uint32_t>{1, 1, 2}));
  const Material& def = s.materials[2];
  EXPECT_EQ(def.baseColorFactor, vec4(1.0f));
  EXPECT_EQ(def.metallic, 1.0f);
  EXPECT_EQ(def.roughness, 1.0f);
  EXPECT_EQ(def.alphaMode, AlphaMode::Opaque);
  EXPECT_FALSE(def.isEmissive());
}

TEST_F(GltfLoaderTest, InterleavedNormalizedTexcoordsAndMissingUvSetsAreFilled) {
  GltfBuilder b;
  // One interleaved buffer view: position (12 bytes) + u8 normalized UV (2 bytes, padded to 4)
  // + u16 normalized UV1 (4 bytes) = stride 20.
  struct Vertex {
    float p[3];
    uint8_t uv0[2], pad[2];
    uint16_t uv1[2];
  };
  static_assert(sizeof(Vertex) == 20);
  std::vector<Vertex> v = {{{0, 0, 0}, {0, 255}, {}, {0, 65535}},
                           {{1, 0, 0}, {255, 255}, {}, {65535, 65535}},
                           {{1, 1, 0}, {255, 0}, {}, {65535, 0}},
                           {{0, 1, 0}, {0, 51}, {}, {32768, 0}}};
  int view = b.addView(v.data(), v.size() * sizeof(Vertex), 20);
  int pos = b.addAccessor(view, kF32, 4, "VEC3");
  int uv0 = b.addAccessor(view, kU8, 4, "VEC2", 12, true);
  int uv1 = b.addAccessor(view, kU16, 4, "VEC2", 16, true);
  Json p0 = {{"attributes", {{"POSITION", pos}, {"TEXCOORD_0", uv0}, {"TEXCOORD_1", uv1}}},
             {"indices", b.addIndices(kQuadIndices)}};
  Json p1 = {{"attributes",
              {{"POSITION", b.addVec3(kQuad)},
               {"TEXCOORD_0", b.addVec2(std::vector<vec2>(4, vec2(0.25f)))}}},
             {"indices", b.addIndices(kQuadIndices)}};
  b.addNode({{"mesh", b.addMesh(Json::array({p0, p1}), "uvmesh")}});
  Scene s = loadOk(b.writeGltf(dir));
  const Object& o = s.objects[0];
  ASSERT_EQ(o.uv0.size(), 8u);
  ASSERT_EQ(o.uv1.size(), 8u);
  expectVec3Near(o.positions[2], vec3(1, 1, 0));
  EXPECT_FLOAT_EQ(o.uv0[0].y, 1.0f);
  EXPECT_FLOAT_EQ(o.uv0[3].y, 0.2f);  // 51 / 255
  EXPECT_FLOAT_EQ(o.uv1[3].x, float(32768.0 / 65535.0));
  EXPECT_FLOAT_EQ(o.uv0[5].x, 0.25f);
  EXPECT_EQ(o.uv1[5], vec2(0.0f));  // the second primitive has no TEXCOORD_1: zeros
  EXPECT_TRUE(contains(s.warnings, "TEXCOORD_1 missing on some primitives"));
  EXPECT_FALSE(contains(s.warnings, "TEXCOORD_0 missing"));
}

TEST_F(GltfLoaderTest, SparseAccessorOverridesBaseValues) {
  GltfBuilder b;
  int base = b.addVec3(kQuad);
  std::vector<uint8_t> which = {2};
  std::vector<vec3> value = {vec3(5, 5, 0)};
  int iv = b.addView(which.data(), 1);
  int vv = b.addView(value.data(), 12);
  b.doc["accessors"][base]["sparse"] = {{"count", 1},
                                        {"indices", {{"bufferView", iv}, {"componentType", kU8}}},
                                        {"values", {{"bufferView", vv}}}};
  Json prim = {{"attributes", {{"POSITION", base}}}, {"indices", b.addIndices(kQuadIndices)}};
  b.addNode({{"mesh", b.addMesh(Json::array({prim}))}});
  Scene s = loadOk(b.writeGltf(dir));
  expectVec3Near(s.objects[0].positions[2], vec3(5, 5, 0));
  expectVec3Near(s.objects[0].positions[1], vec3(1, 0, 0));
}

TEST_F(GltfLoaderTest, GlbLoadsLikeGltf) {
  float h = std::sqrt(0.5f);
  GltfBuilder b = quadScene({{"rotation", {0, h, 0, h}}, {"translation", {0, 1, 0}}});
  Scene a = loadOk(b.writeGltf(dir));
  Scene g = loadOk(b.writeGlb(dir));
  ASSERT_EQ(g.objects.size(), 1u);
  EXPECT_EQ(a.objects[0].positions, g.objects[0].positions);
  EXPECT_EQ(a.objects[0].triangles, g.objects[0].triangles);
  // By magic too: a .glb under another extension is still binary.
  fs::copy_file(dir + "/scene.glb", dir + "/renamed.gltf");
  Scene r = loadOk(dir + "/renamed.gltf");
  EXPECT_EQ(r.objects[0].positions, a.objects[0].positions);
}

TEST_F(GltfLoaderTest, DefaultSceneIsChosen) {
  GltfBuilder b = quadScene();
  b.addNode({{"mesh", 0}, {"name", "second"}, {"translation", {0, 0, 7}}}, false);
  b.doc["scenes"].push_back({{"nodes", {1}}});
  b.doc["scene"] = 1;
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "second");
  // Without "scene", scenes[0]; without scenes, every root node.
  b.doc.erase("scene");
  Scene s0 = loadOk(b.writeGltf(dir, "s0"));
  ASSERT_EQ(s0.objects.size(), 1u);
  EXPECT_EQ(s0.objects[0].name, "quadNode");
  b.doc.erase("scenes");
  Scene all = loadOk(b.writeGltf(dir, "all"));
  EXPECT_EQ(all.objects.size(), 2u);
}

TEST_F(GltfLoaderTest, MaterialPropertiesAndEmissiveStrength) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["material"] = 2;
  b.doc["materials"] = {
      {{"name", "leaves"},
       {"alphaMode", "MASK"},
       {"alphaCutoff", 0.3},
       {"doubleSided", true},
       {"pbrMetallicRoughness",
        {{"baseColorFactor", {0.5, 0.25, 1, 0.75}},
         {"metallicFactor", 0.2},
         {"roughnessFactor", 0.6}}}},
      {{"name", "glass"}, {"alphaMode", "BLEND"}},
      {{"name", "lamp"},
       {"emissiveFactor", {1, 0.5, 0}},
       {"extensions", {{"KHR_materials_emissive_strength", {{"emissiveStrength", 4}}}}}}};
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.materials.size(), 3u);  // no default: every primitive has a material
  const Material& m = s.materials[0];
  EXPECT_EQ(m.name, "leaves");
  EXPECT_EQ(m.alphaMode, AlphaMode::Mask);
  EXPECT_FLOAT_EQ(m.alphaCutoff, 0.3f);
  EXPECT_TRUE(m.doubleSided);
  EXPECT_EQ(m.baseColorFactor, vec4(0.5f, 0.25f, 1.0f, 0.75f));
  EXPECT_FLOAT_EQ(m.metallic, 0.2f);
  EXPECT_FLOAT_EQ(m.roughness, 0.6f);
  EXPECT_EQ(s.materials[1].alphaMode, AlphaMode::Blend);
  EXPECT_FALSE(s.materials[1].doubleSided);
  EXPECT_FLOAT_EQ(s.materials[1].alphaCutoff, 0.5f);
  EXPECT_EQ(s.materials[2].emissiveFactor, vec3(1, 0.5f, 0));
  EXPECT_FLOAT_EQ(s.materials[2].emissiveStrength, 4.0f);
  EXPECT_TRUE(s.materials[2].isEmissive());
  EXPECT_FALSE(s.materials[0].isEmissive());
  EXPECT_EQ(s.objects[0].triangleMaterial, (std::vector<uint32_t>{2, 2}));
}

// Writes a 2x2 RGBA PNG (all pixels `rgba`) and returns its file name.
std::string writePng(const std::string& dir, const std::string& name, std::array<uint8_t, 4> rgba) {
  std::vector<uint8_t> px(16);
  for (size_t i = 0; i < px.size(); ++i) px[i] = rgba[i % 4];
  EXPECT_NE(stbi_write_png((dir + "/" + name).c_str(), 2, 2, 4, px.data(), 8), 0);
  return name;
}

TEST_F(GltfLoaderTest, BaseColorTextureIsDecodedFromSrgb) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["material"] = 0;
  b.doc["materials"] = {
      {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}, {"texCoord", 1}}}}},
       {"emissiveTexture", {{"index", 0}}},
       {"emissiveFactor", {1, 1, 1}}}};
  b.doc["textures"] = {{{"source", 0}, {"sampler", 0}}};
  b.doc["samplers"] = {{{"wrapS", 33071}, {"wrapT", 33648}, {"magFilter", 9728}}};
  b.doc["images"] = {{{"uri", writePng(dir, "albedo.png", {188, 188, 255, 128})}}};
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.textures.size(), 1u);  // shared by base colour and emission
  const Texture& t = s.textures[0];
  EXPECT_EQ(t.image.width, 2);
  EXPECT_EQ(t.image.height, 2);
  ASSERT_EQ(t.image.channels, 4);
  EXPECT_NEAR(t.image.pixels[0], 0.5029f, 1e-4f);  // sRGB 188/255 -> linear
  EXPECT_NEAR(t.image.pixels[2], 1.0f, 1e-6f);
  EXPECT_NEAR(t.image.pixels[3], 128.0f / 255.0f, 1e-6f);  // alpha stays linear
  EXPECT_NEAR(t.average.x, 0.5029f, 1e-4f);
  EXPECT_NEAR(t.average.w, 128.0f / 255.0f, 1e-6f);
  EXPECT_EQ(t.sampler.wrapS, Wrap::ClampToEdge);
  EXPECT_EQ(t.sampler.wrapT, Wrap::MirroredRepeat);
  EXPECT_TRUE(t.sampler.nearest);
  EXPECT_NE(t.name.find("albedo.png"), std::string::npos);
  EXPECT_EQ(s.materials[0].baseColorTexture, 0);
  EXPECT_EQ(s.materials[0].baseColorTexCoord, 1);
  EXPECT_EQ(s.materials[0].emissiveTexture, 0);
  // With textures off, the factors are used and nothing is decoded.
  LoadOptions noTextures;
  noTextures.loadTextures = false;
  Scene f = loadOk(dir + "/scene.gltf", noTextures);
  EXPECT_TRUE(f.textures.empty());
  EXPECT_EQ(f.materials[0].baseColorTexture, -1);
}

TEST_F(GltfLoaderTest, MissingImageWarnsAndFallsBackToFactor) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["material"] = 0;
  b.doc["materials"] = {
      {{"pbrMetallicRoughness",
        {{"baseColorTexture", {{"index", 1}}}, {"baseColorFactor", {0.5, 0.5, 0.5, 1}}}}}};
  b.doc["textures"] = {{{"source", 0}}, {{"source", 1}}};
  b.doc["images"] = {{{"uri", "bark.png"}}, {{"uri", "leaf.png"}}};
  Scene s = loadOk(b.writeGltf(dir));
  EXPECT_EQ(s.materials[0].baseColorTexture, -1);
  EXPECT_EQ(s.materials[0].baseColorFactor, vec4(0.5f, 0.5f, 0.5f, 1.0f));
  EXPECT_TRUE(s.textures.empty());
  EXPECT_TRUE(contains(s.warnings, "textures[1]: image 'leaf.png' not found, using the factor"))
      << (s.warnings.empty() ? "no warnings" : s.warnings[0]);
  EXPECT_EQ(s.warnings.size(), 1u);  // the unused texture is not decoded or reported
}

TEST_F(GltfLoaderTest, UndecodableImageWarns) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["material"] = 0;
  b.doc["materials"] = {{{"emissiveTexture", {{"index", 0}}}}};
  b.doc["textures"] = {{{"source", 0}}};
  b.doc["images"] = {{{"uri", "junk.png"}}};
  test::writeTextFile(dir + "/junk.png", "this is not a png");
  Scene s = loadOk(b.writeGltf(dir));
  EXPECT_EQ(s.materials[0].emissiveTexture, -1);
  EXPECT_TRUE(contains(s.warnings, "textures[0]: image 'junk.png' could not be decoded"));
}

TEST_F(GltfLoaderTest, PunctualLights) {
  GltfBuilder b = quadScene();
  float h = std::sqrt(0.5f);
  b.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  b.doc["extensions"]["KHR_lights_punctual"]["lights"] = {
      {{"type", "spot"},
       {"name", "torch"},
       {"intensity", 40},
       {"color", {1, 0.5, 0.25}},
       {"spot", Json::object()},
       {"extras",
        {{"kiln",
          {{"mode", "mixed"},
           {"shadowRadius", 0.1},
           {"shadowSamples", 8},
           {"bounceIntensity", 2}}}}}},
      {{"type", "directional"},
       {"intensity", 3},
       {"extras", {{"kiln", {{"shadowAngle", 2.5}, {"mode", "realtime"}}}}}},
      {{"type", "point"}, {"range", 5}, {"spot", {{"outerConeAngle", 0.1}}}}};
  // Rotation 90 degrees about +X turns the node's -Z into +Y.
  auto lightNode = [](int light, Json extra) {
    extra["extensions"] = {{"KHR_lights_punctual", {{"light", light}}}};
    return extra;
  };
  b.addNode(lightNode(0, {{"translation", {1, 2, 3}}, {"rotation", {h, 0, 0, h}}}));
  b.addNode(lightNode(1, Json::object()));
  int parent = b.addNode({{"translation", {0, 10, 0}}, {"children", {4}}});
  b.addNode(lightNode(2, {{"translation", {1, 0, 0}}}), false);
  EXPECT_EQ(parent, 3);
  b.doc["extensions"]["KHR_lights_punctual"]["lights"][2].erase("spot");
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.lights.size(), 3u);
  const Light& spot = s.lights[0];
  EXPECT_EQ(spot.name, "torch");
  EXPECT_EQ(spot.type, LightType::Spot);
  EXPECT_EQ(spot.lightIndex, 0);
  EXPECT_EQ(spot.nodeIndex, 1);
  EXPECT_FLOAT_EQ(spot.intensity, 40.0f);
  EXPECT_EQ(spot.color, vec3(1, 0.5f, 0.25f));
  EXPECT_EQ(spot.innerConeAngle, 0.0f);
  EXPECT_NEAR(spot.outerConeAngle, kPi / 4, 1e-6f);
  expectVec3Near(spot.position, vec3(1, 2, 3));
  expectVec3Near(spot.direction, vec3(0, 1, 0));
  EXPECT_EQ(spot.mode, LightMode::Mixed);
  EXPECT_FLOAT_EQ(spot.shadowRadius, 0.1f);
  EXPECT_EQ(spot.shadowSamples, 8);
  EXPECT_FLOAT_EQ(spot.bounceIntensity, 2.0f);
  const Light& sun = s.lights[1];
  EXPECT_EQ(sun.type, LightType::Directional);
  EXPECT_EQ(sun.name, "lights[1]");
  expectVec3Near(sun.direction, vec3(0, 0, -1));
  EXPECT_FLOAT_EQ(sun.shadowAngle, 2.5f);
  EXPECT_EQ(sun.mode, LightMode::Realtime);
  const Light& point = s.lights[2];
  EXPECT_EQ(point.type, LightType::Point);
  EXPECT_FLOAT_EQ(point.range, 5.0f);
  expectVec3Near(point.position, vec3(1, 10, 0));
  EXPECT_EQ(point.mode, LightMode::Baked);
  EXPECT_EQ(point.shadowSamples, 1);
}

TEST_F(GltfLoaderTest, NodeExtrasAndProbeGroups) {
  GltfBuilder b = quadScene({{"extras",
                              {{"kiln",
                                {{"static", false},
                                 {"scaleInLightmap", 0.5},
                                 {"receiveGI", "probes"},
                                 {"lppv", true}}}}}});
  b.addNode({{"name", "probes"},
             {"translation", {10, 0, 0}},
             {"scale", {2, 2, 2}},
             {"extras", {{"kiln", {{"probes", {{0, 0, 0}, {1, 1, 1}}}}}}}});
  b.addNode({{"name", "defaults"}, {"mesh", 0}, {"extras", {{"author", "someone"}}}});
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.objects.size(), 2u);
  const ObjectSettings& o = s.objects[0].settings;
  EXPECT_FALSE(o.isStatic);
  EXPECT_FLOAT_EQ(o.scaleInLightmap, 0.5f);
  EXPECT_EQ(o.receiveGI, ReceiveGI::Probes);
  EXPECT_TRUE(o.lppv);
  EXPECT_TRUE(s.objects[1].settings.isStatic);
  EXPECT_EQ(s.objects[1].settings.receiveGI, ReceiveGI::Lightmaps);
  ASSERT_EQ(s.probeGroups.size(), 1u);
  EXPECT_EQ(s.probeGroups[0].name, "probes");
  EXPECT_EQ(s.probeGroups[0].nodeIndex, 1);
  ASSERT_EQ(s.probeGroups[0].positions.size(), 2u);
  expectVec3Near(s.probeGroups[0].positions[0], vec3(10, 0, 0));
  expectVec3Near(s.probeGroups[0].positions[1], vec3(12, 2, 2));
}

TEST_F(GltfLoaderTest, UnknownExtrasKeyWarns) {
  GltfBuilder b = quadScene({{"extras", {{"kiln", {{"scaleInLightmpa", 2}}}}}});
  Scene s = loadOk(b.writeGltf(dir));
  EXPECT_TRUE(contains(s.warnings, "nodes[0].extras.kiln: unknown key 'scaleInLightmpa'"));
}

TEST_F(GltfLoaderTest, SceneExtrasBecomeSettingsAndSky) {
  GltfBuilder b = quadScene();
  b.doc["scenes"][0]["extras"]["kiln"] = {{"lightingMode", "shadowmask"},
                                          {"lightmapResolution", 20},
                                          {"lightmapPadding", 3},
                                          {"lightmapMaxSize", 2048},
                                          {"directionalMode", "directional"},
                                          {"bounces", 4},
                                          {"albedoBoost", 1.5},
                                          {"indirectIntensity", 0.8},
                                          {"ambientOcclusion", true},
                                          {"aoMaxDistance", 0.5},
                                          {"aoAmount", 0.7},
                                          {"quality", "preview"},
                                          {"sky", {{"color", {0.1, 0.2, 0.3}}}}};
  Scene s = loadOk(b.writeGltf(dir));
  const SceneSettings& st = s.settings;
  EXPECT_EQ(st.lightingMode, "shadowmask");
  EXPECT_EQ(st.lightmapResolution, 20.0f);
  EXPECT_EQ(st.lightmapPadding, 3);
  EXPECT_EQ(st.lightmapMaxSize, 2048);
  EXPECT_EQ(st.directionalMode, "directional");
  EXPECT_EQ(st.bounces, 4);
  EXPECT_EQ(st.albedoBoost, 1.5f);
  EXPECT_EQ(st.indirectIntensity, 0.8f);
  EXPECT_EQ(st.ambientOcclusion, true);
  EXPECT_EQ(st.aoMaxDistance, 0.5f);
  EXPECT_EQ(st.aoAmount, 0.7f);
  EXPECT_EQ(st.quality, "preview");
  EXPECT_FALSE(s.sky.hasMap());
  expectVec3Near(s.sky.color(), vec3(0.1f, 0.2f, 0.3f));
  // Absent settings stay unset.
  Scene plain = loadOk(quadScene().writeGltf(dir, "plain"));
  EXPECT_FALSE(plain.settings.bounces.has_value());
  EXPECT_TRUE(plain.sky.isBlack());
}

TEST_F(GltfLoaderTest, SkyMapIsLoadedRelativeToTheFile) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared absent: no HDR environment map";
  fs::create_directories(dir + "/env");
  fs::copy_file(test::sharedDir() + "/scenes/envmaps/pisa.hdr", dir + "/env/pisa.hdr");
  GltfBuilder b = quadScene();
  b.doc["scenes"][0]["extras"]["kiln"]["sky"] = {
      {"map", "env/pisa.hdr"}, {"intensity", 2}, {"rotation", 90}};
  Scene s = loadOk(b.writeGltf(dir));
  EXPECT_TRUE(s.sky.hasMap());
  EXPECT_FLOAT_EQ(s.sky.intensity(), 2.0f);
  EXPECT_FLOAT_EQ(s.sky.rotationDegrees(), 90.0f);
  LoadOptions noSky;
  noSky.loadSkyMap = false;
  EXPECT_FALSE(loadOk(dir + "/scene.gltf", noSky).sky.hasMap());
}

TEST_F(GltfLoaderTest, Cameras) {
  GltfBuilder b = quadScene();
  b.doc["cameras"] = {{{"type", "perspective"},
                       {"name", "main"},
                       {"perspective", {{"yfov", 0.7}, {"znear", 0.1}, {"aspectRatio", 1.5}}}},
                      {{"type", "orthographic"},
                       {"orthographic", {{"xmag", 2}, {"ymag", 3}, {"znear", 0}, {"zfar", 50}}}}};
  b.addNode({{"camera", 0}, {"translation", {0, 1, 5}}});
  b.addNode({{"camera", 1}, {"name", "top"}});
  Scene s = loadOk(b.writeGltf(dir));
  ASSERT_EQ(s.cameras.size(), 2u);
  EXPECT_EQ(s.cameras[0].name, "main");
  EXPECT_TRUE(s.cameras[0].perspective);
  EXPECT_FLOAT_EQ(s.cameras[0].yfov, 0.7f);
  EXPECT_FLOAT_EQ(s.cameras[0].aspectRatio, 1.5f);
  EXPECT_FLOAT_EQ(s.cameras[0].znear, 0.1f);
  EXPECT_EQ(s.cameras[0].zfar, 0.0f);
  expectVec3Near(vec3(s.cameras[0].worldFromCamera[3]), vec3(0, 1, 5));
  EXPECT_EQ(s.cameras[1].name, "top");
  EXPECT_FALSE(s.cameras[1].perspective);
  EXPECT_FLOAT_EQ(s.cameras[1].xmag, 2.0f);
  EXPECT_FLOAT_EQ(s.cameras[1].ymag, 3.0f);
  EXPECT_EQ(s.cameras[1].nodeIndex, 2);
}

// ---- bad input: each fails with the file name and the element --------------------------------

TEST_F(GltfLoaderTest, MissingFile) { expectError(dir + "/nope.gltf", {"cannot open"}); }

TEST_F(GltfLoaderTest, TruncatedJson) {
  std::string path = quadScene().writeGltf(dir);
  std::string text = test::readTextFile(path);
  test::writeTextFile(path, text.substr(0, text.size() / 2));
  expectError(path, {"malformed JSON"});
}

TEST_F(GltfLoaderTest, JsonRootNotAnObject) {
  test::writeTextFile(dir + "/a.gltf", "[1, 2, 3]");
  expectError(dir + "/a.gltf", {"not an object"});
}

TEST_F(GltfLoaderTest, DeeplyNestedJsonIsRefused) {
  test::writeTextFile(dir + "/deep.gltf", "{\"asset\": {\"version\": \"2.0\"}, \"extras\": " +
                                              std::string(100000, '[') + std::string(100000, ']') +
                                              "}");
  expectError(dir + "/deep.gltf", {"nested deeper"});
}

TEST_F(GltfLoaderTest, MissingBinFile) {
  std::string path = quadScene().writeGltf(dir);
  fs::remove(dir + "/scene.bin");
  expectError(path, {"buffers[0]", "scene.bin", "not found"});
}

TEST_F(GltfLoaderTest, ShortBinFile) {
  std::string path = quadScene().writeGltf(dir);
  fs::resize_file(dir + "/scene.bin", 20);
  expectError(path, {"buffers[0]", "shorter than byteLength"});
}

TEST_F(GltfLoaderTest, BufferViewPastItsBuffer) {
  GltfBuilder b = quadScene();
  b.doc["bufferViews"][1]["byteLength"] = 4000;
  expectError(b.writeGltf(dir), {"bufferViews[1]", "runs past buffers[0]"});
}

TEST_F(GltfLoaderTest, AccessorPastItsBufferView) {
  GltfBuilder b = quadScene();
  b.doc["accessors"][1]["count"] = 5;
  expectError(b.writeGltf(dir), {"accessors[1]", "runs past bufferViews[1]"});
}

TEST_F(GltfLoaderTest, AccessorStrideRunsPastBufferView) {
  GltfBuilder b = quadScene();
  b.doc["bufferViews"][0]["byteStride"] = 16;  // 4 x 12 bytes of data, read at stride 16
  expectError(b.writeGltf(dir), {"accessors[0]", "bufferViews[0]"});
}

TEST_F(GltfLoaderTest, HugeAccessorCountIsRefusedWithoutAllocating) {
  GltfBuilder b = quadScene();
  b.doc["accessors"][0]["count"] = uint64_t(1) << 60;
  expectError(b.writeGltf(dir), {"accessors[0]"});
  // Without a bufferView the values would be zeros the file does not pay for.
  b = quadScene();
  b.doc["accessors"][0].erase("bufferView");
  b.doc["accessors"][0]["count"] = uint64_t(1) << 40;
  expectError(b.writeGltf(dir, "noview"), {"accessors[0]", "too large"});
}

TEST_F(GltfLoaderTest, IndexBeyondVertexCount) {
  GltfBuilder b;
  Json prim = {{"attributes", {{"POSITION", b.addVec3(kQuad)}}},
               {"indices", b.addIndices(std::vector<uint16_t>{0, 1, 7})}};
  b.addNode({{"mesh", b.addMesh(Json::array({prim}))}});
  expectError(b.writeGltf(dir), {"meshes[0].primitives[0]", "accessors[1]", "7 >= vertex count 4"});
}

TEST_F(GltfLoaderTest, MissingAccessorReference) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 42;
  expectError(b.writeGltf(dir), {"meshes[0].primitives[0].attributes.NORMAL", "accessors[42]"});
}

TEST_F(GltfLoaderTest, MissingMaterialReference) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["material"] = 3;
  expectError(b.writeGltf(dir), {"meshes[0].primitives[0].material", "materials[3]"});
}

TEST_F(GltfLoaderTest, MissingTextureReference) {
  GltfBuilder b = quadScene();
  b.doc["materials"] = {{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 2}}}}}}};
  expectError(b.writeGltf(dir),
              {"materials[0].pbrMetallicRoughness.baseColorTexture.index", "textures[2]"});
}

TEST_F(GltfLoaderTest, MissingImageAndSamplerReferences) {
  GltfBuilder b = quadScene();
  b.doc["textures"] = {{{"source", 1}}};
  b.doc["images"] = {{{"uri", "a.png"}}};
  expectError(b.writeGltf(dir, "image"), {"textures[0].source", "images[1]"});
  b.doc["textures"] = {{{"source", 0}, {"sampler", 0}}};
  expectError(b.writeGltf(dir, "sampler"), {"textures[0].sampler", "samplers[0]"});
}

TEST_F(GltfLoaderTest, MissingMeshAndNodeReferences) {
  GltfBuilder b = quadScene();
  b.doc["nodes"][0]["mesh"] = 9;
  expectError(b.writeGltf(dir, "mesh"), {"nodes[0].mesh", "meshes[9]"});
  b = quadScene();
  b.doc["scenes"][0]["nodes"].push_back(5);
  expectError(b.writeGltf(dir, "root"), {"scenes[0].nodes[1]", "nodes[5]"});
  b = quadScene();
  b.doc["nodes"][0]["children"] = {-1};
  expectError(b.writeGltf(dir, "child"), {"nodes[0].children[0]"});
}

TEST_F(GltfLoaderTest, NodeCyclesAndSharedChildrenAreErrors) {
  GltfBuilder b = quadScene();
  b.addNode({{"children", {0}}}, false);
  b.doc["nodes"][0]["children"] = {1};
  expectError(b.writeGltf(dir, "cycle"), {"scenes[0].nodes", "nodes[0] is not a root"});
  // A cycle that no scene reaches is never entered.
  b = quadScene();
  b.addNode({{"children", {2}}}, false);
  b.addNode({{"children", {1}}}, false);
  EXPECT_EQ(loadOk(b.writeGltf(dir, "island")).objects.size(), 1u);
  b = quadScene();
  b.addNode({{"children", {0}}}, false);
  b.addNode({{"children", {0}}}, false);
  expectError(b.writeGltf(dir, "shared"), {"nodes[2].children", "nodes[0]"});
}

TEST_F(GltfLoaderTest, UnsupportedRequiredExtension) {
  GltfBuilder b = quadScene();
  b.doc["extensionsRequired"] = {"KHR_lights_punctual", "EXT_mesh_gpu_instancing"};
  expectError(b.writeGltf(dir), {"extensionsRequired", "unsupported extension(s) EXT_mesh_gpu_instancing",
                                 "KHR_lights_punctual, KHR_materials_emissive_strength"});
}

TEST_F(GltfLoaderTest, GarbageGlbHeader) {
  std::string path = dir + "/bad.glb";
  test::writeTextFile(path, "glTX this is not a binary gltf at all");
  expectError(path, {"GLB header", "magic"});
  test::writeTextFile(path, std::string("glTF\x02\0\0\0\xff\xff\0\0", 12) + std::string(20, 'x'));
  expectError(path, {"GLB header", "length"});
  test::writeTextFile(path, "glTF");
  expectError(path, {"GLB header", "too short"});
}

TEST_F(GltfLoaderTest, GlbBufferLongerThanBinChunk) {
  GltfBuilder b = quadScene();
  std::string path = b.writeGlb(dir, "scene", b.bin.size() + 64);
  expectError(path, {"buffers[0]", "GLB BIN chunk"});
}

TEST_F(GltfLoaderTest, PointsAndLinesAreRejected) {
  GltfBuilder b = quadScene();
  b.doc["meshes"][0]["primitives"][0]["mode"] = 0;
  expectError(b.writeGltf(dir, "points"), {"meshes[0].primitives[0]", "POINTS"});
  b.doc["meshes"][0]["primitives"][0]["mode"] = 1;
  expectError(b.writeGltf(dir, "lines"), {"meshes[0].primitives[0]", "LINES"});
}

TEST_F(GltfLoaderTest, NonFiniteNodeTransform) {
  expectError(quadScene({{"translation", {0, 1e39, 0}}}).writeGltf(dir),
              {"nodes[0].translation", "finite"});
}

TEST_F(GltfLoaderTest, NonFiniteMaterialFactor) {
  GltfBuilder b = quadScene();
  b.doc["materials"] = {{{"emissiveFactor", {1, 1e40, 0}}}};
  expectError(b.writeGltf(dir), {"materials[0].emissiveFactor"});
}

TEST_F(GltfLoaderTest, NonFiniteLightIntensity) {
  GltfBuilder b = quadScene();
  b.doc["extensions"]["KHR_lights_punctual"]["lights"] = {
      {{"type", "point"}, {"intensity", 1e300}}};
  b.addNode({{"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
  expectError(b.writeGltf(dir), {"lights[0].intensity"});
}

TEST_F(GltfLoaderTest, MissingLightReference) {
  GltfBuilder b = quadScene();
  b.addNode({{"extensions", {{"KHR_lights_punctual", {{"light", 2}}}}}});
  expectError(b.writeGltf(dir), {"nodes[1].extensions.KHR_lights_punctual.light", "lights[2]"});
}

TEST_F(GltfLoaderTest, BadNodeExtrasNameTheKey) {
  std::string path =
      quadScene({{"extras", {{"kiln", {{"scaleInLightmap", -1}}}}}}).writeGltf(dir, "room");
  Result<Scene> r = loadScene(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error(), path + ": nodes[0].extras.kiln.scaleInLightmap: must be a number >= 0");
  expectError(quadScene({{"extras", {{"kiln", {{"static", "yes"}}}}}}).writeGltf(dir, "a"),
              {"nodes[0].extras.kiln.static"});
  expectError(quadScene({{"extras", {{"kiln", {{"receiveGI", "both"}}}}}}).writeGltf(dir, "b"),
              {"nodes[0].extras.kiln.receiveGI", "\"lightmaps\" | \"probes\""});
  expectError(quadScene({{"extras", {{"kiln", {{"probes", {{1, 2}}}}}}}}).writeGltf(dir, "c"),
              {"nodes[0].extras.kiln.probes[0]"});
  expectError(quadScene({{"extras", {{"kiln", 5}}}}).writeGltf(dir, "d"), {"nodes[0].extras.kiln"});
}

TEST_F(GltfLoaderTest, BadLightExtrasNameTheKey) {
  GltfBuilder b = quadScene();
  b.doc["extensions"]["KHR_lights_punctual"]["lights"] = {
      {{"type", "point"}, {"extras", {{"kiln", {{"mode", "sometimes"}}}}}}};
  b.addNode({{"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}});
  expectError(b.writeGltf(dir, "a"), {"lights[0].extras.kiln.mode"});
  b.doc["extensions"]["KHR_lights_punctual"]["lights"][0]["extras"]["kiln"] = {
      {"shadowSamples", 0}};
  expectError(b.writeGltf(dir, "b"), {"lights[0].extras.kiln.shadowSamples"});
}

TEST_F(GltfLoaderTest, BadSceneExtrasNameTheKey) {
  GltfBuilder b = quadScene();
  b.doc["scenes"][0]["extras"]["kiln"] = {{"bounces", "many"}};
  expectError(b.writeGltf(dir, "a"), {"scenes[0].extras.kiln.bounces"});
  b.doc["scenes"][0]["extras"]["kiln"] = {{"lightingMode", "magic"}};
  expectError(b.writeGltf(dir, "b"), {"scenes[0].extras.kiln.lightingMode"});
  b.doc["scenes"][0]["extras"]["kiln"] = {{"sky", {{"map", "missing.hdr"}}}};
  expectError(b.writeGltf(dir, "c"), {"scenes[0].extras.kiln.sky.map", "missing.hdr"});
  b.doc["scenes"][0]["extras"]["kiln"] = {{"sky", {{"color", {1, -1, 0}}}}};
  expectError(b.writeGltf(dir, "d"), {"scenes[0].extras.kiln.sky.color"});
}

TEST_F(GltfLoaderTest, TinyGltfErrorsAreWrappedWithTheFileName) {
  GltfBuilder b = quadScene();
  b.doc["accessors"][0].erase("componentType");
  std::string path = b.writeGltf(dir);
  Result<Scene> r = loadScene(path);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
}

// Flipping bytes of valid files must give a scene or an error naming the file, never a crash.
TEST_F(GltfLoaderTest, MutatedFilesNeverCrash) {
  GltfBuilder b = quadScene({{"extras", {{"kiln", {{"probes", {{0, 0, 0}}}}}}}});
  b.doc["materials"] = {{{"name", "m"}}};
  b.doc["meshes"][0]["primitives"][0]["material"] = 0;
  std::string glb = test::readTextFile(b.writeGlb(dir, "base"));
  std::string gltf = test::readTextFile(b.writeGltf(dir, "base"));
  std::mt19937 rng(1234);
  int failures = 0;
  for (int i = 0; i < 300; ++i) {
    bool binary = i % 2 == 0;
    std::string bytes = binary ? glb : gltf;
    int flips = 1 + int(rng() % 4);
    for (int f = 0; f < flips; ++f) {
      size_t at = rng() % bytes.size();
      const char pool[] = "0123456789-e.,:[]{}\"x\xff";
      bytes[at] = rng() % 2 ? pool[rng() % (sizeof pool - 1)] : char(rng());
    }
    std::string path = dir + "/m" + std::to_string(i) + (binary ? ".glb" : ".gltf");
    test::writeTextFile(path, bytes);
    Result<Scene> r = loadScene(path);
    if (!r.ok()) {
      ++failures;
      EXPECT_EQ(r.error().rfind(path + ": ", 0), 0u) << r.error();
    }
    fs::remove(path);
  }
  EXPECT_GT(failures, 0);
}

// ---- real scenes ------------------------------------------------------------------------------

TEST(GltfLoaderScenes, ProjectScenesLoad) {
  std::vector<std::string> files;
  if (fs::is_directory(test::scenesDir()))
    for (const auto& e : fs::directory_iterator(test::scenesDir()))
      if (e.path().extension() == ".gltf" || e.path().extension() == ".glb")
        files.push_back(e.path().string());
  if (files.empty()) GTEST_SKIP() << "no generated scenes in " << test::scenesDir();
  for (const std::string& f : files) {
    Result<Scene> r = loadScene(f);
    ASSERT_TRUE(r.ok()) << r.error();
    EXPECT_FALSE(r->objects.empty()) << f;
    EXPECT_FALSE(r->bounds.empty()) << f;
    for (const Object& o : r->objects) {
      EXPECT_EQ(o.normals.size(), o.positions.size()) << f << " " << o.name;
      EXPECT_EQ(o.triangleMaterial.size(), o.triangles.size()) << f << " " << o.name;
      for (uint32_t m : o.triangleMaterial) EXPECT_LT(m, r->materials.size());
    }
    if (fs::path(f).filename() == "cornell_box.gltf") {
      EXPECT_EQ(r->objects.size(), 16u);
    }
  }
}

TEST(GltfLoaderScenes, SharedCornellBox) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared absent";
  Result<Scene> r = loadScene(test::sharedDir() + "/scenes/cornell_box/cornell_box.gltf");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->objects.size(), 16u);
  EXPECT_EQ(r->cameras.size(), 1u);
  int emissive = 0;
  for (const Material& m : r->materials)
    if (m.isEmissive()) {
      ++emissive;
      EXPECT_FLOAT_EQ(m.emissiveStrength, 17.0f);
      EXPECT_NEAR(m.emissiveFactor.x * m.emissiveStrength, 17.0f, 1e-4f);
      EXPECT_NEAR(m.emissiveFactor.y * m.emissiveStrength, 12.0f, 1e-4f);
      EXPECT_NEAR(m.emissiveFactor.z * m.emissiveStrength, 4.0f, 1e-4f);
    }
  EXPECT_EQ(emissive, 1);
  for (const Object& o : r->objects) EXPECT_FALSE(o.uv1.empty()) << o.name;
  // The box spans about 0.55 m.
  EXPECT_NEAR(r->bounds.extent().x, 0.556f, 0.01f);
}

TEST(GltfLoaderScenes, SharedBlenderCornellBox) {
  if (!test::sharedAvailable()) GTEST_SKIP() << "../shared absent";
  Result<Scene> r =
      loadScene(test::sharedDir() + "/scenes/cornell_vinc3r/cornellBox-2.80-Eevee-gltf.gltf");
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_EQ(r->objects.size(), 12u);  // nodes with meshes in the default scene's hierarchy
  EXPECT_EQ(r->materials.size(), 13u);
  EXPECT_FALSE(r->textures.empty());
  size_t withUv1 = 0;
  for (const Object& o : r->objects) withUv1 += !o.uv1.empty();
  EXPECT_GT(withUv1, 0u);
}

}  // namespace
}  // namespace kiln
