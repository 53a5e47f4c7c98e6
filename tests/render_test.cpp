// render_test.cpp: the preview renderer (tools/render/preview_renderer.h) and `kiln render`.
// Numbers fixed by geometry and physics: a plane under a constant lightmap renders albedo x
// value; a linear lightmap is reproduced exactly by bilinear filtering, which checks the
// scaleOffset mapping and the row orientation; a sphere in a uniform probe field of radiance L
// renders albedo x (pi L) / pi, and an L1 field gives the irradiance for each pixel's normal;
// preview and path-traced reference agree within their noise; cameras put known points at
// known pixels; bad inputs exit 1 (2 for usage) naming the file and field.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "lightmap/lightmap_baker.h"
#include "lightmap/lightmap_writer.h"
#include "probes/tetrahedralize.h"
#include "src/gltf_loader.h"
#include "kiln/sh.h"
#include "tests/test_util.h"
#include "tools/render/preview_renderer.h"

namespace kiln {
namespace {

namespace fs = std::filesystem;
using test::addMaterial;
using test::addQuad;
using test::lambert;

// A 2 x 2 m floor at y = 0 facing up (x in [0, 2], z in [-2, 0]); UV1 = (x, -z) / 2.
Scene floorScene(vec3 albedo, vec3 sky) {
  Scene scene;
  scene.path = "floor (test)";
  const uint32_t m = addMaterial(scene, lambert(albedo));
  addQuad(scene, "floor", vec3(0, 0, 0), vec3(2, 0, 0), vec3(2, 0, -2), vec3(0, 0, -2), m);
  scene.sky = Sky::constant(sky);
  return scene;
}

LightmapSet constantLightmaps(const Scene& scene, vec3 value, vec4 scaleOffset) {
  LightmapSet set;
  PreviewLightmapPage page;
  page.light = Image(8, 8, 3);
  for (int y = 0; y < 8; ++y)
    for (int x = 0; x < 8; ++x)
      for (int c = 0; c < 3; ++c) page.light.at(x, y)[c] = value[c];
  set.pages.push_back(page);
  PreviewLightmapObject lit;
  lit.lightmapIndex = 0;
  lit.scaleOffset = scaleOffset;
  set.objects.assign(scene.objects.size(), lit);
  set.lights.resize(scene.lights.size());
  return set;
}

TEST(RenderTest, PlaneUnderConstantLightmapIsAlbedoTimesValue) {
  const vec3 albedo(0.5f, 0.25f, 0.8f), value(0.3f, 0.6f, 0.9f), sky(0.1f, 0.2f, 0.3f);
  Scene scene = floorScene(albedo, sky);
  LightmapSet lightmaps = constantLightmaps(scene, value, vec4(1, 1, 0, 0));
  RenderInputs in;
  in.scene = &scene;
  in.lightmaps = &lightmaps;
  RenderSettings s;
  s.width = 40;
  s.height = 30;
  const RenderCamera cam = lookAtCamera(vec3(1, 1.5f, 1.5f), vec3(1, 0, -1), 60.0f);
  Result<RenderResult> r = renderImage(in, cam, s);
  ASSERT_TRUE(r.ok()) << r.error();
  int floorPixels = 0, skyPixels = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const vec3 l = r->radiance.rgb(x, y);
      const Ray ray = cameraRay(cam, s.width, s.height, x + 0.5f, y + 0.5f);
      const float t = -ray.origin.y / ray.direction.y;
      const vec3 p = ray.origin + t * ray.direction;
      const bool onFloor = t > 0 && p.x > 0.01f && p.x < 1.99f && p.z < -0.01f && p.z > -1.99f;
      const bool offFloor = !(t > 0) || p.x < -0.01f || p.x > 2.01f || p.z > 0.01f || p.z < -2.01f;
      const vec3 expected = onFloor ? albedo * value : sky;
      if (!onFloor && !offFloor) continue;  // pixel centre within 1 cm of the edge
      (onFloor ? floorPixels : skyPixels)++;
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(l[c], expected[c], 1e-6f) << x << "," << y;
    }
  EXPECT_GT(floorPixels, 150);
  EXPECT_GT(skyPixels, 50);
}

// Texel (x, y) holds (u, v) of its centre: bilinear filtering reproduces the atlas UV exactly
// inside the outermost texel centres, so every floor pixel shows the atlas UV its hit maps to
// through uv1 x scale + offset (and rows run from v = 0 at the top).
TEST(RenderTest, LinearLightmapShowsScaleOffsetAtlasUv) {
  Scene scene = floorScene(vec3(1.0f), vec3(0.0f));
  const vec4 so(0.5f, 0.25f, 0.3f, 0.6f);
  LightmapSet lightmaps = constantLightmaps(scene, vec3(0.0f), so);
  Image& light = lightmaps.pages[0].light;
  light = Image(16, 32, 3);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 16; ++x) {
      light.at(x, y)[0] = (x + 0.5f) / 16.0f;
      light.at(x, y)[1] = (y + 0.5f) / 32.0f;
      light.at(x, y)[2] = 1.0f;
    }
  RenderInputs in;
  in.scene = &scene;
  in.lightmaps = &lightmaps;
  RenderSettings s;
  s.width = 32;
  s.height = 32;
  const RenderCamera cam = lookAtCamera(vec3(1, 3, -1.0001f), vec3(1, 0, -1), 30.0f);
  Result<RenderResult> r = renderImage(in, cam, s);
  ASSERT_TRUE(r.ok()) << r.error();
  int checked = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const Ray ray = cameraRay(cam, s.width, s.height, x + 0.5f, y + 0.5f);
      const float t = -ray.origin.y / ray.direction.y;
      const vec3 p = ray.origin + t * ray.direction;
      const vec2 uv1(p.x / 2.0f, -p.z / 2.0f);  // addQuad: p0 -> (0,0), p1 -> (1,0), p2 -> (1,1)
      const vec2 atlas = uv1 * vec2(so.x, so.y) + vec2(so.z, so.w);
      if (uv1.x < 0.01f || uv1.x > 0.99f || uv1.y < 0.01f || uv1.y > 0.99f) continue;
      const vec3 l = r->radiance.rgb(x, y);
      EXPECT_NEAR(l.r, atlas.x, 2e-4f) << x << "," << y;
      EXPECT_NEAR(l.g, atlas.y, 2e-4f) << x << "," << y;
      ++checked;
    }
  EXPECT_GT(checked, 500);
}

