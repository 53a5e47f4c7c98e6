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


// One tetrahedron of a backend's output: its vertices v (indices into `points`) and its
// neighbours n, n[k] the tetrahedron across the face opposite v[k] or -1 where that face is on
// the convex hull. One 32-byte record, so that reading a tetrahedron in another order than
// the backend's touches one cache line.
struct alignas(32) BackendTet {
  std::array<int32_t, 4> v, n;
};

// A 3D Delaunay tetrahedralization. `vertices`, when not empty, is the backend's own vertex
// order: tets' v index into it, and vertices[j] is the index into `points` (CGAL numbers its
// vertices in memory order, which follows its spatial sort, so that the caller's gathers of
// vertex data for nearby tetrahedra stay in cache); empty = v indexes `points` directly.
// `positive`: every tetrahedron is positively oriented (orient3d(v0, v1, v2, v3) > 0
// exactly), as CGAL guarantees, so that the caller can orient a permutation by its parity
// instead of a predicate.
struct Tetrahedralization {
  std::vector<BackendTet> tets;
  std::vector<int32_t> vertices;
  bool positive = false;
  // Every vertex of `vertices` is a vertex of some tetrahedron (CGAL: each finite vertex of a
  // 3D triangulation has finite cells around it), so the caller need not mark the used ones.
  bool everyVertexUsed = false;
};
using Triangles = std::vector<std::array<int32_t, 3>>;

// TetGen 1.5, switches "Qzn": Delaunay tetrahedralization of the point set (no "p", so no PLC
// and no Steiner points; no "q"), quiet, zero-based numbering, with neighbours. TetGen is
// AGPLv3: it is linked into the bake tools only, never into kiln_runtime.
Result<Tetrahedralization> tetgenDelaunay3(std::span<const glm::dvec3> points);

// CGAL Delaunay_triangulation_3 with Exact_predicates_inexact_constructions_kernel (the
// faster backend and the default, docs/probes.md "Delaunay backends").
Result<Tetrahedralization> cgalDelaunay3(std::span<const glm::dvec3> points);

// CGAL Delaunay_triangulation_2 (the fallback for coplanar probes), counter-clockwise faces.
Result<Triangles> cgalDelaunay2(std::span<const glm::dvec2> points);

}  // namespace kiln::detail
