// cli_progress_test.cpp: the long commands as a user runs them: a progress line for every
// phase (and none with --quiet), --sky / --sky-map overriding the scene's sky, --out checked
// before any work, and Ctrl-C (SIGINT) exiting 130 with earlier outputs left as they were.
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "src/image.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

// A 2 x 2 m ground at y = 0 facing +Y, `grid` x `grid` quads, without TEXCOORD_1 (so kiln
// generates lightmap UVs), with a small base colour texture (so the loader decodes one), five
// scene probes above it and an extras.kiln.sky of 0.5 that the tests override.
std::string writePlaneScene(const std::string& dir, int grid = 16) {
  std::vector<float> positions, uvs;
  std::vector<uint32_t> indices;
  const float size = 2.0f;
  for (int j = 0; j <= grid; ++j)
    for (int i = 0; i <= grid; ++i) {
      positions.insert(positions.end(), {size * i / grid, 0.0f, size * j / grid});
      uvs.insert(uvs.end(), {float(i) / grid, float(j) / grid});
    }
  auto vertex = [&](int i, int j) { return uint32_t(j * (grid + 1) + i); };
  for (int j = 0; j < grid; ++j)
    for (int i = 0; i < grid; ++i) {
      // (x, z) -> (x, z + 1) -> (x + 1, z) winds counter-clockwise seen from +Y.
      indices.insert(indices.end(), {vertex(i, j), vertex(i, j + 1), vertex(i + 1, j)});
      indices.insert(indices.end(), {vertex(i + 1, j), vertex(i, j + 1), vertex(i + 1, j + 1)});
    }
  const size_t pBytes = positions.size() * 4, uBytes = uvs.size() * 4,
               iBytes = indices.size() * 4;
  std::ofstream bin(dir + "/plane.bin", std::ios::binary);
  bin.write(reinterpret_cast<const char*>(positions.data()), std::streamsize(pBytes));
  bin.write(reinterpret_cast<const char*>(uvs.data()), std::streamsize(uBytes));
  bin.write(reinterpret_cast<const char*>(indices.data()), std::streamsize(iBytes));
  bin.close();
  Image texture(4, 4, 3);
  for (float& v : texture.pixels) v = 0.8f;
  EXPECT_TRUE(writePng(dir + "/albedo.png", texture).ok());
  const size_t vertices = positions.size() / 3;
  Json doc = {
      {"asset", {{"version", "2.0"}}},
      {"buffers", {{{"uri", "plane.bin"}, {"byteLength", pBytes + uBytes + iBytes}}}},
      {"bufferViews",
       {{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", pBytes}},
        {{"buffer", 0}, {"byteOffset", pBytes}, {"byteLength", uBytes}},
        {{"buffer", 0}, {"byteOffset", pBytes + uBytes}, {"byteLength", iBytes}}}},
      {"accessors",
       {{{"bufferView", 0},
         {"componentType", 5126},
         {"count", vertices},
         {"type", "VEC3"},
         {"min", {0, 0, 0}},
         {"max", {size, 0, size}}},
        {{"bufferView", 1}, {"componentType", 5126}, {"count", vertices}, {"type", "VEC2"}},
        {{"bufferView", 2}, {"componentType", 5125}, {"count", indices.size()}, {"type", "SCALAR"}}}},
      {"images", {{{"uri", "albedo.png"}}}},
      {"textures", {{{"source", 0}}}},
      {"materials", {{{"name", "ground"}, {"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}}},
      {"meshes",
       {{{"primitives",
          {{{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}},
            {"indices", 2},
            {"material", 0}}}}}}},
      {"nodes",
       {{{"name", "ground"},
         {"mesh", 0},
         {"extras",
          {{"kiln",
            {{"probes",
              {{0.5, 0.5, 0.5}, {1.5, 0.5, 0.5}, {0.5, 0.5, 1.5}, {0.5, 1.5, 0.5},
               {1.5, 1.5, 1.5}}}}}}}}}},
      {"scenes",
       {{{"nodes", {0}}, {"extras", {{"kiln", {{"sky", {{"color", {0.5, 0.5, 0.5}}}}}}}}}}},
      {"scene", 0}};
  const std::string path = dir + "/plane.gltf";
  test::writeTextFile(path, doc.dump(1));
  return path;
}

class CliProgressTest : public ::testing::Test {
 protected:
  void SetUp() override { dir = test::makeTempDir("kiln_cli_progress"); }
  void TearDown() override { fs::remove_all(dir); }
  // Runs kiln with stderr captured apart from stdout; returns the exit code.
  int run(const std::string& args, std::string* err) {
    const std::string errFile = dir + "/stderr.txt";
    std::string ignored;
    // In a subshell: runCommand appends its own 2>&1, which must not undo ours.
    std::string command = "(";
    command.append(test::kilnExe()).append(" ").append(args);
    command.append(" 2>").append(errFile).append(" >/dev/null)");
    const int code = test::runCommand(command, &ignored);
    *err = test::readTextFile(errFile);
    return code;
  }
  std::string dir;
};

// "<phase>: 12.3% (" somewhere in `text`.
bool hasPercentLine(const std::string& text, const std::string& phase) {
  return std::regex_search(text, std::regex("(^|\n|\r)" + phase + ": [0-9]+\\.[0-9]% \\("));
}

TEST_F(CliProgressTest, BakeShowsEveryPhaseWithAPercentageAndQuietNone) {
  const std::string scene = writePlaneScene(dir);
  std::string err;
  ASSERT_EQ(run("bake " + scene + " --out " + dir + "/out --samples 4 --resolution 8", &err), 0)
      << err;
  for (const char* phase : {"texture decoding", "UV generation", "atlas", "rasterization",
                            "push-out", "bake", "denoise", "fill", "dilation", "seams"})
    EXPECT_TRUE(hasPercentLine(err, phase)) << "no progress line for " << phase << " in:\n"
                                            << err;
  // Each phase ends on its 100% line.
  EXPECT_TRUE(hasPercentLine(err, "UV generation") &&
              err.find("UV generation: 100.0%") != std::string::npos)
      << err;

  ASSERT_EQ(run("bake " + scene + " --out " + dir + "/quiet --samples 4 --resolution 8 --quiet",
                &err),
            0)
      << err;
  // Warnings still go to stderr (the generated normals); progress and the summary do not.
  EXPECT_EQ(err.find('%'), std::string::npos) << "--quiet printed progress:\n" << err;
  EXPECT_EQ(err.find("kiln: baking"), std::string::npos) << err;
  EXPECT_EQ(err.find("kiln: wrote"), std::string::npos) << err;
}

TEST_F(CliProgressTest, ProbeCommandsShowTextureDecodingAndProbeProgress) {
  const std::string scene = writePlaneScene(dir);
  std::string err;
  ASSERT_EQ(run("probes bake " + scene + " --out " + dir + "/p.kprobe --rays 64 --sky 1,1,1",
                &err),
            0)
      << err;
  EXPECT_TRUE(hasPercentLine(err, "texture decoding")) << err;
  EXPECT_TRUE(hasPercentLine(err, "probes")) << err;
  ASSERT_EQ(run("probes bake " + scene + " --out " + dir + "/q.kprobe --rays 64 --quiet", &err),
            0)
      << err;
  EXPECT_EQ(err.find('%'), std::string::npos) << err;
}

// A lone ground under a constant sky of radiance L sees the sky over its whole upper
// hemisphere and nothing else, so E = pi L exactly and every texel (E / pi) is L. The
// scene's own extras.kiln.sky (0.5) is replaced by --sky.
TEST_F(CliProgressTest, SkyOverridesTheSceneAndGivesEqualsPiOnAnOpenPlane) {
  const std::string scene = writePlaneScene(dir);
  std::string err;
  ASSERT_EQ(run("bake " + scene + " --out " + dir + "/out --sky 1,1,1 --samples 64 "
                "--resolution 16 --no-denoise --quiet",
                &err),
            0)
      << err;
  Result<Image> page = readHdrImage(dir + "/out/lightmap-0_light.exr");
  ASSERT_TRUE(page.ok()) << page.error();
  for (int c = 0; c < 3; ++c) {
    // Texels the bake or the dilation wrote (the rest of the page is 0; no texel of this
    // scene can be 0).
    double sum = 0.0, sum2 = 0.0;
    size_t n = 0;
    for (int y = 0; y < page->height; ++y)
      for (int x = 0; x < page->width; ++x) {
        const double v = page->at(x, y)[c];
        if (v <= 0.0) continue;
        sum += v;
        sum2 += v * v;
        ++n;
      }
    ASSERT_GT(n, 900u);  // 32 x 32 texels of ground, plus padding
    const double mean = sum / double(n);
    const double sd = std::sqrt(std::max(0.0, sum2 / double(n) - mean * mean));
    const double standardError = sd / std::sqrt(double(n));
    // Five measured standard errors, plus the half-float page's rounding (half a unit in the
    // last place at 1: 2^-12, which may not average out).
    EXPECT_NEAR(mean, 1.0, 5.0 * standardError + std::ldexp(1.0, -12))
        << "channel " << c << ": sd " << sd << " over " << n << " texels";
    RecordProperty("sd" + std::to_string(c), std::to_string(sd));
    RecordProperty("mean" + std::to_string(c), std::to_string(mean));
  }

  // The same sky as an equirectangular map of constant radiance 4 at intensity 0.25: the
  // map's importance sampling has its own noise, so the bound is measured again.
  Image map(64, 32, 3);
  for (float& v : map.pixels) v = 4.0f;
  ASSERT_TRUE(writeExr(dir + "/sky.exr", map, true).ok());
  ASSERT_EQ(run("bake " + scene + " --out " + dir + "/map --sky-map " + dir + "/sky.exr "
                "--sky-intensity 0.25 --samples 64 --resolution 16 --no-denoise --quiet",
                &err),
            0)
      << err;
  Result<Image> mapped = readHdrImage(dir + "/map/lightmap-0_light.exr");
  ASSERT_TRUE(mapped.ok()) << mapped.error();
  {
    double sum = 0.0, sum2 = 0.0;
    size_t n = 0;
    for (int y = 0; y < mapped->height; ++y)
      for (int x = 0; x < mapped->width; ++x) {
        const double v = mapped->at(x, y)[1];
        if (v <= 0.0) continue;
        sum += v, sum2 += v * v, ++n;
      }
    ASSERT_GT(n, 900u);
    const double mean = sum / double(n);
    const double sd = std::sqrt(std::max(0.0, sum2 / double(n) - mean * mean));
    EXPECT_NEAR(mean, 1.0, 5.0 * sd / std::sqrt(double(n)) + std::ldexp(1.0, -12))
        << "sd " << sd << " over " << n << " texels";
    RecordProperty("mapSd", std::to_string(sd));
    RecordProperty("mapMean", std::to_string(mean));
  }

  // --sky-intensity scales it: E/pi = 0.25 x (2, 2, 2) = 0.5 (checked on the mean only).
  ASSERT_EQ(run("bake " + scene + " --out " + dir + "/half --sky 2,2,2 --sky-intensity 0.25 "
                "--samples 16 --resolution 8 --no-denoise --quiet",
                &err),
            0)
      << err;
  Result<Image> half = readHdrImage(dir + "/half/lightmap-0_light.exr");
  ASSERT_TRUE(half.ok()) << half.error();
  double sum = 0.0;
  size_t n = 0;
  for (float v : half->pixels)
    if (v > 0.0f) sum += v, ++n;
  ASSERT_GT(n, 0u);
  EXPECT_NEAR(sum / double(n), 0.5, 0.01);
}

TEST_F(CliProgressTest, BadSkyValuesExitTwoAndAnUnreadableMapExitsOne) {
  const std::string scene = writePlaneScene(dir);
  std::string err;
  for (const char* sky : {"1,1", "1,-1,1", "1,nan,1", "1,inf,1", "a,b,c", "1,1,1,1"}) {
    EXPECT_EQ(run("bake " + scene + " --out " + dir + "/o --sky '" + sky + "'", &err), 2) << sky;
    EXPECT_NE(err.find("--sky '" + std::string(sky) + "'"), std::string::npos) << err;
  }
  EXPECT_EQ(run("bake " + scene + " --out " + dir + "/o --sky 1,1,1 --sky-intensity -1", &err),
            2);
  EXPECT_NE(err.find("--sky-intensity"), std::string::npos) << err;
  EXPECT_EQ(run("bake " + scene + " --out " + dir + "/o --sky-intensity 2", &err), 2);
  EXPECT_NE(err.find("--sky-intensity needs"), std::string::npos) << err;
  EXPECT_EQ(run("bake " + scene + " --out " + dir + "/o --sky 1,1,1 --sky-map x.hdr", &err), 2);
  const std::string missing = dir + "/missing.hdr";
  EXPECT_EQ(run("bake " + scene + " --out " + dir + "/o --sky-map " + missing, &err), 1);
  EXPECT_NE(err.find(missing), std::string::npos) << err;
  test::writeTextFile(dir + "/broken.hdr", "not an image");
  EXPECT_EQ(run("probes bake " + scene + " --out " + dir + "/p.kprobe --sky-map " + dir +
                    "/broken.hdr",
                &err),
            1);
  EXPECT_NE(err.find("broken.hdr"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(dir + "/o"));
}

// --out under a regular file (so it cannot be created) or a regular file itself is refused
// before the scene is loaded: the error is the first thing on stderr, no progress line was
// printed and, on the breakfast room (262k triangles, seconds to load), it answers at once.
TEST_F(CliProgressTest, UnwritableOutIsRefusedBeforeAnyWork) {
  const std::string scene = test::sharedAvailable()
                                ? test::sharedDir() + "/scenes/breakfast_room/BreakfastRoom.gltf"
                                : writePlaneScene(dir);
  const std::string file = dir + "/a_file";
  test::writeTextFile(file, "not a directory");
  struct Case {
    std::string command, out;
  };
  const std::vector<Case> cases = {
      {"bake " + scene + " --preset preview --out ", file + "/lightmaps"},
      {"bake " + scene + " --preset preview --out ", file + "/deeper/lightmaps"},
      {"bake " + scene + " --preset preview --out ", file},
      {"probes bake " + scene + " --out ", file + "/probes.kprobe"},
      {"probes bake " + scene + " --out ", dir},  // a directory, not a file
      {"probes place " + scene + " --out ", file + "/positions.json"},
      {"render " + scene + " --lightmaps " + dir + " --out ", file + "/image.png"},
  };
  for (const Case& c : cases) {
    std::string err;
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(run(c.command + c.out, &err), 1) << c.command << c.out << "\n" << err;
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_EQ(err.rfind("kiln: error: --out " + c.out + ": ", 0), 0u) << err;
    EXPECT_EQ(err.find('%'), std::string::npos) << err;
    EXPECT_LT(seconds, 1.0) << c.command << c.out;
  }
  EXPECT_EQ(test::readTextFile(file), "not a directory");
}

// ---- Ctrl-C ---------------------------------------------------------------------------------

// kiln started with `args`, its stderr on a pipe.
struct Child {
  pid_t pid = -1;
  int err = -1;
};

Child spawnKiln(const std::vector<std::string>& args) {
  int fds[2];
  if (::pipe(fds) != 0) return {};
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(fds[1], STDERR_FILENO);
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, STDOUT_FILENO);
    ::close(fds[0]);
    ::close(fds[1]);
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(test::kilnExe()));
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    ::execv(test::kilnExe(), argv.data());
    ::_exit(127);
  }
  ::close(fds[1]);
  return {pid, fds[0]};
}

// Reads the child's stderr into *text until it contains `needle`, EOF or `seconds` pass.
bool readUntil(int fd, const std::string& needle, double seconds, std::string* text) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (text->find(needle) == std::string::npos) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        end - std::chrono::steady_clock::now());
    if (left.count() <= 0) return false;
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, int(left.count())) <= 0) return false;
    char buf[4096];
    const ssize_t n = ::read(fd, buf, sizeof buf);
    if (n <= 0) return false;
    text->append(buf, size_t(n));
  }
  return true;
}