// Probes at the corners of a 4 m cube (and its centre) around the spheres, all with the SH
// `sh`.
ProbeSet uniformProbes(const ShL2Rgb& sh) {
  std::vector<glm::vec3> positions;
  for (int i = 0; i < 8; ++i)
    positions.push_back(vec3(i & 1 ? 3.0f : -1.0f, i & 2 ? 3.0f : -1.0f, i & 4 ? 1.0f : -3.0f));
  positions.push_back(vec3(1.0f, 1.0f, -1.0f));
  Result<ProbeSet> set = buildProbeTopology(positions);
  EXPECT_TRUE(set.ok()) << set.error();
  ProbeSet probes = std::move(set).value();
  for (ShL2Rgb& s : probes.sh) s = sh;
  return probes;
}

// Renders two spheres (the second through an LPPV) over the floor and checks every sphere
// pixel against albedo x E(n) / pi for its analytic normal.
void checkSpheresInField(const ShL2Rgb& sh, float relTolerance) {
  Scene scene = floorScene(vec3(0.5f), vec3(0.0f));
  LightmapSet lightmaps = constantLightmaps(scene, vec3(0.1f), vec4(1, 1, 0, 0));
  ProbeSet probes = uniformProbes(sh);
  RenderInputs in;
  in.scene = &scene;
  in.lightmaps = &lightmaps;
  in.probes = &probes;
  in.spheres = {RenderSphere{vec3(0.6f, 0.5f, -1.0f), 0.35f, vec3(0.8f, 0.5f, 0.3f), false},
                RenderSphere{vec3(1.4f, 0.5f, -1.0f), 0.35f, vec3(0.2f, 0.6f, 0.9f), true}};
  RenderSettings s;
  s.width = 48;
  s.height = 32;
  const RenderCamera cam = lookAtCamera(vec3(1.0f, 0.9f, 1.2f), vec3(1.0f, 0.45f, -1.0f), 35.0f);
  Result<RenderResult> r = renderImage(in, cam, s);
  ASSERT_TRUE(r.ok()) << r.error();
  int counted[2] = {0, 0};
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const Ray ray = cameraRay(cam, s.width, s.height, x + 0.5f, y + 0.5f);
      float best = kInfinity;
      int which = -1;
      for (int i = 0; i < 2; ++i)
        if (auto t = intersectSphere(in.spheres[size_t(i)], ray.origin, ray.direction, 0.0f, best)) {
          best = *t;
          which = i;
        }
      if (which < 0) continue;
      const RenderSphere& sp = in.spheres[size_t(which)];
      const vec3 n = glm::normalize(ray.origin + best * ray.direction - sp.center);
      const vec3 expected = sp.albedo * sh.irradiance(n) / kPi;
      const vec3 l = r->radiance.rgb(x, y);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(l[c], expected[c], relTolerance * expected[c] + 1e-6f)
            << "sphere " << which << " pixel " << x << "," << y;
      ++counted[which];
    }
  EXPECT_GT(counted[0], 40);
  EXPECT_GT(counted[1], 40);
}

