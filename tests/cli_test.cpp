// cli_test.cpp: the `kiln` executable as a user runs it: exit codes (0 ok, 1 bad input,
// 2 bad usage), "kiln: error:" messages naming the file, --help on every subcommand, and
// `kiln info` in text and JSON.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

// Writes a two-object scene without normals: a quad (2 triangles, with TEXCOORD_1) and a
// triangle on a dynamic node, one point light and a camera. Returns the .gltf path.
std::string writeScene(const std::string& dir) {
  const float positions[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  const float uvs[] = {0, 0, 1, 0, 1, 1, 0, 1};
  const uint16_t indices[] = {0, 1, 2, 0, 2, 3};
  std::ofstream bin(dir + "/scene.bin", std::ios::binary);
  bin.write(reinterpret_cast<const char*>(positions), sizeof positions);
  bin.write(reinterpret_cast<const char*>(uvs), sizeof uvs);
  bin.write(reinterpret_cast<const char*>(indices), sizeof indices);
  bin.close();
  Json doc = {
      {"asset", {{"version", "2.0"}}},
      {"buffers", {{{"uri", "scene.bin"}, {"byteLength", 48 + 32 + 12}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", 48}},
        {{"buffer", 0}, {"byteOffset", 48}, {"byteLength", 32}},
        {{"buffer", 0}, {"byteOffset", 80}, {"byteLength", 12}}}},
      {"accessors",
       {{{"bufferView", 0}, {"componentType", 5126}, {"count", 4}, {"type", "VEC3"}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", 4}, {"type", "VEC2"}},
        {{"bufferView", 2}, {"componentType", 5123}, {"count", 6}, {"type", "SCALAR"}},
        {{"bufferView", 2}, {"componentType", 5123}, {"count", 3}, {"type", "SCALAR"}}}},
      {"materials", {{{"name", "lamp"}, {"emissiveFactor", {1, 1, 1}}, {"alphaMode", "MASK"}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}, {"TEXCOORD_1", 1}}},
            {"indices", 2},
            {"material", 0}}}}},
        {{"primitives", {{{"attributes", {{"POSITION", 0}}}, {"indices", 3}}}}}}},
      {"cameras", {{{"type", "perspective"}, {"perspective", {{"yfov", 0.8}, {"znear", 0.1}}}}}},
      {"extensions",
       {{"KHR_lights_punctual",
         {{"lights", {{{"type", "point"}, {"name", "bulb"}, {"intensity", 25}}}}}}}},
      {"nodes",
       {{{"name", "floor"}, {"mesh", 0}},
        {{"name", "prop"},
         {"mesh", 1},
         {"translation", {0, 0, 2}},
         {"extras", {{"kiln", {{"static", false}, {"probes", {{0, 1, 0}}}}}}}},
        {{"name", "cam"}, {"camera", 0}},
        {{"name", "light"}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}}}},
      {"scenes",
       {{{"nodes", {0, 1, 2, 3}},
         {"extras", {{"kiln", {{"bounces", 3}, {"sky", {{"color", {0.5, 0.5, 0.5}}}}}}}}}}},
      {"scene", 0}};
  std::string path = dir + "/scene.gltf";
  test::writeTextFile(path, doc.dump(1));
  return path;
}

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override { dir = test::makeTempDir("kiln_cli"); }
  void TearDown() override { fs::remove_all(dir); }
  int run(const std::string& args, std::string* out) {
    return test::runCommand(std::string(test::kilnExe()) + " " + args, out);
  }
  std::string dir;
};

TEST_F(CliTest, InfoPrintsCounts) {
  std::string path = writeScene(dir);
  std::string out;
  ASSERT_EQ(run("info " + path, &out), 0) << out;
  EXPECT_NE(out.find("file: " + path), std::string::npos) << out;
  EXPECT_NE(out.find("objects: 2"), std::string::npos) << out;
  EXPECT_NE(out.find("triangles: 3"), std::string::npos) << out;
  EXPECT_NE(out.find("floor: 2 triangles, UV1 yes, static"), std::string::npos) << out;
  EXPECT_NE(out.find("prop: 1 triangles, UV1 no, dynamic"), std::string::npos) << out;
  EXPECT_NE(out.find("bulb: point, baked, intensity 25 cd"), std::string::npos) << out;
  EXPECT_NE(out.find("lamp: MASK"), std::string::npos) << out;
  EXPECT_NE(out.find("bounces: 3"), std::string::npos) << out;
  EXPECT_NE(out.find("sky: constant (0.5, 0.5, 0.5)"), std::string::npos) << out;
  EXPECT_NE(out.find("warnings: 2"), std::string::npos) << out;    // generated normals
  EXPECT_EQ(out.find("kiln: warning"), std::string::npos) << out;  // in the report instead
}

