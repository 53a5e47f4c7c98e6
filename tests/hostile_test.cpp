// hostile_test.cpp: every hostile input of ../shared/hostile (its README lists the command for
// each) and every case its make_hostile.py generates gets a clear answer within bounds: the
// kiln CLI exits 0, 1 or 2 (never a signal), within a CPU-time bound and under a 2 GiB
// address-space limit (setrlimit in the child), and a wall-clock bound that catches a hang
// (a FIFO). Some cases must fail with a message naming the file and field; they say which.
// Also: FIFOs given to every reader (glTF, image, sky map, .kprobe, .klppv, positions JSON,
// lock-atlas manifest) are refused at once. docs/limits.md states the bounds.
//
// Skips with a message when ../shared/hostile (KILN_SHARED_DIR) is absent; the FIFO and
// oversized-EXR cases need no shared files and always run.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfOutputFile.h>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <map>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "kiln/lppv_volume.h"
#include "kiln/probe_set.h"
#include "tests/test_util.h"

namespace kiln {
namespace {

namespace fs = std::filesystem;
using namespace kiln::test;

constexpr rlim_t kAddressSpace = rlim_t(2) << 30;  // 2 GiB per run
constexpr double kCpuSeconds = 10.0;              // user + system time per run
constexpr double kWallSeconds = 60.0;             // a run still going then is a hang

struct KilnRun {
  bool exited = false;  // false: killed by a signal (ours on a hang, or its own crash)
  int code = -1;        // exit code when exited
  int signal = 0;
  bool hung = false;  // killed by us after kWallSeconds
  double cpuSeconds = 0.0, wallSeconds = 0.0;
  long peakKiB = 0;
  std::string output;  // stdout + stderr
};

std::string describe(const KilnRun& r) {
  std::ostringstream s;
  if (r.hung)
    s << "hung (killed after " << kWallSeconds << " s)";
  else if (r.exited)
    s << "exit " << r.code;
  else
    s << "signal " << r.signal;
  s << ", " << r.cpuSeconds << " s CPU, " << r.wallSeconds << " s wall, peak " << r.peakKiB / 1024
    << " MiB";
  return s.str();
}

// Forks; the child limits its address space and runs `body` (which returns an exit code or
// execs); the parent waits with a wall-clock bound and collects CPU time and peak memory.
KilnRun runBounded(const std::function<int()>& body, const std::string& outputFile) {
  KilnRun r;
  auto start = std::chrono::steady_clock::now();
  pid_t pid = fork();
  if (pid == 0) {
    rlimit as{kAddressSpace, kAddressSpace};
    setrlimit(RLIMIT_AS, &as);
    int fd = open(outputFile.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
      close(fd);
    }
    _exit(body());
  }
  int status = 0;
  rusage usage{};
  while (true) {
    pid_t done = wait4(pid, &status, WNOHANG, &usage);
    if (done == pid) break;
    double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (elapsed > kWallSeconds && !r.hung) {
      r.hung = true;
      kill(pid, SIGKILL);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  r.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  r.exited = WIFEXITED(status);
  if (r.exited) r.code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.signal = WTERMSIG(status);
  r.cpuSeconds = double(usage.ru_utime.tv_sec) + usage.ru_utime.tv_usec * 1e-6 +
                 double(usage.ru_stime.tv_sec) + usage.ru_stime.tv_usec * 1e-6;
  r.peakKiB = usage.ru_maxrss;
  r.output = readTextFile(outputFile);
  return r;
}

// kiln with `args` (each one argument, no shell), bounded as above.
KilnRun runKiln(const std::vector<std::string>& args, const std::string& dir) {
  return runBounded(
      [&] {
        std::vector<char*> argv;
        std::string exe = kilnExe();
        argv.push_back(exe.data());
        std::vector<std::string> copy = args;
        for (std::string& a : copy) argv.push_back(a.data());
        argv.push_back(nullptr);
        execv(exe.c_str(), argv.data());
        return 127;
      },
      dir + "/output.txt");
}

// The bounds every hostile run must keep: a clear exit code, no signal, no hang, CPU time.
void expectBounded(const KilnRun& r, const std::string& what) {
  SCOPED_TRACE(what + ": " + describe(r) + "\n" + r.output.substr(0, 2000));
  EXPECT_FALSE(r.hung);
  EXPECT_TRUE(r.exited) << "killed by signal " << r.signal;
  if (r.exited) {
    EXPECT_TRUE(r.code == 0 || r.code == 1 || r.code == 2) << "exit " << r.code;
  }
  EXPECT_LT(r.cpuSeconds, kCpuSeconds);
  std::printf("  %-48s %s\n", what.c_str(), describe(r).c_str());
}

// A refusal: exit 1 or 2 and a message holding each of `needles` (file, field, reason).
void expectRefused(const KilnRun& r, const std::string& what, std::vector<std::string> needles) {
  expectBounded(r, what);
  EXPECT_TRUE(r.exited && (r.code == 1 || r.code == 2)) << what << ": " << describe(r);
  for (const std::string& n : needles)
    EXPECT_NE(r.output.find(n), std::string::npos)
        << what << ": the message lacks '" << n << "':\n" << r.output;
}

std::string hostileDir() { return sharedDir() + "/hostile"; }
bool hostileAvailable() { return fs::is_directory(hostileDir()); }

#define SKIP_WITHOUT_HOSTILE()                                                          \
  if (!hostileAvailable()) {                                                            \
    GTEST_SKIP() << "no " << hostileDir()                                               \
                 << " (KILN_SHARED_DIR/hostile): the shared hostile inputs are not present"; \
  }

std::string cornellBox() { return scenesDir() + "/cornell_box.gltf"; }

// ---- the files in ../shared/hostile, with the README's commands ---------------------------------

TEST(HostileShared, EmbreeAbortTranslate1e20Bake) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln({"bake", hostileDir() + "/bake-embree-abort-translate_1e20.gltf", "--out",
                   dir + "/out", "--preset", "preview", "--quiet"},
                  dir);
  expectBounded(r, "bake-embree-abort-translate_1e20.gltf");
}

TEST(HostileShared, EmbreeAbortProbePositions) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln({"probes", "bake", cornellBox(), "--positions",
                   hostileDir() + "/probes-bake-embree-abort-positions.json", "--out",
                   dir + "/p.kprobe", "--rays", "64", "--quiet"},
                  dir);
  expectRefused(r, "probes-bake-embree-abort-positions.json",
                {"probes-bake-embree-abort-positions.json", "positions[0]"});
}

TEST(HostileShared, LockAtlasIntOverflow) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln({"bake", hostileDir() + "/lock-atlas-int-overflow-segv.scene.gltf", "--out",
                   dir + "/out", "--lock-atlas",
                   hostileDir() + "/lock-atlas-int-overflow-segv.manifest.json", "--quiet"},
                  dir);
  expectRefused(r, "lock-atlas-int-overflow-segv", {"lock-atlas"});
}

TEST(HostileShared, FortyTexturesOnOnePng) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln({"info", hostileDir() + "/oom-40-textures-one-png.gltf"}, dir);
  expectBounded(r, "oom-40-textures-one-png.gltf (info)");
  EXPECT_EQ(r.code, 0);
}