TEST(RenderTest, SphereInUniformProbeFieldIsAlbedoTimesRadiance) {
  // Constant radiance L: c0 = 2 sqrt(pi) L, E = pi L, outgoing radiance = albedo x L.
  const vec3 L(0.2f, 0.4f, 0.6f);
  ShL2Rgb sh;
  sh.c[0] = 2.0f * std::sqrt(kPi) * L;
  EXPECT_NEAR(sh.irradiance(vec3(0, 1, 0)).g, kPi * L.g, 1e-5f);
  checkSpheresInField(sh, 1e-5f);
}

TEST(RenderTest, SphereInLinearProbeFieldFollowsNormal) {
  // Bands 0 and 1 only: E(n) = pi c0 Y00 + (2 pi / 3) (c1 Y1-1(n) + c3 Y11(n)), positive for
  // every normal with these coefficients, so each pixel's value depends on its own normal.
  ShL2Rgb sh;
  sh.c[0] = vec3(1.0f, 0.8f, 0.6f);
  sh.c[3] = vec3(0.5f, -0.3f, 0.2f);
  sh.c[1] = vec3(0.2f, 0.1f, 0.0f);
  checkSpheresInField(sh, 1e-4f);
}

// Preview against the path-traced reference in the Cornell box, baked here at a low
// resolution. The difference of the image means must stay within the noise of both estimates
// (4 sigma, sigma of the reference's mean measured from two independent renders, the
// lightmap's from its samples per texel) plus the bilinear discretization allowance.
TEST(RenderTest, PreviewAgreesWithReferenceInCornellBox) {
  Result<Scene> loaded = loadScene(test::scenesDir() + "/cornell_box.gltf");
  ASSERT_TRUE(loaded.ok()) << loaded.error();
  const Scene& scene = *loaded;
  LightmapBakeSettings bake;
  bake.resolution = 40.0f;
  bake.samplesPerTexel = 256;
  bake.bounces = 3;
  Result<LightmapBakeResult> baked = bakeLightmaps(scene, bake);
  ASSERT_TRUE(baked.ok()) << baked.error();
  const std::string dir = test::makeTempDir("kiln_render");
  LightmapOutputSettings out;
  out.outDir = dir;
  out.writeGltf = false;
  ASSERT_TRUE(writeLightmapOutputs(scene.path, *baked, bake, out).ok());
  Result<LightmapSet> lightmaps = loadLightmapSet(dir, scene);
  ASSERT_TRUE(lightmaps.ok()) << lightmaps.error();

  // The lower part of the box: floor, blocks, walls (not the emitter).
  const RenderCamera cam =
      lookAtCamera(vec3(0.278f, 0.3f, -0.6f), vec3(0.278f, 0.15f, 0.3f), 28.0f);
  RenderInputs in;
  in.scene = &scene;
  in.lightmaps = &*lightmaps;
  RenderSettings s;
  s.width = 24;
  s.height = 24;
  Result<RenderResult> preview = renderImage(in, cam, s);
  ASSERT_TRUE(preview.ok()) << preview.error();
  s.mode = RenderMode::Reference;
  s.samples = 128;
  Result<RenderResult> ref1 = renderImage(in, cam, s);
  s.seed = 1;
  Result<RenderResult> ref2 = renderImage(in, cam, s);
  ASSERT_TRUE(ref1.ok() && ref2.ok());

  const size_t n = size_t(s.width) * s.height;
  double meanP = 0, meanR = 0, sumD2 = 0, maxR = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x) {
      const float p = luminance(preview->radiance.rgb(x, y));
      const float a = luminance(ref1->radiance.rgb(x, y)), b = luminance(ref2->radiance.rgb(x, y));
      meanP += p / n;
      meanR += 0.5 * (a + b) / n;
      sumD2 += double(a - b) * (a - b);
      maxR = std::max<double>(maxR, a);
    }
  ASSERT_LT(maxR, 5.0) << "the emitter is in view";
  ASSERT_GT(meanR, 0.05);
  // Per-pixel variance of one render = E[(a - b)^2] / 2; the mean of the two renders over n
  // pixels has variance (that / 2) / n.
  const double sigmaRef = std::sqrt(sumD2 / n / 2.0 / 2.0 / n);
  // Lightmap noise: about sqrt(n / texelsPerPixel) times smaller than per-pixel reference
  // noise at 256 vs 2 x 128 paths; bounded generously by the reference's.
  const double sigmaLightmap = sigmaRef;
  const double discretization = 0.02 * meanR;  // bilinear texels + denoiser on 1.4 cm texels
  const double tolerance = 4.0 * std::hypot(sigmaRef, sigmaLightmap) + discretization;
  std::printf("preview mean %.5f, reference mean %.5f, sigma(reference mean) %.5f, tolerance %.5f\n",
              meanP, meanR, sigmaRef, tolerance);
  EXPECT_NEAR(meanP, meanR, tolerance);
  fs::remove_all(dir);
}

