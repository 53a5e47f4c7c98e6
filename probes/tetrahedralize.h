// tetrahedralize.h: probe positions -> the cells and neighbours of a ProbeSet (bake time).
//
// Delaunay tetrahedralization (CGAL by default, or TetGen: the same cells in general position),
// then Cupisz's outer cells (GDC 2012, "Light probe interpolation using tetrahedral
// tessellations") on the convex hull for continuous extrapolation. Degenerate probe sets get
// a lower-dimensional ProbeSet (see ProbeSet::dimension) and a warning, never a crash:
//   0 probes                  -> error;
//   1 distinct position       -> dimension 0: every query gets that probe;
//   all on a line (incl. 2)   -> dimension 1: segments along the line, clamped at the ends;
//   all in a plane (incl. 3)  -> dimension 2: 2D Delaunay (CGAL) in the plane, projected
//                                queries, nearest hull-boundary point outside;
//   exact / near duplicates   -> merged into the first (within mergeTolerance x diagonal);
//                                the merged probe keeps its slot but is in no cell;
//   huge coordinates          -> handled (exact predicates on the float positions) with a
//                                warning that float precision limits the lookup.
#pragma once

#include <span>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "kiln/probe_set.h"
#include "kiln/result.h"

namespace kiln {

enum class DelaunayBackend { TetGen, Cgal };

struct ProbeTopologySettings {
  // CGAL by default: the faster build (issue 16). TetGen stays selectable; it gives the same
  // cells in general position and another valid split of cospherical probes (grids). Every
  // test passes with either; beside two_rooms_thin's wall CGAL's split of the scene probes
  // leaves 0.22 of the leak bound at one point (TetGen's 3e-15), a probe whose map texel
  // straddles the doorway's edge (docs/probes.md, "Delaunay backends"). TetGen is AGPLv3 and
  // only ever linked into the bake tools, never kiln_runtime.
  DelaunayBackend backend = DelaunayBackend::Cgal;
  // Probes closer than this fraction of the bounds diagonal are merged.
  double mergeTolerance = 1e-6;
  // A set thinner than this fraction of its diagonal counts as coplanar (or colinear).
  double flatTolerance = 1e-6;
  // Inner cells per seed of the runtime's acceleration grid.
  int cellsPerSeed = 1;
};

// Builds the topology for `positions` (world space, metres). The result has zero SH and
// validity 1 for every probe (the SH bake fills them), cells in a canonical order (each cell's
// smallest probe index first where orientation allows; tetrahedra along a Morton curve
// through their centroids, ties by probe indices, so that cells near in space are near in
// memory; outer cells sorted by probe indices), so two backends that produce the same
// triangulation produce identical ProbeSets. Probes keep the caller's order (their indices
// are the caller's). The backends' own adjacency gives the neighbours. Warnings (degenerate input) are
// appended to *warnings when given. Errors: no probes, non-finite positions, backend failure.
// Thread-safe (no shared state).
Result<ProbeSet> buildProbeTopology(std::span<const glm::vec3> positions,
                                    const ProbeTopologySettings& settings = {},
                                    std::vector<std::string>* warnings = nullptr);

}  // namespace kiln
