// tetgen_backend.cpp: Delaunay tetrahedralization with TetGen 1.5 (Si, "TetGen, a
// Delaunay-based quality tetrahedral mesh generator", ACM TOMS 2015). TetGen uses Shewchuk's
// robust predicates; in library mode (TETLIBRARY) it reports failure by throwing an int.
#include <exception>
#include <string>

#include <tetgen.h>

#include "probes/delaunay_backends.h"

namespace kiln::detail {

Result<Tetrahedralization> tetgenDelaunay3(std::span<const glm::dvec3> points) {
  try {
    tetgenio in, out;
    in.firstnumber = 0;
    in.numberofpoints = int(points.size());
    in.pointlist = new REAL[points.size() * 3];  // freed by tetgenio::deinitialize
    for (size_t i = 0; i < points.size(); ++i) {
      for (int a = 0; a < 3; ++a) in.pointlist[3 * i + a] = points[i][a];
    }
    // Q: quiet; z: number from zero; n: neighbours (the i-th opposite the i-th corner, -1 on
    // the hull). Without p there is no PLC and without q no quality refinement, so TetGen
    // adds no Steiner points: the output vertices are the input points.
    char switches[] = "Qzn";
    tetrahedralize(switches, &in, &out);
    if (out.numberofpoints != in.numberofpoints) {
      return Error{"TetGen: output has " + std::to_string(out.numberofpoints) +
                   " points for " + std::to_string(in.numberofpoints) + " inputs"};
    }
    if (out.neighborlist == nullptr) return Error{"TetGen: no neighbour list"};
    Tetrahedralization r;
    r.tets.resize(size_t(out.numberoftetrahedra));
    for (int t = 0; t < out.numberoftetrahedra; ++t) {
      for (int k = 0; k < 4; ++k) {
        r.tets[size_t(t)].v[k] = out.tetrahedronlist[t * out.numberofcorners + k];
        const int n = out.neighborlist[4 * t + k];
        r.tets[size_t(t)].n[k] = n >= 0 && n < out.numberoftetrahedra ? n : -1;
      }
    }
    return r;
  } catch (int code) {
    return Error{"TetGen failed with code " + std::to_string(code)};
  } catch (const std::exception& e) {
    return Error{std::string("TetGen failed: ") + e.what()};
  }
}

}  // namespace kiln::detail