TEST(RenderTest, CameraPutsKnownPointsAtKnownPixels) {
  const vec3 from(1, 2, 3), at(4, 2, -1);
  const RenderCamera cam = lookAtCamera(from, at, 40.0f);
  const int w = 200, h = 100;
  std::optional<vec2> c = projectToPixel(cam, w, h, at);
  ASSERT_TRUE(c.has_value());
  EXPECT_NEAR(c->x, 100.0f, 1e-3f);
  EXPECT_NEAR(c->y, 50.0f, 1e-3f);
  const float dist = glm::length(at - from);
  const float t = std::tan(glm::radians(20.0f));
  // Top edge centre and right edge centre of the image.
  std::optional<vec2> top = projectToPixel(cam, w, h, at + cam.up * (t * dist));
  EXPECT_NEAR(top->x, 100.0f, 1e-3f);
  EXPECT_NEAR(top->y, 0.0f, 1e-3f);
  std::optional<vec2> right = projectToPixel(cam, w, h, at + cam.right * (2.0f * t * dist));
  EXPECT_NEAR(right->x, 200.0f, 1e-3f);
  EXPECT_NEAR(right->y, 50.0f, 1e-3f);
  EXPECT_FALSE(projectToPixel(cam, w, h, from - cam.forward).has_value());
  // Round trip: the ray through a pixel passes through the point projected there.
  const Ray ray = cameraRay(cam, w, h, 37.25f, 81.5f);
  std::optional<vec2> back = projectToPixel(cam, w, h, ray.origin + 5.0f * ray.direction);
  EXPECT_NEAR(back->x, 37.25f, 1e-3f);
  EXPECT_NEAR(back->y, 81.5f, 1e-3f);

  // A small sphere placed where pixel (30, 70) looks appears there, and only near there.
  Scene scene = floorScene(vec3(0.5f), vec3(0.0f));
  LightmapSet lightmaps = constantLightmaps(scene, vec3(0.0f), vec4(1, 1, 0, 0));
  ShL2Rgb sh;
  sh.c[0] = vec3(2.0f * std::sqrt(kPi));  // L = 1
  ProbeSet probes = uniformProbes(sh);
  const RenderCamera view = lookAtCamera(vec3(1, 1, 2), vec3(1, 1, -5), 50.0f);
  const Ray toPixel = cameraRay(view, 100, 80, 30.5f, 70.5f);
  RenderInputs in;
  in.scene = &scene;
  in.lightmaps = &lightmaps;
  in.probes = &probes;
  in.spheres = {RenderSphere{toPixel.origin + 3.0f * toPixel.direction, 0.02f, vec3(1.0f), false}};
  RenderSettings s;
  s.width = 100;
  s.height = 80;
  Result<RenderResult> r = renderImage(in, view, s);
  ASSERT_TRUE(r.ok()) << r.error();
  int lit = 0;
  for (int y = 0; y < s.height; ++y)
    for (int x = 0; x < s.width; ++x)
      if (r->radiance.rgb(x, y).r > 0.5f) {
        ++lit;
        EXPECT_LE(std::abs(x - 30), 1);
        EXPECT_LE(std::abs(y - 70), 1);
      }
  EXPECT_NEAR(r->radiance.rgb(30, 70).r, 1.0f, 1e-4f);  // albedo 1, L = 1, facing the camera
  EXPECT_GE(lit, 1);

  // The Cornell box's glTF camera at (0.278, 0.273, -0.8) looks down +Z: points on its axis
  // are at the image centre.
  Result<Scene> cornell = loadScene(test::scenesDir() + "/cornell_box.gltf");
  ASSERT_TRUE(cornell.ok()) << cornell.error();
  Result<RenderCamera> cc = resolveCamera(*cornell, CameraRequest{});
  ASSERT_TRUE(cc.ok());
  std::optional<vec2> centre = projectToPixel(*cc, 64, 48, vec3(0.278f, 0.273f, 0.4f));
  EXPECT_NEAR(centre->x, 32.0f, 1e-3f);
  EXPECT_NEAR(centre->y, 24.0f, 1e-3f);
  Result<RenderCamera> named = resolveCamera(*cornell, CameraRequest{"camera", {}, {}, 50.0f});
  EXPECT_TRUE(named.ok());
  Result<RenderCamera> missing = resolveCamera(*cornell, CameraRequest{"nope", {}, {}, 50.0f});
  ASSERT_FALSE(missing.ok());
  EXPECT_NE(missing.error().find("no camera named \"nope\""), std::string::npos);
}

