// light_modes_test.cpp: lighting-mode plans and shadowmask channel colouring.
#include <gtest/gtest.h>

#include <set>

#include "src/light_modes.h"

namespace kiln {
namespace {

Light spot(vec3 position, float range, float intensity, LightMode mode = LightMode::Mixed) {
  Light l;
  l.name = "spot";
  l.type = LightType::Spot;
  l.position = position;
  l.range = range;
  l.intensity = intensity;
  l.mode = mode;
  return l;
}

TEST(LightModes, ParsesNamesAndRejectsOthers) {
  EXPECT_EQ(*parseLightingMode("shadowmask"), LightingMode::Shadowmask);
  EXPECT_EQ(*parseLightingMode("baked-indirect"), LightingMode::BakedIndirect);
  EXPECT_EQ(*parseLightingMode("subtractive"), LightingMode::Subtractive);
  auto bad = parseLightingMode("distance-shadowmask");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.error().find("baked-indirect, shadowmask or subtractive"), std::string::npos);
}

TEST(LightModes, WhatEachModeBakes) {
  Scene scene;
  scene.lights = {spot({0, 0, 0}, 5, 1, LightMode::Baked), spot({0, 0, 0}, 5, 1, LightMode::Mixed),
                  spot({0, 0, 0}, 5, 1, LightMode::Realtime)};
  LightModePlan indirect = planLightModes(scene, LightingMode::BakedIndirect);
  EXPECT_EQ(indirect.bakeDirect, (std::vector<bool>{true, false, false}));
  EXPECT_EQ(indirect.bakeIndirect, (std::vector<bool>{true, true, false}));
  EXPECT_EQ(indirect.shadowmaskChannel, (std::vector<int>{-1, -1, -1}));
  LightModePlan mask = planLightModes(scene, LightingMode::Shadowmask);
  EXPECT_EQ(mask.bakeDirect, (std::vector<bool>{true, false, false}));
  EXPECT_EQ(mask.shadowmaskChannel, (std::vector<int>{-1, 0, -1}));
  LightModePlan subtractive = planLightModes(scene, LightingMode::Subtractive);
  EXPECT_EQ(subtractive.bakeDirect, (std::vector<bool>{true, true, false}));
  EXPECT_EQ(subtractive.bakeIndirect, (std::vector<bool>{true, true, false}));
}

TEST(LightModes, FiveOverlappingMixedLightsUseFourChannelsAndBakeTheFifth) {
  Scene scene;
  // Five spots within 1 m of each other, range 5: all overlap. The dimmest loses.
  for (int i = 0; i < 5; ++i) scene.lights.push_back(spot({0.2f * i, 0, 0}, 5, 10.0f - i));
  LightModePlan plan = planLightModes(scene, LightingMode::Shadowmask);
  std::set<int> used(plan.shadowmaskChannel.begin(), plan.shadowmaskChannel.begin() + 4);
  EXPECT_EQ(used, (std::set<int>{0, 1, 2, 3}));
  EXPECT_EQ(plan.shadowmaskChannel[4], -1);
  EXPECT_TRUE(plan.bakeDirect[4]);
  for (int i = 0; i < 4; ++i) EXPECT_FALSE(plan.bakeDirect[i]);
  ASSERT_EQ(plan.warnings.size(), 1u);
  EXPECT_NE(plan.warnings[0].find("more than 4 overlapping"), std::string::npos);
}

TEST(LightModes, DistantLightsShareAChannel) {
  Scene scene;
  scene.lights = {spot({0, 0, 0}, 2, 1), spot({10, 0, 0}, 2, 1)};
  EXPECT_FALSE(lightsOverlap(scene.lights[0], scene.lights[1]));
  LightModePlan plan = planLightModes(scene, LightingMode::Shadowmask);
  EXPECT_EQ(plan.shadowmaskChannel, (std::vector<int>{0, 0}));
  EXPECT_TRUE(plan.warnings.empty());
}

TEST(LightModes, DirectionalLightsOverlapEverythingAndComeFirst) {
  Scene scene;
  scene.lights = {spot({0, 0, 0}, 2, 100), spot({10, 0, 0}, 2, 100)};
  Light sun;
  sun.type = LightType::Directional;
  sun.mode = LightMode::Mixed;
  sun.intensity = 1;
  scene.lights.push_back(sun);
  EXPECT_TRUE(lightsOverlap(scene.lights[0], sun));
  LightModePlan plan = planLightModes(scene, LightingMode::Shadowmask);
  EXPECT_EQ(plan.shadowmaskChannel[2], 0);  // the sun is coloured first
  EXPECT_EQ(plan.shadowmaskChannel[0], 1);
  EXPECT_EQ(plan.shadowmaskChannel[1], 1);  // far from spot 0: shares its channel
}

}  // namespace
}  // namespace kiln
