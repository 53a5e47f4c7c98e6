// mpi_test: distributed bakes (docs/distributed.md) under `mpirun --oversubscribe -n 2` and
// `-n 3` on localhost give the same bytes as one process: lightmap pages (light, direction,
// shadowmask, AO, the dLDR PNGs), the manifest and the output glTF; the .kprobe of a probe bake;
// the positions of a placement. A rank killed mid-bake fails the job and leaves the earlier
// outputs as they were. Skipped (GTEST_SKIP) when kiln was built without MPI.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "kiln/probe_set.h"
#include "test_util.h"

namespace fs = std::filesystem;
using Json = nlohmann::json;

namespace kiln {
namespace {

#ifdef KILN_MPIEXEC
constexpr const char* kMpiexec = KILN_MPIEXEC;
#else
constexpr const char* kMpiexec = nullptr;
#endif

// mpirun as root needs --allow-run-as-root; --bind-to none lets each rank's threads use every
// core (the machine may have fewer cores than ranks: --oversubscribe).
std::string mpirun(int ranks) {
  return std::string(kMpiexec) + " --allow-run-as-root --oversubscribe --bind-to none -n " +
         std::to_string(ranks) + " ";
}

std::string readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// Every regular file under `dir` (relative path -> bytes).
std::map<std::string, std::string> filesUnder(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file())
      files[fs::relative(e.path(), dir).string()] = readBytes(e.path().string());
  return files;
}

class MpiTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!kMpiexec) GTEST_SKIP() << "kiln was built without MPI (KILN_WITH_MPI)";
    dir = test::makeTempDir("kiln_mpi");
    scene = writeMixedTwoRooms(dir);
  }

  // tools/scenes/two_rooms.gltf with its sun turned mixed, so that a shadowmask bake has a
  // channel (soft shadows: the sun's shadowAngle 0.5) and the probe group gets occlusion.
  static std::string writeMixedTwoRooms(const std::string& dir) {
    const std::string src = test::scenesDir() + "/two_rooms.gltf";
    Json g = Json::parse(test::readTextFile(src));
    g["extensions"]["KHR_lights_punctual"]["lights"][0]["extras"]["kiln"]["mode"] = "mixed";
    fs::copy_file(test::scenesDir() + "/two_rooms.bin", dir + "/two_rooms.bin");
    const std::string path = dir + "/two_rooms.gltf";
    test::writeTextFile(path, g.dump(1));
    return path;
  }

  int run(const std::string& command, std::string* output) {
    return test::runCommand(command, output);
  }

  // Runs `bake` (a command line ending in --out) into `one` (dir/stem_one.kprobe) with one
  // process and 2 threads, then with 2 ranks x 1 thread and 3 ranks x 2 threads, and expects
  // the same bytes each time.
  void expectSameProbeFileOnRanks(const std::string& bake, const std::string& stem,
                                  std::string* one) {
    std::string out;
    *one = dir + "/" + stem + "_one.kprobe";
    ASSERT_EQ(run(bake + *one + " --threads 2", &out), 0) << out;
    const std::string expected = readBytes(*one);
    ASSERT_FALSE(expected.empty());
    for (auto [ranks, threads] : {std::pair{2, 1}, {3, 2}}) {
      const std::string path = dir + "/" + stem + "_split" + std::to_string(ranks) + ".kprobe";
      ASSERT_EQ(run(mpirun(ranks) + bake + path + " --threads " + std::to_string(threads), &out),
                0)
          << out;
      EXPECT_TRUE(readBytes(path) == expected) << stem << ", " << ranks << " ranks";
    }
  }

  std::string dir, scene;
};

