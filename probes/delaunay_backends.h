// delaunay_backends.h: the Delaunay libraries behind buildProbeTopology (private to probes/).
// Each takes points exactly as the probe positions (floats widened to double) and returns
// cells as indices into `points`, in the library's own order and orientation, with the
// library's own adjacency (so the caller need not match faces); the caller makes them
// canonical. Errors come back as messages, never as exceptions.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "kiln/result.h"

namespace kiln::detail {

using Tets = std::vector<std::array<int32_t, 4>>;

// A 3D Delaunay tetrahedralization: neighbours[t][k] is the tetrahedron across the face of
// tets[t] opposite its vertex k, or -1 where that face is on the convex hull.
struct Tetrahedralization {
  Tets tets;
  Tets neighbours;
};
using Triangles = std::vector<std::array<int32_t, 3>>;

// TetGen 1.5, switches "Qzn": Delaunay tetrahedralization of the point set (no "p", so no PLC
// and no Steiner points; no "q"), quiet, zero-based numbering, with neighbours. TetGen is
// AGPLv3: it is linked into the bake tools only, never into kiln_runtime.
Result<Tetrahedralization> tetgenDelaunay3(std::span<const glm::dvec3> points);

// CGAL Delaunay_triangulation_3 with Exact_predicates_inexact_constructions_kernel (the
// default backend: about twice as fast as TetGen on random probes).
Result<Tetrahedralization> cgalDelaunay3(std::span<const glm::dvec3> points);

// CGAL Delaunay_triangulation_2 (the fallback for coplanar probes), counter-clockwise faces.
Result<Triangles> cgalDelaunay2(std::span<const glm::dvec2> points);

}  // namespace kiln::detail
