// cli_test.cpp: the `kiln` executable as a user runs it: exit codes (0 ok, 1 bad input,
// 2 bad usage), "kiln: error:" messages naming the file, --help on every subcommand,
// `kiln info` in text and JSON, and NaN and infinities refused by every floating-point option.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

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

// Every floating-point option checked by CLI11 (finiteNumberValidator, cli_common.h): NaN and
// both infinities are usage errors (exit 2) whose message names the option and the value, as
// is a number just past the range; a value at the range's edge passes the check, and the
// command then fails on its missing input (exit 1) instead, so that no row bakes anything.
TEST_F(CliTest, FloatOptionsRejectNanAndInfinities) {
  const std::string bake = "bake " + dir + "/missing.gltf --out " + dir + "/out -q";
  const std::string render =
      "render " + dir + "/missing.gltf --mode reference --out " + dir + "/r.png -q";
  const std::string compare =
      "render --compare " + dir + "/missing_a.png " + dir + "/missing_b.png --out " + dir + "/";
  const std::string probes = "probes bake " + dir + "/missing.gltf --out " + dir + "/p.kprobe -q";
  const std::string place = "probes place " + dir + "/missing.gltf --out " + dir + "/p.json -q";
  const std::string comparePlacement = "probes compare-placement " + dir + "/missing.gltf -q";
  const std::string lppv =
      "probes lppv " + dir + "/missing.kprobe --bounds 0,0,0,1,1,1 --out " + dir + "/l";
  const std::string sky = " --sky 1,1,1";
  // Per command: {option, a value at the edge of its range, a finite value past it}.
  struct Check {
    std::string option, edge, outside;
  };
  const std::pair<std::string, std::vector<Check>> commands[] = {
      // 1e5001 overflows to infinity; 3.5e38 is beyond a float (it would read as infinity).
      {bake,
       {{"--error-target", "1", "1.0001"},
        {"--resolution", "1e-6", "1e5001"},
        {"--resolution", "1e5", "100001"},
        {"--ao-amount", "1", "-0.001"},
        {"--ao-distance", "1e-6", "2e9"}}},
      {bake + sky, {{"--sky-intensity", "0", "-1e-9"}}},
      {render,
       {{"--fov", "0.01", "179.5"}, {"--fov", "179", "0.009"}, {"--exposure", "-32", "32.5"}}},
      {render + sky, {{"--sky-intensity", "3.4e38", "3.5e38"}}},
      {compare, {{"--diff-scale", "1e-3", "2e6"}}},
      {probes,
       {{"--visibility-max-distance", "1e9", "-1"},
        {"--footprint", "0.5", "0.51"},
        {"--footprint-max-radius", "1e6", "0"}}},
      {probes + sky, {{"--sky-intensity", "0", "-1"}}},
      {place + sky,
       {{"--min-distance", "1e-30", "0"},
        {"--spacing", "0", "3.5e38"},
        {"--leak-weight", "0", "-1"},
        {"--floor-height", "100", "100.5"},
        {"--target-error", "0", "-0.5"},
        {"--sky-intensity", "0", "-1"}}},
      {comparePlacement, {{"--min-distance", "3.4e38", "-1"}, {"--floor-height", "0", "-1"}}},
      {lppv, {{"--samples-per-spacing", "1e-300", "0"}}},
  };
  struct Row {
    std::string command, option, edge, outside;
  };
  std::vector<Row> rows;
  for (const auto& [command, checks] : commands)
    for (const Check& c : checks) rows.push_back({command, c.option, c.edge, c.outside});
  for (const Row& row : rows) {
    for (const std::string& bad : {std::string("nan"), std::string("inf"), std::string("-inf"),
                                   std::string("NaN"), row.outside}) {
      const std::string args = row.command + " " + row.option + " " + bad;
      std::string out;
      EXPECT_EQ(run(args, &out), 2) << args << "\n" << out;
      EXPECT_NE(out.find("kiln: error: " + row.option + ": must be "), std::string::npos)
          << args << "\n"
          << out;
      EXPECT_NE(out.find("got '" + bad + "'"), std::string::npos) << args << "\n" << out;
    }
    const std::string args = row.command + " " + row.option + " " + row.edge;
    std::string out;
    EXPECT_EQ(run(args, &out), 1) << args << "\n" << out;
    EXPECT_NE(out.find("missing"), std::string::npos) << args << "\n" << out;
    EXPECT_EQ(out.find("must be"), std::string::npos) << args << "\n" << out;
  }
}