// Lightmaps in shadowmask mode with directional and AO pages, fixed and adaptive sampling,
// and the final gather from a bounce cache (a pass every rank must read in full) with its
// adaptive allocation, and an object lit by its probe light instead of a lightmap: every
// output file of 2 ranks x 1 thread and 3 ranks x 2 threads equals one process's.
TEST_F(MpiTest, LightmapsByteIdenticalToOneProcess) {
  const std::vector<std::string> configs = {
      "--samples 32 --lighting-mode shadowmask --directional --ao",
      "--samples 128 --error-target 0.05 --lighting-mode shadowmask --directional",
      "--samples 32 --bounce-cache 8 --adaptive --footprint-grid --coverage-map "
      "--lighting-mode shadowmask --directional",
      // table_A (134 texels at 6 per unit) lit by its probe light (probeSH, probeOcclusion):
      // objects dealt over the ranks.
      "--samples 32 --lighting-mode shadowmask --min-object-texels 150"};
  for (size_t c = 0; c < configs.size(); ++c) {
    const std::string base = std::string(test::kilnExe()) + " bake " + scene + " " + configs[c] +
                             " --resolution 6 -q --out ";
    const std::string one = dir + "/one" + std::to_string(c);
    std::string out;
    ASSERT_EQ(run(base + one + " --threads 2", &out), 0) << out;
    const auto expected = filesUnder(one);
    ASSERT_TRUE(expected.count("lightmap-0_light.exr")) << out;
    ASSERT_TRUE(expected.count("lightmap-0_shadowmask.exr")) << out;
    if (configs[c].find("min-object-texels") != std::string::npos) {
      const std::string manifest = test::readTextFile(one + "/manifest.json");
      ASSERT_NE(manifest.find("\"probeSH\""), std::string::npos) << manifest;
      ASSERT_NE(manifest.find("\"probeOcclusion\""), std::string::npos) << manifest;
    } else {
      ASSERT_TRUE(expected.count("lightmap-0_direction.exr")) << out;
    }
    for (auto [ranks, threads] : {std::pair{2, 1}, {3, 2}}) {
      const std::string split = dir + "/split" + std::to_string(c) + "_" + std::to_string(ranks);
      ASSERT_EQ(run(mpirun(ranks) + base + split + " --threads " + std::to_string(threads), &out),
                0)
          << out;
      const auto got = filesUnder(split);
      ASSERT_EQ(got.size(), expected.size()) << ranks << " ranks";
      for (const auto& [name, bytes] : expected) {
        ASSERT_TRUE(got.count(name)) << name << ", " << ranks << " ranks";
        EXPECT_TRUE(got.at(name) == bytes) << name << " differs with " << ranks << " ranks, "
                                           << threads << " threads per rank";
      }
    }
  }
}

// Without -q: one progress line for the whole job (rank 0's, counting every rank's texels) and
// one summary; the other ranks print nothing.
TEST_F(MpiTest, ProgressIsTheWholeJobsOnRankZero) {
  std::string out;
  ASSERT_EQ(run(mpirun(3) + test::kilnExe() + " bake " + scene +
                    " --samples 16 --resolution 6 --threads 1 --out " + dir + "/lm",
                &out),
            0)
      << out;
  const Json m = Json::parse(test::readTextFile(dir + "/lm/manifest.json"));
  const uint64_t texels = m["stats"]["texels"];
  const std::string done = "bake: 100.0% (" + std::to_string(texels) + "/" +
                           std::to_string(texels) + " texels";
  size_t count = 0;
  for (size_t at = out.find(done); at != std::string::npos; at = out.find(done, at + 1)) ++count;
  EXPECT_EQ(count, 1u) << out;
  size_t summaries = 0;
  for (size_t at = out.find("kiln: wrote "); at != std::string::npos;
       at = out.find("kiln: wrote ", at + 1))
    ++summaries;
  EXPECT_EQ(summaries, 1u) << out;
  EXPECT_NE(out.find("3 ranks"), std::string::npos) << out;
}

// The scene's probe group baked with occlusion (shadowmask) and visibility maps: the .kprobe
// of 2 and 3 ranks equals one process's.
TEST_F(MpiTest, ProbeFileByteIdenticalToOneProcess) {
  std::string one;
  expectSameProbeFileOnRanks(std::string(test::kilnExe()) + " probes bake " + scene +
                                 " --rays 256 --lighting-mode shadowmask -q --out ",
                             "mixed", &one);
}

// two_rooms as shipped (its sun baked): the sun layer's ramps, their cells dealt across the
// ranks, give the .kprobe of one process.
TEST_F(MpiTest, SunRampsByteIdenticalToOneProcess) {
  std::string path;
  expectSameProbeFileOnRanks(std::string(test::kilnExe()) + " probes bake " + test::scenesDir() +
                                 "/two_rooms.gltf --rays 256 -q --out ",
                             "sun", &path);
  if (HasFatalFailure()) return;
  Result<ProbeSet> one = loadProbeFile(path);
  ASSERT_TRUE(bool(one)) << one.error();
  size_t ramps = 0;
  for (const glm::vec4& r : one->sun.ramps) ramps += std::isnan(r.x) ? 0 : 1;
  ASSERT_GT(ramps, 0u) << "the test needs cells with a ramp";
}

// Placement (its cheap bakes split across ranks, every rank placing from all of them): the
// same positions file as one process, but for the report's wall time.
TEST_F(MpiTest, PlacementPositionsIdenticalToOneProcess) {
  const std::string base = std::string(test::kilnExe()) + " probes place " + scene +
                           " --budget 48 --rays 32 --check-points 128 --depth 1 -q --out ";
  auto read = [](const std::string& path) {
    Json j = Json::parse(test::readTextFile(path));
    j["report"].erase("seconds");
    return j;
  };
  std::string out;
  ASSERT_EQ(run(base + dir + "/one.json --threads 2", &out), 0) << out;
  const Json expected = read(dir + "/one.json");
  ASSERT_GE(expected["positions"].size(), 4u);
  for (auto [ranks, threads] : {std::pair{2, 1}, {3, 2}}) {
    const std::string path = dir + "/split" + std::to_string(ranks) + ".json";
    ASSERT_EQ(run(mpirun(ranks) + base + path + " --threads " + std::to_string(threads), &out), 0)
        << out;
    const Json got = read(path);
    EXPECT_EQ(got["positions"].dump(), expected["positions"].dump()) << ranks << " ranks";
    EXPECT_EQ(got.dump(), expected.dump()) << ranks << " ranks";
  }
}