TEST(HostileShared, LightmapResolution1e6MaxSize65536) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln(
      {"bake", hostileDir() + "/oom-extras-lightmapResolution-1e6-maxSize-65536.gltf", "--out",
       dir + "/out", "--quiet"},
      dir);
  expectRefused(r, "oom-extras-lightmapResolution-1e6-maxSize-65536.gltf",
                {"budget", "texels"});
  EXPECT_FALSE(fs::exists(dir + "/out/manifest.json"));
}

TEST(HostileShared, SixtyFourPrimsOverZeroAccessor) {
  SKIP_WITHOUT_HOSTILE();
  std::string dir = makeTempDir("kiln_hostile");
  KilnRun r = runKiln({"info", hostileDir() + "/cpu-64-prims-2pow24-zero-accessor.gltf"}, dir);
  expectRefused(r, "cpu-64-prims-2pow24-zero-accessor.gltf",
                {"cpu-64-prims-2pow24-zero-accessor.gltf", "accessors[", "without a bufferView"});
}

// ---- the cases make_hostile.py writes -----------------------------------------------------------

// Removes the generated cases (about 11 MB) when the program ends.
std::string generatedCleanup;
struct RemoveGenerated : ::testing::Environment {
  void TearDown() override {
    std::error_code ec;
    if (!generatedCleanup.empty()) fs::remove_all(generatedCleanup, ec);
  }
};
[[maybe_unused]] ::testing::Environment* const kRemoveGenerated =
    ::testing::AddGlobalTestEnvironment(new RemoveGenerated);

// Generates the cases once per test program into a scratch directory.
const std::string& generatedDir() {
  static std::string dir = [] {
    std::string d = makeTempDir("kiln_hostile_gen");
    generatedCleanup = d;
    std::string out;
    int rc = runCommand("python3 '" + hostileDir() + "/make_hostile.py' '" + d + "' 2>&1", &out);
    if (rc != 0) ADD_FAILURE() << "make_hostile.py failed: " << out;
    return d;
  }();
  return dir;
}