// --help describes the float options' checks by their ranges.
TEST_F(CliTest, HelpShowsFloatRanges) {
  const std::pair<std::string, std::vector<std::string>> commands[] = {
      {"bake",
       {"--error-target FLOAT:0..1", "--resolution FLOAT:1e-6..1e5",
        "--ao-distance FLOAT:1e-6..1e9", "--sky-intensity FLOAT:NUMBER >= 0"}},
      {"render",
       {"--fov FLOAT:0.01..179", "--exposure FLOAT:-32..32=0", "--diff-scale FLOAT:1e-3..1e6=4"}},
      {"probes bake", {"--footprint FLOAT:0..0.5", "--footprint-max-radius FLOAT:METRES > 0"}},
      {"probes place",
       {"--min-distance FLOAT:NUMBER > 0=0.1", "--floor-height FLOAT:0..100",
        "--target-error FLOAT:NUMBER >= 0"}},
      {"probes lppv", {"--samples-per-spacing FLOAT:NUMBER > 0=1"}},
  };
  for (const auto& [command, lines] : commands) {
    std::string out;
    EXPECT_EQ(run(command + " --help", &out), 0) << out;
    for (const std::string& line : lines) EXPECT_NE(out.find(line), std::string::npos) << out;
  }
}

// The numbers kiln parses itself (comma lists, "auto" or a number, positional coordinates):
// NaN and infinities are usage errors (exit 2) whose message names the option.
TEST_F(CliTest, HandParsedNumbersRejectNanAndInfinities) {
  const std::string bake = "bake " + dir + "/missing.gltf --out " + dir + "/out -q ";
  const std::string render =
      "render " + dir + "/missing.gltf --mode reference --out " + dir + "/r.png -q ";
  const std::string place = "probes place " + dir + "/missing.gltf --out " + dir + "/p.json -q ";
  const std::string lppv = "probes lppv " + dir + "/missing.kprobe --out " + dir + "/l ";
  const std::string query = "probes query " + dir + "/missing.kprobe ";
  struct Row {
    std::string args, message;
  };
  std::vector<Row> rows;
  for (const std::string bad : {"nan", "inf", "-inf"}) {
    rows.push_back({bake + "--min-object-texels " + bad, "--min-object-texels: expected"});
    rows.push_back({bake + "--shadow-color 0," + bad + ",0", "--shadow-color '0," + bad});
    rows.push_back({bake + "--sky 1,1," + bad, "--sky '1,1," + bad});
    rows.push_back({render + "--look-from 0," + bad + ",1 --look-at 0,0,0", "--look-from 0,"});
    rows.push_back({render + "--look-from 0,0,1 --look-at " + bad + ",0,0", "--look-at " + bad});
    rows.push_back({place + "--volume 0,0,0,1," + bad + ",1", "--volume 0,0,0,1," + bad});
    rows.push_back({lppv + "--bounds 0,0,0,1,1," + bad, "--bounds: expected"});
    rows.push_back(
        {lppv + "--bounds 0,0,0,1,1,1 --resolution " + bad + ",2,2", "--resolution: expected"});
    // "--": a positional "-inf" would otherwise read as an option.
    rows.push_back({query + "-- 0 " + bad + " 0", "probes query: the point must be finite"});
    rows.push_back({query + "-- 0 0 0 0 " + bad + " 0",
                    "probes query: the point must be finite and the normal finite"});
  }
  // Finite text that overflows a float is infinity too.
  rows.push_back({render + "--look-from 0,1e39,1 --look-at 0,0,0", "--look-from 0,1e39"});
  rows.push_back({place + "--volume 0,0,0,1,1e39,1", "--volume 0,0,0,1,1e39"});
  rows.push_back({lppv + "--bounds 0,0,0,1,1,1e39", "--bounds: expected"});
  rows.push_back({query + "0 1e39 0", "probes query: the point must be finite"});
  for (const Row& row : rows) {
    std::string out;
    EXPECT_EQ(run(row.args, &out), 2) << row.args << "\n" << out;
    EXPECT_NE(out.find("kiln: error: " + row.message), std::string::npos) << row.args << "\n"
                                                                          << out;
  }
}

}  // namespace
}  // namespace kiln