// Exit code, or 1000 + signal when the child was killed by one.
int waitExit(const Child& c, std::string* text) {
  char buf[4096];
  ssize_t n;
  while ((n = ::read(c.err, buf, sizeof buf)) > 0) text->append(buf, size_t(n));
  ::close(c.err);
  int status = 0;
  ::waitpid(c.pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 1000 + WTERMSIG(status);
}

// Ctrl-C once the first progress line (texture decoding, the first phase) is out: every long
// command stops, exits 130 and leaves the output that was there before untouched.
TEST_F(CliProgressTest, CtrlCExits130AndLeavesEarlierOutputsIntact) {
  const std::string scene = writePlaneScene(dir);
  const std::string earlier = "an earlier output\n";
  struct Case {
    std::vector<std::string> args;
    std::string out;
  };
  const std::vector<Case> cases = {
      {{"probes", "bake", scene, "--rays", "16777216", "--out", dir + "/p.kprobe"},
       dir + "/p.kprobe"},
      {{"probes", "place", scene, "--volume", "0,0.1,0,2,2,2", "--rays", "65536", "--budget",
        "100000", "--out",
        dir + "/positions.json"},
       dir + "/positions.json"},
      // Cancellation is polled between chunks of 16 texels: 2^16 paths per texel keeps a
      // chunk around a second while the whole bake would take minutes.
      {{"bake", scene, "--samples", "65536", "--resolution", "32", "--out", dir + "/lm"},
       dir + "/lm/manifest.json"},
  };
  fs::create_directories(dir + "/lm");
  for (const Case& c : cases) {
    test::writeTextFile(c.out, earlier);
    Child child = spawnKiln(c.args);
    ASSERT_GT(child.pid, 0);
    std::string err;
    const bool started = readUntil(child.err, "texture decoding: ", 30.0, &err);
    EXPECT_TRUE(started) << c.args[0] << " " << c.args[1] << ": " << err;
    const auto sent = std::chrono::steady_clock::now();
    ::kill(child.pid, SIGINT);
    const int code = waitExit(child, &err);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - sent).count();
    EXPECT_EQ(code, 130) << c.args[0] << " " << c.args[1] << ": " << err;
    EXPECT_NE(err.find("interrupted"), std::string::npos) << err;
    EXPECT_LT(seconds, 10.0) << c.args[0] << " " << c.args[1] << " took this long to stop";
    EXPECT_EQ(test::readTextFile(c.out), earlier) << c.out;
  }
}

}  // namespace
}  // namespace kiln