// What a generated case must give under `kiln info` beyond the common bounds: a refusal
// (with these words in the message) or, by default, success or a clear error.
struct Expect {
  bool refused = false;
  std::vector<std::string> words;
  bool success = false;
};

TEST(HostileGenerated, InfoOnEveryCase) {
  SKIP_WITHOUT_HOSTILE();
  const std::string& gen = generatedDir();
  // The FIFO the sky_fifo case names (make_hostile.py leaves it to the user).
  mkfifo((gen + "/fifo.hdr").c_str(), 0644);
  const std::map<std::string, Expect> expected = {
      {"baseline", {false, {}, true}},
      {"zero_accessor_64prims", {true, {"accessors[", "without a bufferView"}}},
      {"zero_accessor_over", {true, {"accessors[", "too large without a bufferView"}}},
      {"indices_2pow64", {true, {"accessors[", "count"}}},
      {"indices_negative", {true, {"accessors[", "count"}}},
      {"accessor_neg_offset", {true, {"accessors[7].byteOffset", "must be an integer >= 0"}}},
      // Without scenes every parentless node is a root, so a cycle is reached by none: a
      // warning says it is ignored. In a scene's list, a node of a cycle is no root: refused.
      {"cycle_2_no_scene", {false, {"nodes[", "cycle", "ignored"}, true}},
      {"cycle_2_in_scene", {true, {"scenes[0].nodes", "is not a root"}}},
      {"cycle_self", {true, {"nodes[1]", "its own child"}}},
      {"two_parents", {true, {"nodes["}}},
      {"png_100k", {false, {"textures[0]", "too large", "100000x100000"}, true}},
      {"png_4k_x40", {false, {}, true}},
      {"deep_100k", {false, {}, true}},
      {"nodes_65k", {false, {}, true}},
      {"empty_nodes_400000", {false, {}, true}},
      {"json_depth_1e6", {true, {"nested deeper"}}},
      {"sky_fifo", {true, {"fifo.hdr", "not a regular file"}}},
      {"sky_dev_zero", {true, {"/dev/zero", "not a regular file"}}},
      {"mesh_twice", {false, {}, true}},
  };
  int cases = 0;
  for (const auto& entry : fs::directory_iterator(gen)) {
    if (entry.path().extension() != ".gltf") continue;
    std::string name = entry.path().stem().string();
    if (name.rfind("sky_exr_", 0) == 0) continue;  // their EXRs: OversizedSkyMap below
    ++cases;
    std::string dir = makeTempDir("kiln_hostile");
    KilnRun r = runKiln({"info", entry.path().string()}, dir);
    auto it = expected.find(name);
    if (it == expected.end()) {
      expectBounded(r, name);
      continue;
    }
    const Expect& e = it->second;
    if (e.refused) {
      std::vector<std::string> words = e.words;
      words.push_back(name + ".gltf");
      expectRefused(r, name, words);
    } else {
      expectBounded(r, name);
      if (e.success) {
        EXPECT_EQ(r.code, 0) << name << ": " << r.output;
      }
      for (const std::string& w : e.words)
        EXPECT_NE(r.output.find(w), std::string::npos) << name << ": lacks '" << w << "'";
    }
  }
  EXPECT_GE(cases, 35) << "make_hostile.py wrote fewer cases than expected";
}

// Bakes where the bake itself is what a case attacks: transforms past float range (Embree),
// scene settings past the CLI's ranges (the texel budget), and a chain of 100,000 nested
// nodes (the output glTF writer composed every node's chain again: minutes).
TEST(HostileGenerated, BakeTransformsAndSettings) {
  SKIP_WITHOUT_HOSTILE();
  const std::string& gen = generatedDir();
  for (const char* name : {"translate_1e20", "translate_3e38", "scale_1e30", "scale_1e19",
                           "scale_1e-30", "extras_res_1e6_max_65536", "deep_100k"}) {
    std::string dir = makeTempDir("kiln_hostile");
    KilnRun r = runKiln({"bake", gen + "/" + name + ".gltf", "--out", dir + "/out", "--preset",
                     "preview", "--quiet"},
                    dir);
    if (std::string(name) == "extras_res_1e6_max_65536")
      expectRefused(r, name, {"budget", "texels"});
    else
      expectBounded(r, name);
  }
}

// ---- oversized images ---------------------------------------------------------------------------