TEST(RenderTest, ToneMapAndComparison) {
  EXPECT_EQ(acesFilmic(0.0f), 0.0f);
  EXPECT_NEAR(acesFilmic(1.0f), 2.54f / 3.16f, 1e-6f);
  EXPECT_EQ(acesFilmic(1e6f), 1.0f);
  Image a(2, 1, 3), b(2, 1, 3);
  a.pixels = {0.5f, 0.5f, 0.5f, 1.0f, 1.0f, 1.0f};
  b.pixels = {0.5f, 0.5f, 0.5f, 0.5f, 0.5f, 0.5f};
  Result<ImageComparison> c = compareImages(a, b);
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->meanAbsoluteDifference, 0.25, 1e-9);
  EXPECT_NEAR(c->relativeMeanDifference, 1.5 / 3.0, 1e-9);
  EXPECT_EQ(c->sideBySide.width, 6);
  EXPECT_FALSE(compareImages(a, Image(1, 1, 3)).ok());
  // Exposure +1 EV doubles the radiance before the curve.
  Image r(1, 1, 3);
  r.pixels = {0.25f, 0.25f, 0.25f};
  EXPECT_NEAR(toneMap(r, 1.0f).pixels[0], linearToSrgb(acesFilmic(0.5f)), 1e-6f);
}