TEST_F(CliTest, InfoJsonParsesWithTheRightCounts) {
  std::string path = writeScene(dir);
  std::string out;
  // runCommand merges stderr, so this also checks that nothing but JSON is printed.
  ASSERT_EQ(run("info --json " + path, &out), 0) << out;
  Json j = Json::parse(out);
  EXPECT_EQ(j["file"], path);
  EXPECT_EQ(j["objectCount"], 2);
  EXPECT_EQ(j["triangleCount"], 3);
  ASSERT_EQ(j["objects"].size(), 2u);
  EXPECT_EQ(j["objects"][0]["name"], "floor");
  EXPECT_EQ(j["objects"][0]["triangles"], 2);
  EXPECT_EQ(j["objects"][0]["hasUV1"], true);
  EXPECT_EQ(j["objects"][1]["static"], false);
  EXPECT_EQ(j["materials"].size(), 2u);  // lamp + glTF's default
  EXPECT_EQ(j["materials"][0]["emissive"], true);
  EXPECT_EQ(j["materials"][0]["alphaMode"], "MASK");
  EXPECT_EQ(j["lights"].size(), 1u);
  EXPECT_EQ(j["lights"][0]["intensity"], 25.0);
  EXPECT_EQ(j["lights"][0]["mode"], "baked");
  EXPECT_EQ(j["cameras"].size(), 1u);
  ASSERT_EQ(j["probeGroups"].size(), 1u);
  EXPECT_EQ(j["probeGroups"][0]["probes"], 1);
  EXPECT_EQ(j["sky"]["type"], "constant");
  EXPECT_EQ(j["settings"]["bounces"], 3);
  EXPECT_EQ(j["bounds"]["max"][2], 2.0);
  // No NORMAL in the file: one warning per object, in the report (not on stderr).
  ASSERT_EQ(j["warnings"].size(), 2u);
  EXPECT_NE(j["warnings"][0].get<std::string>().find("NORMAL"), std::string::npos);
}

TEST_F(CliTest, MalformedFileIsBadInput) {
  std::string path = dir + "/broken.gltf";
  test::writeTextFile(path, "{\"asset\": {\"version\": \"2.0\"}, \"nodes\": [");
  std::string out;
  EXPECT_EQ(run("info " + path, &out), 1) << out;
  EXPECT_NE(out.find("kiln: error: "), std::string::npos) << out;
  EXPECT_NE(out.find("broken.gltf"), std::string::npos) << out;
  EXPECT_EQ(run("info " + dir + "/missing.gltf", &out), 1) << out;
  EXPECT_NE(out.find("kiln: error: "), std::string::npos) << out;
  EXPECT_NE(out.find("missing.gltf"), std::string::npos) << out;
}

TEST_F(CliTest, BadUsageExitsTwo) {
  std::string path = writeScene(dir);
  std::string out;
  EXPECT_EQ(run("info " + path + " --no-such-option", &out), 2) << out;
  EXPECT_NE(out.find("kiln: error: "), std::string::npos) << out;
  EXPECT_EQ(run("info", &out), 2) << out;  // missing SCENE
  EXPECT_EQ(run("", &out), 2) << out;      // no subcommand
  EXPECT_EQ(run("frobnicate", &out), 2) << out;
}

TEST_F(CliTest, HelpAndVersion) {
  std::string out;
  EXPECT_EQ(run("--help", &out), 0) << out;
  EXPECT_NE(out.find("info"), std::string::npos) << out;
  EXPECT_EQ(run("info --help", &out), 0) << out;
  EXPECT_NE(out.find("--json"), std::string::npos) << out;
  EXPECT_EQ(run("--version", &out), 0) << out;
  EXPECT_NE(out.find("kiln "), std::string::npos) << out;
}

}  // namespace
}  // namespace kiln
