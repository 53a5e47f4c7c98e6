// octree_placement_test.cpp: the Godot-style octree-corner placement baseline
// (probes/octree_placement.h): the triangle-box overlap test on cases decided by hand, exact
// leaf-cell and corner counts for planes and a block on a known lattice, no probe inside
// geometry (checked analytically against the block), relocation, determinism, bad settings.
#include "probes/octree_placement.h"

#include <gtest/gtest.h>

#include "tests/test_util.h"

namespace kiln {
namespace {

using test::addBox;
using test::addMaterial;
using test::addQuad;
using test::lambert;

TEST(OctreePlacement, TriangleBoxOverlapDecidedCases) {
  const vec3 c(0.0f), h(1.0f);
  // Inside, crossing, far away.
  EXPECT_TRUE(triangleBoxOverlap(c, h, vec3(-0.5f, 0, 0), vec3(0.5f, 0, 0), vec3(0, 0.5f, 0)));
  EXPECT_TRUE(triangleBoxOverlap(c, h, vec3(-5, 0, -5), vec3(5, 0, -5), vec3(0, 0, 5)));
  EXPECT_FALSE(triangleBoxOverlap(c, h, vec3(3, 3, 3), vec3(4, 3, 3), vec3(3, 4, 3)));
  // Touching a face (closed test) and just past it.
  EXPECT_TRUE(triangleBoxOverlap(c, h, vec3(-5, 1, -5), vec3(5, 1, -5), vec3(0, 1, 5)));
  EXPECT_FALSE(triangleBoxOverlap(c, h, vec3(-5, 1.01f, -5), vec3(5, 1.01f, -5), vec3(0, 1.01f, 5)));
  // Bounding boxes overlap but the triangle passes beside the corner: only the edge-cross-
  // axis tests separate them. The plane x + y = 2.5 misses the box (max x + y = 2) while
  // the triangle's box [0, 2.5]^2 x [-1, 1] covers the box's corner.
  EXPECT_FALSE(triangleBoxOverlap(c, h, vec3(2.5f, 0, -1), vec3(0, 2.5f, -1), vec3(1.25f, 1.25f, 1)));
  // The same triangle moved so that x + y = 1.9 cuts the corner.
  EXPECT_TRUE(triangleBoxOverlap(c, h, vec3(1.9f, 0, -1), vec3(0, 1.9f, -1), vec3(0.95f, 0.95f, 1)));
}

// A horizontal square [0, 4] x [0, 4] at height y (two triangles).
Scene floorAt(float y) {
  Scene scene;
  const uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
  addQuad(scene, "floor", vec3(0, y, 4), vec3(4, y, 4), vec3(4, y, 0), vec3(0, y, 0), m);
  scene.updateBounds();
  return scene;
}

TEST(OctreePlacement, LeafCellsAndCornersOfAPlaneOnAKnownLattice) {
  // Octree over [0, 4]^3, level 2: 1 m cells. A plane at y = 1.25 lies in one layer of 4 x 4
  // cells, whose corners are 5 x 2 x 5.
  uint32_t leaves = 0;
  std::vector<glm::ivec3> corners = octreeLeafCorners(floorAt(1.25f), vec3(0.0f), 4.0f, 2, &leaves);
  EXPECT_EQ(leaves, 16u);
  ASSERT_EQ(corners.size(), 50u);
  for (const glm::ivec3& k : corners) EXPECT_TRUE(k.y == 1 || k.y == 2);
  // Sorted (z, y, x) and distinct.
  for (size_t i = 1; i < corners.size(); ++i) {
    const glm::ivec3 a = corners[i - 1], b = corners[i];
    EXPECT_TRUE(std::tie(a.z, a.y, a.x) < std::tie(b.z, b.y, b.x));
  }
  // On a cell boundary (y = 1) the plane touches both layers: 32 cells, 5 x 3 x 5 corners.
  corners = octreeLeafCorners(floorAt(1.0f), vec3(0.0f), 4.0f, 2, &leaves);
  EXPECT_EQ(leaves, 32u);
  EXPECT_EQ(corners.size(), 75u);
  // Level 3 (0.5 m cells), y = 1.25 again: 8 x 8 cells in one layer, 9 x 2 x 9 corners.
  corners = octreeLeafCorners(floorAt(1.25f), vec3(0.0f), 4.0f, 3, &leaves);
  EXPECT_EQ(leaves, 64u);
  EXPECT_EQ(corners.size(), 162u);
  // A plane outside the cube touches nothing.
  corners = octreeLeafCorners(floorAt(5.0f), vec3(0.0f), 4.0f, 2, &leaves);
  EXPECT_EQ(leaves, 0u);
  EXPECT_TRUE(corners.empty());
}

// A solid 1 m block [1.5, 2.5]^3 (outward faces) in the volume [0, 4]^3: at level 2 (1 m
// cells) it touches the 2 x 2 x 2 cells around (2, 2, 2), whose 27 corners are the lattice
// points {1, 2, 3}^3; the centre one, (2, 2, 2), is inside the block.
struct BlockScene {
  Scene scene;
  std::unique_ptr<Tracer> tracer;
  BlockScene() {
    const uint32_t m = addMaterial(scene, lambert(vec3(0.5f)));
    addBox(scene, "block", vec3(1.5f), vec3(2.5f), m, /*inward=*/false);
    scene.updateBounds();
    Result<std::unique_ptr<Tracer>> t = Tracer::create(scene);
    EXPECT_TRUE(bool(t));
    tracer = std::move(t).value();
  }
};

// True when p lies inside the block grown by `margin`.
bool insideBlock(vec3 p, float margin) {
  return glm::all(glm::greaterThan(p, vec3(1.5f - margin))) &&
         glm::all(glm::lessThan(p, vec3(2.5f + margin)));
}

TEST(OctreePlacement, CornersAroundABlockNoneInsideGeometry) {
  BlockScene b;
  OctreePlacementSettings s;
  s.volumes = {Bounds3{vec3(0.0f), vec3(4.0f)}};
  s.level = 2;
  s.relocate = false;
  Result<OctreePlacement> dropped = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(dropped.ok()) << dropped.error();
  EXPECT_FLOAT_EQ(dropped->cellSize, 1.0f);
  EXPECT_EQ(dropped->leafCells, 8u);
  EXPECT_EQ(dropped->corners, 27u);
  EXPECT_EQ(dropped->dropped, 1u);  // the centre corner
  ASSERT_EQ(dropped->positions.size(), 26u);
  for (const vec3& p : dropped->positions) {
    EXPECT_FALSE(insideBlock(p, 0.0f)) << p.x << "," << p.y << "," << p.z;
    // Every kept corner is a lattice point of {1, 2, 3}^3 other than the centre.
    const vec3 r = glm::round(p);
    EXPECT_EQ(p, r);
    EXPECT_TRUE(glm::all(glm::greaterThanEqual(r, vec3(1.0f))) &&
                glm::all(glm::lessThanEqual(r, vec3(3.0f))));
  }

  // With relocation the centre corner is moved out of the block through its nearest face and
  // kept: 27 probes, none inside the block or within half the minimum distance of it.
  s.relocate = true;
  Result<OctreePlacement> moved = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(moved.ok()) << moved.error();
  EXPECT_EQ(moved->moved, 1u);
  EXPECT_EQ(moved->dropped, 0u);
  ASSERT_EQ(moved->positions.size(), 27u);
  for (const vec3& p : moved->positions)
    EXPECT_FALSE(insideBlock(p, 0.5f * s.validity.minSurfaceDistance))
        << p.x << "," << p.y << "," << p.z;

  // Deterministic at any thread count.
  s.threads = 1;
  Result<OctreePlacement> one = octreeCornerPlacement(b.scene, *b.tracer, s);
  s.threads = 2;
  Result<OctreePlacement> two = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(one.ok() && two.ok());
  EXPECT_EQ(one->positions, two->positions);
  EXPECT_EQ(one->positions, moved->positions);
}

TEST(OctreePlacement, FinerLevelsKeepCornersNearGeometryOnly) {
  // Level 4 (0.25 m cells): every leaf cell touches the block, so every corner lies within
  // one cell diagonal of the block's surface, and none inside it.
  BlockScene b;
  OctreePlacementSettings s;
  s.volumes = {Bounds3{vec3(0.0f), vec3(4.0f)}};
  s.level = 4;
  Result<OctreePlacement> r = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(r.ok()) << r.error();
  EXPECT_FLOAT_EQ(r->cellSize, 0.25f);
  // The block's faces (1.5 and 2.5) lie on cell boundaries, so the closed test takes the
  // cells 5..10 on each axis (6 x 6 x 6) that touch the solid, minus the 2 x 2 x 2 cells of
  // [1.75, 2.25]^3 that touch no face.
  EXPECT_EQ(r->leafCells, 6u * 6u * 6u - 2u * 2u * 2u);
  const float diagonal = std::sqrt(3.0f) * r->cellSize;
  for (const vec3& p : r->positions) {
    EXPECT_FALSE(insideBlock(p, 0.5f * s.validity.minSurfaceDistance));
    EXPECT_TRUE(insideBlock(p, diagonal + 0.2f)) << "far from geometry";
  }
}

TEST(OctreePlacement, CellSizeOfALevelGivesThatLevelAndCountsAreExact) {
  BlockScene b;
  OctreePlacementSettings s;
  s.volumes = {Bounds3{vec3(0.0f), vec3(4.0f)}};
  s.level = 2;
  Result<OctreePlacement> byLevel = octreeCornerPlacement(b.scene, *b.tracer, s);
  s.level = 7;  // ignored once cellSize is set
  s.cellSize = 1.0f;
  Result<OctreePlacement> bySize = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(byLevel.ok() && bySize.ok());
  EXPECT_EQ(bySize->positions, byLevel->positions);
  // 0.8 m cells: the root grows to 0.8 x 8 = 6.4 m from the volume's minimum corner; the
  // block [1.5, 2.5]^3 spans cells 1..3 on each axis: 27 cells less the centre one
  // ([1.6, 2.4]^3, inside the solid, touching no face); their corners are 4^3 lattice points,
  // all in the volume.
  s.cellSize = 0.8f;
  s.relocate = false;
  Result<OctreePlacement> odd = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_TRUE(odd.ok()) << odd.error();
  EXPECT_FLOAT_EQ(odd->cellSize, 0.8f);
  EXPECT_EQ(odd->leafCells, 26u);
  EXPECT_EQ(odd->corners, 64u);
  // Exact counts, every probe valid.
  s.relocate = true;
  for (uint32_t count : {4u, 26u, 60u, 150u}) {
    Result<std::vector<vec3>> p = octreeCornerPositions(b.scene, *b.tracer, s, count);
    ASSERT_TRUE(p.ok()) << p.error();
    EXPECT_EQ(p->size(), count);
    for (const vec3& q : *p) EXPECT_TRUE(isValidProbePoint(b.scene, *b.tracer, q, s.validity));
  }
  EXPECT_FALSE(octreeCornerPositions(b.scene, *b.tracer, s, 3).ok());
}

TEST(OctreePlacement, BadSettingsAreErrors) {
  BlockScene b;
  OctreePlacementSettings s;
  s.level = 0;
  Result<OctreePlacement> r = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("level 0"), std::string::npos) << r.error();
  s.level = 3;
  s.volumes = {Bounds3{vec3(10.0f), vec3(12.0f)}};  // no geometry there
  r = octreeCornerPlacement(b.scene, *b.tracer, s);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.error().find("no static triangle"), std::string::npos) << r.error();
}

}  // namespace
}  // namespace kiln