TEST(RenderTest, SpheresJsonErrorsNameTheField) {
  auto err = [](const std::string& text) {
    Result<std::vector<RenderSphere>> r = parseSpheres(text, "s.json");
    return r.ok() ? std::string() : r.error();
  };
  EXPECT_NE(err("{\"spheres\": [{\"center\": [0,0,0], \"radius\": 1}, {\"center\": [0,0,0], "
                "\"radius\": -1}]}")
                .find("s.json: spheres[1].radius"),
            std::string::npos);
  EXPECT_NE(err("{\"spheres\": [{\"center\": [0,0], \"radius\": 1}]}").find("spheres[0].center"),
            std::string::npos);
  EXPECT_NE(err("{\"spheres\": [{\"center\": [0,0,0], \"radius\": 1, \"albedo\": [2,0,0]}]}")
                .find("spheres[0].albedo"),
            std::string::npos);
  EXPECT_NE(err("{\"spheres\": [{\"center\": [0,0,0], \"raduis\": 1}]}").find("\"raduis\""),
            std::string::npos);
  EXPECT_NE(err("{\"spheres\": [{\"center\": [0,0,0], \"radius\": 1, \"lppv\": 3}]}")
                .find("spheres[0].lppv"),
            std::string::npos);
  EXPECT_NE(err("[1, 2").find("malformed JSON"), std::string::npos);
  Result<std::vector<RenderSphere>> ok =
      parseSpheres("{\"spheres\": [{\"center\": [1,2,3], \"radius\": 0.5, \"lppv\": true}]}", "s");
  ASSERT_TRUE(ok.ok());
  EXPECT_EQ(ok->size(), 1u);
  EXPECT_TRUE((*ok)[0].lppv);
  EXPECT_EQ((*ok)[0].albedo, vec3(0.8f));
}

// The CLI end to end: a quick bake of the Cornell box, then renders that succeed (and are
// identical at any thread count) and bad inputs that fail with the field named and no PNG.
class RenderCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new std::string(test::makeTempDir("kiln_render_cli"));
    std::string output;
    bakeCode_ = test::runCommand(std::string(test::kilnExe()) + " bake " + test::scenesDir() +
                                     "/cornell_box.gltf --out " + *dir_ +
                                     "/bake --preset preview --resolution 15 --quiet",
                                 &output);
    bakeOutput_ = new std::string(output);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete bakeOutput_;
  }
  int run(const std::string& args, std::string* output) {
    return test::runCommand(std::string(test::kilnExe()) + " render " + args, output);
  }
  std::string cornell() const { return test::scenesDir() + "/cornell_box.gltf"; }
  static std::string* dir_;
  static std::string* bakeOutput_;
  static int bakeCode_;
};
std::string* RenderCliTest::dir_ = nullptr;
std::string* RenderCliTest::bakeOutput_ = nullptr;
int RenderCliTest::bakeCode_ = -1;