// The pid of the kiln process of MPI rank `rank` whose command line contains `marker`, or -1.
pid_t findRank(int rank, const std::string& marker) {
  const std::string want = "OMPI_COMM_WORLD_RANK=" + std::to_string(rank);
  for (const auto& e : fs::directory_iterator("/proc")) {
    const std::string name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    const std::string cmdline = readBytes(e.path().string() + "/cmdline");
    if (cmdline.find(marker) == std::string::npos) continue;
    if (cmdline.rfind(std::string(KILN_EXE), 0) != 0) continue;  // mpirun itself
    const std::string env = readBytes(e.path().string() + "/environ");
    size_t at = env.find(want);
    if (at != std::string::npos && (at == 0 || env[at - 1] == '\0') &&
        (at + want.size() == env.size() || env[at + want.size()] == '\0'))
      return pid_t(std::stoi(name));
  }
  return -1;
}

// Bakes into `outDir` (holding an earlier bake) with `ranks` ranks and sends `signal` to
// rank `rank` once the light stage has started. Returns mpirun's wait status; *log gets its
// output.
int bakeAndSignalRank(const std::string& scene, const std::string& dir, const std::string& outDir,
                      int ranks, int rank, int signal, std::string* log) {
  // Long enough (minutes) that the signal lands inside the light stage; 2^16 paths per texel
  // keep a chunk of texels (cancellation is polled between chunks) around a second.
  const std::string command = mpirun(ranks) + test::kilnExe() + " bake " + scene +
                              " --samples 65536 --resolution 6 --threads 1 --out " + outDir +
                              " > " + dir + "/log.txt 2>&1";
  const pid_t child = fork();
  if (child < 0) return -1;
  if (child == 0) {
    execl("/bin/sh", "sh", "-c", command.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Wait for the light stage's progress (rank 0 prints it), then signal the rank.
  bool sent = false;
  const auto start = std::chrono::steady_clock::now();
  while (!sent && std::chrono::steady_clock::now() - start < std::chrono::seconds(120)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    if (test::readTextFile(dir + "/log.txt").find("bake: ") == std::string::npos) continue;
    const pid_t pid = findRank(rank, outDir);
    sent = pid > 0 && ::kill(pid, signal) == 0;
  }
  if (!sent) ::kill(child, SIGKILL);
  int status = 0;
  ::waitpid(child, &status, 0);
  *log = test::readTextFile(dir + "/log.txt");
  return sent ? status : -1;
}

// A rank killed (SIGKILL) or stopped (SIGTERM, as Ctrl-C on one node) during the light stage:
// the job fails (SIGTERM: exit 130 and rank 0 names the rank), and the output directory keeps
// the earlier bake's files byte for byte, with no temporary file.
TEST_F(MpiTest, KilledOrInterruptedRankFailsTheJobAndLeavesEarlierOutputs) {
  const std::string outDir = dir + "/lm";
  std::string out;
  ASSERT_EQ(run(std::string(test::kilnExe()) + " bake " + scene +
                    " --samples 8 --resolution 6 -q --out " + outDir,
                &out),
            0)
      << out;
  const auto earlier = filesUnder(outDir);
  auto expectEarlierOutputs = [&](const std::string& log) {
    const auto after = filesUnder(outDir);
    EXPECT_EQ(after.size(), earlier.size()) << log;
    for (const auto& [name, bytes] : earlier)
      EXPECT_TRUE(after.count(name) && after.at(name) == bytes) << name << " changed\n" << log;
  };
  std::string log;
  int status = bakeAndSignalRank(scene, dir, outDir, 2, 1, SIGKILL, &log);
  ASSERT_NE(status, -1) << log;
  ASSERT_TRUE(WIFEXITED(status)) << log;
  EXPECT_NE(WEXITSTATUS(status), 0) << log;
  EXPECT_NE(log.find("rank 1"), std::string::npos) << log;
  EXPECT_NE(log.find("signal 9"), std::string::npos) << log;
  expectEarlierOutputs(log);

  status = bakeAndSignalRank(scene, dir, outDir, 3, 2, SIGTERM, &log);
  ASSERT_NE(status, -1) << log;
  ASSERT_TRUE(WIFEXITED(status)) << log;
  EXPECT_EQ(WEXITSTATUS(status), 130) << log;
  EXPECT_NE(log.find("kiln: rank 2 of 3 was interrupted"), std::string::npos) << log;
  EXPECT_NE(log.find("left untouched"), std::string::npos) << log;
  expectEarlierOutputs(log);
}

}  // namespace
}  // namespace kiln
