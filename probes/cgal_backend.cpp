// cgal_backend.cpp: Delaunay triangulations with CGAL (the second backend, and the 2D fallback
// for coplanar probes). Exact_predicates_inexact_constructions_kernel gives exact predicates,
// so the triangulation is valid for any input; each vertex carries its input index as info.
// The only translation unit that includes CGAL (it is heavy to compile).
#include <exception>
#include <string>
#include <utility>

#include <CGAL/Delaunay_triangulation_2.h>
#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/Triangulation_cell_base_with_info_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include "probes/delaunay_backends.h"
#include "probes/huge_pages.h"
#include "probes/runtime/src/prefetch.h"

namespace kiln::detail {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb3 = CGAL::Triangulation_vertex_base_with_info_3<int32_t, Kernel>;
// A finite cell's number in the output, -1 until the reading pass gives it one (infinite cells
// never get one).
struct CellNumber {
  int32_t i = -1;
};
using Cb3 = CGAL::Triangulation_cell_base_with_info_3<CellNumber, Kernel>;
using Tds3 = CGAL::Triangulation_data_structure_3<Vb3, Cb3>;
using Delaunay3 = CGAL::Delaunay_triangulation_3<Kernel, Tds3>;
using Vb2 = CGAL::Triangulation_vertex_base_with_info_2<int32_t, Kernel>;
using Tds2 = CGAL::Triangulation_data_structure_2<Vb2>;
using Delaunay2 = CGAL::Delaunay_triangulation_2<Kernel, Tds2>;
using runtime_detail::prefetch;

}  // namespace

Result<Tetrahedralization> cgalDelaunay3(std::span<const glm::dvec3> points) {
  try {
    // CGAL's range insert with info sorts indices into the points and then reads each point
    // and info through them, in an order that scatters over the arrays (a miss per point);
    // sorting the (point, index) pairs themselves with the same spatial sort and inserting
    // them as CGAL's plain range insert does (each point's vertex the next one's hint) reads
    // them in order. The Delaunay triangulation does not depend on the order (CGAL's symbolic
    // perturbation makes it unique), and the caller orders the cells canonically. The sort
    // splits each box at its middle rather than at the median point (CGAL's
    // Hilbert_sort_middle_policy, with the same biased randomised rounds): at 100k random
    // probes the sort takes 8-10 ms CPU against 18-20 with the default median policy, and
    // the insertion that follows is not slower (docs/probes.md, "Speed").
    using Input = std::pair<Kernel::Point_3, int32_t>;
    std::vector<Input> input;
    input.reserve(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      input.emplace_back(Kernel::Point_3(points[i].x, points[i].y, points[i].z), int32_t(i));
    }
    CGAL::spatial_sort(
        input.begin(), input.end(),
        CGAL::Spatial_sort_traits_adapter_3<Kernel, CGAL::First_of_pair_property_map<Input>>(),
        CGAL::Hilbert_sort_middle_policy());
    Delaunay3 dt;
    Delaunay3::Vertex_handle hint;
    for (const Input& in : input) {
      hint = dt.insert(in.first, hint);
      hint->info() = in.second;
    }
    if (dt.dimension() != 3) {
      return Error{"CGAL: triangulation has dimension " + std::to_string(dt.dimension())};
    }
    // Number the vertices in memory order (their info becomes that number, the input index
    // goes to r.vertices), then read the finite cells in memory order in one pass, numbering
    // each as it is read: CGAL's neighbor(k) is opposite vertex(k), as the caller expects. A
    // neighbour read earlier already has its number: both links are written (the earlier
    // record's slot through its index of this cell); one read later (or an infinite cell,
    // which never gets a number) leaves -1, which that later cell overwrites when it is read.
    Tetrahedralization r;
    r.vertices.reserve(dt.number_of_vertices());
    for (auto v : dt.finite_vertex_handles()) {
      r.vertices.push_back(v->info());
      v->info() = int32_t(r.vertices.size() - 1);
    }
    // The cells are read in CGAL's memory order, but their vertices and neighbours lie
    // anywhere in it (50 MB for 100k probes): the cell kAhead places ahead has the lines this
    // pass reads of its vertices and neighbours fetched, so that those misses overlap instead
    // of following each other. A cell is 72 bytes with its number (info) at byte 68, always
    // past the line the cell starts in; a vertex is 48 bytes with its info at byte 40, past
    // that line for most vertices: fetching only the first line (as before) left those a miss
    // each (100k probes: this pass 43-45 -> 30-32 ms CPU, same session, phase timers).
    r.positive = true;  // CGAL's finite cells are positively oriented (exact predicates)
    // A finite vertex of a 3D triangulation is in a finite cell: its star holds finite cells,
    // or, if only infinite ones, then one of their hull facets, whose other side is finite.
    r.everyVertexUsed = true;
    // finite and infinite: an upper bound, O(1)
    reserveOnHugePages(r.tets, dt.number_of_cells());
    constexpr int kAhead = 8;
    auto ahead = dt.finite_cells_begin();
    for (int i = 0; i < kAhead && ahead != dt.finite_cells_end(); ++i) ++ahead;
    int32_t count = 0;
    for (auto c = dt.finite_cells_begin(); c != dt.finite_cells_end(); ++c) {
      if (ahead != dt.finite_cells_end()) {
        for (int k = 0; k < 4; ++k) {
          prefetch(&*ahead->vertex(k));
          prefetch(&ahead->vertex(k)->info());
          prefetch(&*ahead->neighbor(k));
          prefetch(&ahead->neighbor(k)->info());
        }
        ++ahead;
      }
      const int32_t i = count++;
      c->info().i = i;
      BackendTet t;
      t.v = {c->vertex(0)->info(), c->vertex(1)->info(), c->vertex(2)->info(),
             c->vertex(3)->info()};
      for (int k = 0; k < 4; ++k) {
        const auto n = c->neighbor(k);
        const int32_t j = n->info().i;
        t.n[size_t(k)] = j;
        if (j >= 0) r.tets[size_t(j)].n[size_t(n->index(c))] = i;
      }
      r.tets.push_back(t);
    }
    return r;
  } catch (const std::exception& e) {
    return Error{std::string("CGAL Delaunay_triangulation_3 failed: ") + e.what()};
  }
}

Result<Triangles> cgalDelaunay2(std::span<const glm::dvec2> points) {
  try {
    std::vector<std::pair<Kernel::Point_2, int32_t>> input;
    input.reserve(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      input.emplace_back(Kernel::Point_2(points[i].x, points[i].y), int32_t(i));
    }
    Delaunay2 dt(input.begin(), input.end());
    if (dt.dimension() != 2) {
      return Error{"CGAL: 2D triangulation has dimension " + std::to_string(dt.dimension())};
    }
    Triangles tris;
    for (auto f : dt.finite_face_handles()) {
      tris.push_back({f->vertex(0)->info(), f->vertex(1)->info(), f->vertex(2)->info()});
    }
    return tris;
  } catch (const std::exception& e) {
    return Error{std::string("CGAL Delaunay_triangulation_2 failed: ") + e.what()};
  }
}

}  // namespace kiln::detail