TEST_F(RenderCliTest, RendersDeterministicallyAndCompares) {
  ASSERT_EQ(bakeCode_, 0) << *bakeOutput_;
  const std::string& d = *dir_;
  test::writeTextFile(d + "/spheres.json",
                      "{\"spheres\": [{\"center\": [0.15, 0.1, 0.15], \"radius\": 0.08}]}");
  // A probe file is needed for the sphere: bake 8 probes quickly.
  test::writeTextFile(d + "/pos.json",
                      "{\"positions\": [[0.1,0.1,0.1],[0.45,0.1,0.1],[0.1,0.45,0.1],"
                      "[0.45,0.45,0.1],[0.1,0.1,0.45],[0.45,0.1,0.45],[0.1,0.45,0.45],"
                      "[0.45,0.45,0.45]]}");
  std::string out;
  ASSERT_EQ(test::runCommand(std::string(test::kilnExe()) + " probes bake " + cornell() +
                                 " --positions " + d + "/pos.json --no-scene-probes --rays 256 "
                                 "--out " + d + "/p.kprobe --quiet",
                             &out),
            0)
      << out;
  const std::string common = cornell() + " --lightmaps " + d + "/bake --probes " + d +
                             "/p.kprobe --spheres " + d + "/spheres.json --size 32,24 --quiet";
  ASSERT_EQ(run(common + " --threads 1 --out " + d + "/a.png --linear " + d + "/a.exr", &out), 0)
      << out;
  ASSERT_EQ(run(common + " --threads 2 --out " + d + "/b.png --linear " + d + "/b.exr", &out), 0)
      << out;
  EXPECT_EQ(test::readTextFile(d + "/a.exr"), test::readTextFile(d + "/b.exr"));
  EXPECT_EQ(test::readTextFile(d + "/a.png"), test::readTextFile(d + "/b.png"));
  // The plain blend renders too (the spheres' probes then blend by barycentric weights alone).
  ASSERT_EQ(run(common + " --probe-blend plain --out " + d + "/plain.png", &out), 0) << out;
  EXPECT_TRUE(fs::exists(d + "/plain.png"));
  ASSERT_EQ(run(common + " --mode reference --samples 4 --out " + d + "/r.png", &out), 0) << out;
  ASSERT_EQ(run("--compare " + d + "/a.png " + d + "/b.png --out " + d + "/same", &out), 0) << out;
  EXPECT_NE(out.find("mean absolute difference 0.000000"), std::string::npos) << out;
  ASSERT_EQ(run("--compare " + d + "/a.png " + d + "/r.png --out " + d + "/cmp/", &out), 0) << out;
  EXPECT_TRUE(fs::exists(d + "/cmp/compare.png"));
  EXPECT_TRUE(fs::exists(d + "/cmp/compare_diff.png"));
  EXPECT_TRUE(fs::exists(d + "/same.png"));
}

// An --atlas-uv bake writes the atlas UV into the output glTF's TEXCOORD_1 and records
// settings.atlasUv: rendering that output applies no scaleOffset, rendering the input scene
// applies the manifest's, and both show the same lightmap texels. The Cornell box's own
// TEXCOORD_1 makes the two UV paths differ only by float rounding of uv1 x s + o.
TEST_F(RenderCliTest, AtlasUvOutputRendersLikeTheInputScene) {
  const std::string& d = *dir_;
  std::string out;
  ASSERT_EQ(test::runCommand(std::string(test::kilnExe()) + " bake " + cornell() + " --out " + d +
                                 "/atlas --preset preview --resolution 15 --atlas-uv --quiet",
                             &out),
            0)
      << out;
  const std::string view = " --lightmaps " + d + "/atlas --size 48,36 --quiet --linear ";
  ASSERT_EQ(run(d + "/atlas/cornell_box.gltf" + view + d + "/output.exr --out " + d +
                    "/output.png",
                &out),
            0)
      << out;
  ASSERT_EQ(run(cornell() + view + d + "/input.exr --out " + d + "/input.png", &out), 0) << out;
  Result<Image> a = readImageFile(d + "/output.exr");
  Result<Image> b = readImageFile(d + "/input.exr");
  ASSERT_TRUE(a && b);
  ASSERT_EQ(a->pixels.size(), b->pixels.size());
  double sum = 0.0, diff = 0.0;
  for (size_t i = 0; i < a->pixels.size(); ++i) {
    sum += std::abs(b->pixels[i]);
    diff += std::abs(double(a->pixels[i]) - double(b->pixels[i]));
  }
  ASSERT_GT(sum, 0.0);
  // A scaleOffset applied twice moves every lookup by a chart's offset (tens of percent, as
  // measured when the renderer ignored settings.atlasUv); float rounding moves it by ~1e-7 of
  // a texel.
  EXPECT_LT(diff / sum, 1e-4) << "mean |output - input| / mean input";
}

