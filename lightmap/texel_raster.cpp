// texel_raster.cpp: conservative UV-space rasterization by exact texel-triangle clipping
// (Sutherland-Hodgman), binned by rows and run in parallel over rows.
#include "lightmap/texel_raster.h"

#include <array>
#include <cassert>
#include <cmath>
#include <string>

namespace kiln {

namespace {

using glm::dvec2;

double cross2(dvec2 a, dvec2 b) { return a.x * b.y - a.y * b.x; }

// One triangle in page texel coordinates.
struct RasterTriangle {
  uint32_t object, triangle;
  std::array<dvec2, 3> p;    // as the mesh orders them (for barycentrics)
  std::array<dvec2, 3> ccw;  // counter-clockwise (for clipping)
  double area2;              // twice the signed area of p
  dvec2 lo, hi;
};

// Embree barycentrics (b1, b2) of q in the triangle.
dvec2 barycentrics(const RasterTriangle& t, dvec2 q) {
  const dvec2 e1 = t.p[1] - t.p[0], e2 = t.p[2] - t.p[0], d = q - t.p[0];
  return dvec2(cross2(d, e2), cross2(e1, d)) / t.area2;
}

bool inside(dvec2 b) { return b.x >= 0.0 && b.y >= 0.0 && 1.0 - b.x - b.y >= 0.0; }

// Area and centroid of the texel square [x, x+1] x [y, y+1] clipped to the triangle.
struct Piece {
  double area = 0.0;
  dvec2 centroid{0.0};
};
Piece clipTexel(const RasterTriangle& t, int x, int y) {
  // A square clipped by three half-planes has at most 7 vertices.
  std::array<dvec2, 8> a, b;
  size_t n = 4;
  a[0] = dvec2(x, y);
  a[1] = dvec2(x + 1, y);
  a[2] = dvec2(x + 1, y + 1);
  a[3] = dvec2(x, y + 1);
  for (int e = 0; e < 3 && n > 0; ++e) {
    const dvec2 p = t.ccw[e], q = t.ccw[(e + 1) % 3], edge = q - p;
    size_t m = 0;
    for (size_t i = 0; i < n; ++i) {
      const dvec2 s = a[i], u = a[(i + 1) % n];
      const double ds = cross2(edge, s - p), du = cross2(edge, u - p);
      if (ds >= 0.0) b[m++] = s;
      if ((ds >= 0.0) != (du >= 0.0) && m < b.size()) b[m++] = s + (u - s) * (ds / (ds - du));
    }
    n = m;
    a = b;
  }
  Piece piece;
  if (n < 3) return piece;
  // Shoelace area and centroid, relative to the texel corner for precision.
  const dvec2 o(x, y);
  double area2 = 0.0;
  dvec2 c(0.0);
  for (size_t i = 0; i < n; ++i) {
    const dvec2 s = a[i] - o, u = a[(i + 1) % n] - o;
    const double w = cross2(s, u);
    area2 += w;
    c += (s + u) * w;
  }
  if (!(area2 > 0.0)) return piece;
  piece.area = 0.5 * area2;
  piece.centroid = o + c / (3.0 * area2);
  return piece;
}

TexelPoint makePoint(const Scene& scene, const RasterTriangle& t, dvec2 q, dvec2 bary) {
  // Clamp rounding noise so the point stays on the triangle.
  bary = glm::max(bary, dvec2(0.0));
  if (bary.x + bary.y > 1.0) bary /= bary.x + bary.y;
  TexelPoint p;
  p.triangle = t.triangle;
  p.bary = vec2(bary);
  p.point = vec2(q);
  p.position = scene.positionAt(t.object, t.triangle, p.bary);
  p.normal = scene.shadingNormalAt(t.object, t.triangle, p.bary);
  return p;
}

// Per-texel state while a row is rasterized.
struct Accumulator {
  int32_t object = -1;
  double coverage = 0.0;
  int32_t centre = -1;  // index of the first triangle holding the centre
  dvec2 centreBary{0.0};
  int32_t best = -1;  // triangle covering the most of the texel
  double bestArea = 0.0;
  dvec2 bestCentroid{0.0};
};

struct RowOutput {
  std::vector<TexelSample> texels;
  std::vector<TexelPoint> subsamples;
};

}  // namespace

Result<std::vector<RasterPage>> rasterizeAtlas(const Scene& scene, const AtlasLayout& layout,
                                               const RasterSettings& settings) {
  if (layout.objects.size() != scene.objects.size())
    return Error{"lightmap atlas has " + std::to_string(layout.objects.size()) +
                 " objects but the scene has " + std::to_string(scene.objects.size())};
  const int n = settings.supersampling;
  if (n < 1 || n > 16)
    return Error{"supersampling must be in [1, 16] (got " + std::to_string(n) + ")"};

  if (settings.subsampleMask && settings.subsampleMask->size() != layout.pages.size())
    return Error{"subsample mask has " + std::to_string(settings.subsampleMask->size()) +
                 " pages but the atlas has " + std::to_string(layout.pages.size())};
  std::vector<RasterPage> pages(layout.pages.size());
  std::vector<std::vector<RasterTriangle>> pageTriangles(layout.pages.size());
  for (size_t i = 0; i < pages.size(); ++i) {
    pages[i].width = layout.pages[i].width;
    pages[i].height = layout.pages[i].height;
    if (pages[i].width < 1 || pages[i].height < 1)
      return Error{"lightmap " + std::to_string(i) + " has no texels"};
  }
  for (uint32_t oi = 0; oi < scene.objects.size(); ++oi) {
    const AtlasObject& ao = layout.objects[oi];
    if (ao.lightmapIndex < 0) continue;
    const Object& o = scene.objects[oi];
    if (ao.lightmapIndex >= int(pages.size()))
      return Error{"object '" + o.name + "': lightmapIndex " + std::to_string(ao.lightmapIndex) +
                   " out of range"};
    if (o.uv1.size() != o.positions.size())
      return Error{"object '" + o.name + "': has no lightmap UVs (TEXCOORD_1)"};
    const dvec2 dims(pages[size_t(ao.lightmapIndex)].width, pages[size_t(ao.lightmapIndex)].height);
    const dvec2 s(ao.scaleOffset.x, ao.scaleOffset.y), off(ao.scaleOffset.z, ao.scaleOffset.w);
    for (uint32_t t = 0; t < o.triangles.size(); ++t) {
      RasterTriangle rt;
      rt.object = oi;
      rt.triangle = t;
      for (int k = 0; k < 3; ++k) rt.p[k] = (dvec2(o.uv1[o.triangles[t][k]]) * s + off) * dims;
      rt.area2 = cross2(rt.p[1] - rt.p[0], rt.p[2] - rt.p[0]);
      if (!(std::abs(rt.area2) > 0.0)) continue;  // no area (or NaN): covers no texel
      rt.ccw = rt.p;
      if (rt.area2 < 0.0) std::swap(rt.ccw[1], rt.ccw[2]);
      rt.lo = glm::min(rt.p[0], glm::min(rt.p[1], rt.p[2]));
      rt.hi = glm::max(rt.p[0], glm::max(rt.p[1], rt.p[2]));
      pageTriangles[size_t(ao.lightmapIndex)].push_back(rt);
    }
  }

  for (size_t pi = 0; pi < pages.size(); ++pi) {
    RasterPage& page = pages[pi];
    const std::vector<RasterTriangle>& tris = pageTriangles[pi];
    const int w = page.width, h = page.height;
    // Bin triangles by the rows they touch, in (object, triangle) order.
    std::vector<std::vector<uint32_t>> rows(static_cast<size_t>(h));
    for (uint32_t i = 0; i < tris.size(); ++i) {
      const int y0 = std::max(0, int(std::floor(tris[i].lo.y)));
      const int y1 = std::min(h - 1, int(std::ceil(tris[i].hi.y)) - 1);
      for (int y = y0; y <= y1; ++y) rows[size_t(y)].push_back(i);
    }

    const std::vector<uint8_t>* mask =
        settings.subsampleMask ? &(*settings.subsampleMask)[pi] : nullptr;
    assert(!mask || mask->size() == size_t(w) * size_t(h));
    std::vector<RowOutput> out(static_cast<size_t>(h));
    auto rasterRow = [&](int y) {
      std::vector<Accumulator> acc(static_cast<size_t>(w));
      std::vector<int32_t> claim(n > 1 ? size_t(w) * n * n : 0, -1);
      std::vector<dvec2> claimBary(claim.size());
      for (uint32_t i : rows[size_t(y)]) {
        const RasterTriangle& t = tris[i];
        const int x0 = std::max(0, int(std::floor(t.lo.x)));
        const int x1 = std::min(w - 1, int(std::ceil(t.hi.x)) - 1);
        for (int x = x0; x <= x1; ++x) {
          const Piece piece = clipTexel(t, x, y);
          // Touching along an edge or at a corner is not covering.
          if (!(piece.area > 1e-12)) continue;
          Accumulator& a = acc[size_t(x)];
          if (a.object >= 0 && a.object != int32_t(t.object)) {
            assert(false && "two objects on one texel: the atlas padding should prevent this");
            continue;  // keep the first object
          }
          a.object = int32_t(t.object);
          a.coverage += piece.area;
          if (a.centre < 0) {
            const dvec2 b = barycentrics(t, dvec2(x + 0.5, y + 0.5));
            if (inside(b)) {
              a.centre = int32_t(i);
              a.centreBary = b;
            }
          }
          if (piece.area > a.bestArea) {
            a.best = int32_t(i);
            a.bestArea = piece.area;
            a.bestCentroid = piece.centroid;
          }
          const bool grid = n > 1 && (!mask || (*mask)[size_t(y) * w + x]);
          for (int j = 0; j < n * n && grid; ++j) {
            const size_t c = size_t(x) * n * n + j;
            if (claim[c] >= 0) continue;
            const dvec2 q(x + (j % n + 0.5) / n, y + (j / n + 0.5) / n);
            const dvec2 b = barycentrics(t, q);
            if (inside(b)) {
              claim[c] = int32_t(i);
              claimBary[c] = b;
            }
          }
        }
      }
      RowOutput& row = out[size_t(y)];
      row.texels.resize(size_t(w));
      for (int x = 0; x < w; ++x) {
        const Accumulator& a = acc[size_t(x)];
        if (a.object < 0) continue;
        TexelSample& s = row.texels[size_t(x)];
        s.object = a.object;
        s.coverage = float(std::min(1.0, a.coverage));
        if (a.centre >= 0) {
          s.sample =
              makePoint(scene, tris[size_t(a.centre)], dvec2(x + 0.5, y + 0.5), a.centreBary);
        } else {
          const RasterTriangle& t = tris[size_t(a.best)];
          s.sample = makePoint(scene, t, a.bestCentroid, barycentrics(t, a.bestCentroid));
        }
        s.firstSubsample = uint32_t(row.subsamples.size());
        for (int j = 0; j < n * n && n > 1; ++j) {
          const size_t c = size_t(x) * n * n + j;
          if (claim[c] < 0) continue;
          const dvec2 q(x + (j % n + 0.5) / n, y + (j / n + 0.5) / n);
          row.subsamples.push_back(makePoint(scene, tris[size_t(claim[c])], q, claimBary[c]));
        }
        s.subsampleCount = uint32_t(row.subsamples.size()) - s.firstSubsample;
      }
    };
    const bool finished = parallelFor(
        size_t(h),
        [&](size_t begin, size_t end) {
          for (size_t y = begin; y < end; ++y) rasterRow(int(y));
        },
        settings.parallel);
    if (!finished) return Error{"lightmap rasterization cancelled"};

    // Stitch the rows together in order.
    page.texels.reserve(size_t(w) * size_t(h));
    for (int y = 0; y < h; ++y) {
      RowOutput& row = out[size_t(y)];
      const uint32_t base = uint32_t(page.subsamples.size());
      for (TexelSample& s : row.texels) {
        if (s.valid()) s.firstSubsample += base;
        page.texels.push_back(s);
      }
      page.subsamples.insert(page.subsamples.end(), row.subsamples.begin(), row.subsamples.end());
      row = RowOutput();
    }
  }
  return pages;
}

}  // namespace kiln