// The header of an OpenEXR of side x side half RGB, without its pixels: OpenEXR writes the
// header and an empty line-offset table when the file is closed unwritten. The reader must
// refuse it for its size, from the header, before it looks at the pixels (a complete file
// would take seconds to write; the 16384^2 one of make_hostile took 9.7 GB to read).
void writeBigExrHeader(const std::string& path, int side) {
  Imf::Header header(side, side);
  header.compression() = Imf::ZIP_COMPRESSION;
  for (const char* c : {"R", "G", "B"}) header.channels().insert(c, Imf::Channel(Imf::HALF));
  Imf::OutputFile file(path.c_str(), header);
}

TEST(HostileImages, OversizedSkyMapRefusedFromItsHeader) {
  std::string dir = makeTempDir("kiln_hostile");
  writeBigExrHeader(dir + "/sky16k.exr", 16384);
  // The sky_exr_16k case of make_hostile.py, written here so that it needs no shared files.
  writeTextFile(dir + "/sky16k.gltf",
                R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[],)"
                R"("extras":{"kiln":{"sky":{"map":"sky16k.exr"}}}}]})");
  KilnRun r = runKiln({"info", dir + "/sky16k.gltf"}, dir);
  // "budget", not "truncated": the size is checked first.
  expectRefused(r, "16384^2 EXR sky map", {"sky16k.exr", "16384 x 16384", "budget"});
  EXPECT_EQ(r.output.find("truncated"), std::string::npos);
}

// ---- FIFOs given to every reader: refused at once -----------------------------------------------

class HostileFifo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = makeTempDir("kiln_hostile_fifo");
    fifo_ = dir_ + "/fifo";
    ASSERT_EQ(mkfifo(fifo_.c_str(), 0644), 0);
  }
  std::string dir_, fifo_;
};

TEST_F(HostileFifo, AsTheGltf) {
  std::string path = dir_ + "/scene.gltf";
  ASSERT_EQ(mkfifo(path.c_str(), 0644), 0);
  expectRefused(runKiln({"info", path}, dir_), "FIFO as the glTF", {path, "not a regular file"});
}

TEST_F(HostileFifo, AsATextureImage) {
  writeTextFile(dir_ + "/scene.gltf",
                R"({"asset":{"version":"2.0"},"images":[{"uri":"fifo"}],"textures":[{"source":0}],)"
                R"("materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}]})");
  expectRefused(runKiln({"info", dir_ + "/scene.gltf"}, dir_), "FIFO as a texture image",
                {"images[0].uri", "not a regular file"});
}

TEST_F(HostileFifo, AsABuffer) {
  writeTextFile(dir_ + "/scene.gltf",
                R"({"asset":{"version":"2.0"},"buffers":[{"uri":"fifo","byteLength":4}]})");
  expectRefused(runKiln({"info", dir_ + "/scene.gltf"}, dir_), "FIFO as a buffer",
                {"buffers[0].uri", "not a regular file"});
}

TEST_F(HostileFifo, AsAKprobe) {
  expectRefused(runKiln({"probes", "query", fifo_, "0", "0", "0"}, dir_), "FIFO as a .kprobe",
                {fifo_, "not a regular file"});
}

TEST_F(HostileFifo, AsAKlppv) {
  // No CLI command reads a .klppv: the runtime's reader, in a bounded child.
  KilnRun r = runBounded([&] { return loadLppvFile(fifo_).ok() ? 0 : 1; }, dir_ + "/output.txt");
  expectBounded(r, "FIFO as a .klppv");
  EXPECT_EQ(r.code, 1);
  Result<LppvVolume> direct = loadLppvFile(dir_ + "/missing.klppv");
  EXPECT_FALSE(direct.ok());
}

TEST_F(HostileFifo, AsProbePositions) {
  expectRefused(runKiln({"probes", "bake", cornellBox(), "--positions", fifo_, "--out",
                         dir_ + "/p.kprobe", "--quiet"},
                        dir_),
                "FIFO as probe positions", {fifo_, "not a regular file"});
}

TEST_F(HostileFifo, AsALockAtlasManifest) {
  expectRefused(runKiln({"bake", cornellBox(), "--out", dir_ + "/out", "--lock-atlas", fifo_,
                         "--quiet"},
                        dir_),
                "FIFO as a --lock-atlas manifest", {fifo_, "not a regular file"});
}

TEST_F(HostileFifo, AsTheSkyMapOfACleanScene) {
  writeTextFile(dir_ + "/scene.gltf",
                R"({"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[],)"
                R"("extras":{"kiln":{"sky":{"map":"fifo"}}}}]})");
  expectRefused(runKiln({"info", dir_ + "/scene.gltf"}, dir_), "FIFO as the sky map",
                {"fifo", "not a regular file"});
}

}  // namespace
}  // namespace kiln