TEST_F(RenderCliTest, BadInputsNameTheFieldAndWriteNothing) {
  ASSERT_EQ(bakeCode_, 0) << *bakeOutput_;
  const std::string& d = *dir_;
  const std::string png = d + "/bad.png";
  std::string out;
  struct Case {
    std::string args;
    int code;
    std::string message;
  };
  test::writeTextFile(d + "/badspheres.json",
                      "{\"spheres\": [{\"center\": [0.2, 0.1, 0.2], \"radius\": 0.1}, "
                      "{\"center\": [0.2, 0.1, 0.2], \"radius\": 0}]}");
  test::writeTextFile(d + "/goodspheres.json",
                      "{\"spheres\": [{\"center\": [0.2, 0.1, 0.2], \"radius\": 0.1}]}");
  // A manifest whose first object names another node.
  fs::create_directories(d + "/renamed");
  for (const auto& e : fs::directory_iterator(d + "/bake"))
    fs::copy_file(e.path(), d + "/renamed/" + e.path().filename().string(),
                  fs::copy_options::overwrite_existing);
  nlohmann::json manifest = nlohmann::json::parse(test::readTextFile(d + "/bake/manifest.json"));
  manifest["objects"][0]["node"] = "not_the_floor";
  test::writeTextFile(d + "/renamed/manifest.json", manifest.dump());
  const std::vector<Case> cases = {
      {cornell() + " --lightmaps " + d + "/nowhere", 1, "nowhere: no such directory"},
      {cornell() + " --lightmaps " + d + "/renamed", 1, "manifest.json: objects[0].node"},
      {test::scenesDir() + "/two_rooms.gltf --lightmaps " + d + "/bake", 1,
       "manifest.json: objects["},
      {cornell() + " --lightmaps " + d + "/bake --camera nope", 1, "no camera named \"nope\""},
      {cornell() + " --lightmaps " + d + "/bake --mode reference --spheres " + d +
           "/badspheres.json",
       1, "badspheres.json: spheres[1].radius"},
      {cornell() + " --lightmaps " + d + "/bake --probes " + d + "/bake/manifest.json", 1,
       "manifest.json"},
      {cornell() + " --lightmaps " + d + "/bake --size 0,10", 2, "--size 0,10"},
      {cornell() + " --lightmaps " + d + "/bake --size 64", 2, "--size 64"},
      {cornell() + " --lightmaps " + d + "/bake --look-from 0,0,0", 2, "--look-at"},
      {cornell() + " --lightmaps " + d + "/bake --look-from 0,0 --look-at 1,1,1", 2,
       "--look-from 0,0"},
      {cornell(), 2, "--lightmaps DIR is required"},
      {cornell() + " --lightmaps " + d + "/bake --mode fancy", 2, "--mode"},
      {cornell() + " --lightmaps " + d + "/bake --probe-blend linear", 2, "--probe-blend"},
      {cornell() + " --lightmaps " + d + "/bake --spheres " + d + "/goodspheres.json", 2,
       "--probes"},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(run(c.args + " --out " + png, &out), c.code) << c.args << "\n" << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << c.args << "\n" << out;
    EXPECT_FALSE(fs::exists(png)) << c.args;
  }
  EXPECT_EQ(run("--compare " + d + "/missing.png " + d + "/missing2.png --out " + d + "/x", &out),
            1);
  EXPECT_NE(out.find("missing.png"), std::string::npos) << out;
}

}  // namespace
}  // namespace kiln
