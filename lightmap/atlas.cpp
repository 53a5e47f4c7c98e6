// atlas.cpp: lightmap atlas packing (texel density rule, skyline packing into pages shrunk
// to the smallest multiple-of-4 size) and its manifest form for --lock-atlas.
#include "lightmap/atlas.h"

#include <algorithm>
#include <array>
#include <climits>
#include <cmath>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lightmap/chart_packer.h"
#include "lightmap/manifest.h"
#include "lightmap/uv_unwrap.h"
#include "lightmap/skyline_packer.h"
#include "src/progress.h"

namespace kiln {

namespace {

std::string describe(const Object& o) {
  return "object '" + o.name + "' (nodeIndex " + std::to_string(o.nodeIndex) + ")";
}

// Rounds texel extents up, tolerating float noise on exact integers.
int texelsUp(double x) { return std::max(1, int(std::ceil(x - 1e-4))); }

// UV1 triangle area (sum of |areas|) and world area, in double.
struct AreaPair {
  double uv = 0.0, world = 0.0;
};
AreaPair areas(const Object& o) {
  AreaPair a;
  for (uint32_t t = 0; t < o.triangles.size(); ++t) {
    const uvec3 tri = o.triangles[t];
    const glm::dvec2 u0(o.uv1[tri.x]), u1(o.uv1[tri.y]), u2(o.uv1[tri.z]);
    const glm::dvec2 e1 = u1 - u0, e2 = u2 - u0;
    a.uv += 0.5 * std::abs(e1.x * e2.y - e1.y * e2.x);
    const glm::dvec3 p0(o.positions[tri.x]), p1(o.positions[tri.y]), p2(o.positions[tri.z]);
    a.world += 0.5 * glm::length(glm::cross(p1 - p0, p2 - p0));
  }
  return a;
}

// Texels per UV1 unit of an object whose UV1 bounding rectangle has extent (eu, ev): `k`,
// scaled down when the rectangle's longer side would exceed `limit` texels.
double texelsPerUv(double k, double eu, double ev, int limit) {
  if (std::max(texelsUp(k * eu), texelsUp(k * ev)) > limit)
    k *= double(limit) / std::max(k * eu, k * ev);
  return k;
}

// Page sides are multiples of this (block-compressed formats such as BC6H and ASTC 4x4 need
// whole 4 x 4 blocks), or maxSize itself.
constexpr int kPageAlign = 4;

// A page side of at least x texels: rounded up to kPageAlign, at most maxSize.
int pageSide(int x, int maxSize) {
  return std::min(maxSize, (x + kPageAlign - 1) / kPageAlign * kPageAlign);
}

// The page that holds packed content spanning w x h texels with `padding` empty texels
// around it (pageSide on each side).
glm::ivec2 paddedPage(int w, int h, int padding, int maxSize) {
  return glm::ivec2(pageSide(w + 2 * padding, maxSize), pageSide(h + 2 * padding, maxSize));
}

// The chart packer's cost of content spanning w x h texels (ChartPackOptions::cost): the area
// of its padded page; INT64_MAX when it is too tall for a page of maxSize.
std::function<int64_t(int, int)> paddedPageArea(int padding, int maxSize) {
  return [padding, maxSize](int w, int h) -> int64_t {
    if (h + 2 * padding > maxSize) return INT64_MAX;
    const glm::ivec2 page = paddedPage(w, h, padding, maxSize);
    return int64_t(page.x) * page.y;
  };
}

// The smallest page (by area; ties: the squarer, then the earlier order) that holds `items`,
// padded as packPage pads: for each of four insertion orders (the given one, then by width,
// by area and by longer side, all descending with ties by index) and each candidate width
// (multiples of kPageAlign from the items' area bound up to maxSize, at most 128), the
// skyline's used height gives the height. `items` is left in the order that won.
glm::ivec2 smallestPage(int maxSize, int padding, std::vector<uint32_t>& items,
                        const std::vector<glm::ivec2>& sizes) {
  double area = 0.0;
  int widest = 1;
  std::vector<glm::ivec2> padded(sizes.size());
  for (uint32_t i : items) {
    padded[i] = sizes[i] + glm::ivec2(padding);
    area += double(padded[i].x) * double(padded[i].y);
    widest = std::max(widest, padded[i].x + padding);
  }
  const std::vector<int> widths =
      candidateWidths(std::max(widest, int(std::sqrt(area) / 2.0)), maxSize, kPageAlign, 128);
  std::vector<int> bins;
  for (int w : widths) bins.push_back(w - padding);
  auto key = [&](int order, uint32_t i) -> int64_t {
    const glm::ivec2 s = sizes[i];
    return order == 1 ? s.x : order == 2 ? int64_t(s.x) * s.y : std::max(s.x, s.y);
  };
  glm::ivec2 best(maxSize);
  std::vector<uint32_t> bestOrder = items;
  for (int order = 0; order < 4; ++order) {
    std::vector<uint32_t> trial = items;
    if (order > 0)
      std::sort(trial.begin(), trial.end(), [&](uint32_t a, uint32_t b) {
        return key(order, a) != key(order, b) ? key(order, a) > key(order, b) : a < b;
      });
    const auto packed = packSmallest(padded, trial, bins, maxSize - padding, [&](int w, int used) {
      return glm::ivec2(w + padding, pageSide(used + padding, maxSize));
    });
    if (!packed) continue;
    const int64_t a = int64_t(packed->page.x) * packed->page.y, b = int64_t(best.x) * best.y;
    if (a < b || (a == b && order == 0)) {
      best = packed->page;
      bestOrder = trial;
    }
  }
  items = bestOrder;
  return best;
}

// Packs `items` (indices into `sizes`, in order) into a bin of page size `page` with padding
// p: the bin is (W - p) x (H - p) and items are (w + p) x (h + p), placed at p + corner.
// Returns false when one does not fit.
bool packPage(glm::ivec2 page, int padding, const std::vector<uint32_t>& items,
              const std::vector<glm::ivec2>& sizes, std::vector<glm::ivec2>& corners) {
  if (page.x - padding < 1 || page.y - padding < 1) return false;
  SkylinePacker packer(page.x - padding, page.y - padding);
  for (uint32_t i : items) {
    const auto at = packer.insert(sizes[i].x + padding, sizes[i].y + padding);
    if (!at) return false;
    corners[i] = *at + glm::ivec2(padding);
  }
  return true;
}

// Maps [lo, hi] onto the texel rectangle inset by kInset texels on every side: pages need not
// be powers of two, so 1 / width is not exact in float, and a UV on the rectangle's edge could
// otherwise land a hair beyond it, where the conservative rasterizer would give a texel of
// the padding a sliver of the object.
constexpr double kInset = 5e-4;

vec4 scaleOffsetFor(vec2 lo, vec2 hi, glm::ivec2 texelMin, glm::ivec2 texelSize, AtlasPage page) {
  const double sx = (texelSize.x - 2.0 * kInset) / ((double(hi.x) - lo.x) * page.width);
  const double sy = (texelSize.y - 2.0 * kInset) / ((double(hi.y) - lo.y) * page.height);
  const double ox = (texelMin.x + kInset) / page.width - lo.x * sx;
  const double oy = (texelMin.y + kInset) / page.height - lo.y * sy;
  return vec4(float(sx), float(sy), float(ox), float(oy));
}

// The texels an object covers in its texel rectangle of `size`: its UV1 triangles mapped as
// scaleOffsetFor maps them (chart_packer.h footprintInFrame).
ChartFootprint objectFootprint(const Object& o, std::pair<vec2, vec2> bounds, glm::ivec2 size) {
  const glm::dvec2 lo(bounds.first), hi(bounds.second);
  const glm::dvec2 scale = (glm::dvec2(size) - 2.0 * kInset) / (hi - lo);
  std::vector<std::array<glm::dvec2, 3>> triangles(o.triangles.size());
  for (size_t t = 0; t < o.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      triangles[t][size_t(k)] = (glm::dvec2(o.uv1[o.triangles[t][k]]) - lo) * scale + kInset;
  return footprintInFrame(triangles, size);
}

// The page's objects packed by their shape (chart_packer.h: each object's covered texels per
// column, dropped where its top ends lowest, upright only since one scale and offset cannot
// turn it) with `padding` empty texels between the covered texels of two objects and to the
// page's border. An L-shaped or ragged object (charts packed by shape leave a ragged top)
// lends its hollows to the next ones, which rectangles cannot. nullopt when no packing fits
// maxSize; else the page and each member's rectangle corner.
std::optional<std::pair<glm::ivec2, std::vector<glm::ivec2>>> shapePage(
    int maxSize, int padding, const std::vector<uint32_t>& members,
    const std::vector<ChartFootprint>& footprints) {
  std::vector<ChartFootprint> shapes;
  for (uint32_t i : members) shapes.push_back(footprints[i]);
  ChartPackOptions options;
  options.rigid.assign(shapes.size(), true);
  options.maxWidth = maxSize - 2 * padding;
  options.cost = paddedPageArea(padding, maxSize);
  const ChartPacking packed = packCharts(shapes, {}, padding, options);
  if (packed.size.x <= 0 || packed.size.y + 2 * padding > maxSize) return std::nullopt;
  std::vector<glm::ivec2> corners(members.size());
  for (size_t m = 0; m < members.size(); ++m) corners[m] = packed.corners[m] + glm::ivec2(padding);
  return std::make_pair(paddedPage(packed.size.x, packed.size.y, padding, maxSize), corners);
}

}  // namespace

bool isLightmapped(const Object& object) {
  return object.settings.isStatic && object.settings.scaleInLightmap > 0.0f &&
         object.settings.receiveGI == ReceiveGI::Lightmaps && !object.triangles.empty();
}

double lightmapTexels(const Object& object, float resolution) {
  const double density = double(resolution) * object.settings.scaleInLightmap;
  double area = 0.0;
  for (uint32_t t = 0; t < object.triangles.size(); ++t) area += object.triangleArea(t);
  return density * density * area;
}

double lightmappedArea(const Scene& scene) {
  double area = 0.0;
  for (const Object& o : scene.objects)
    if (isLightmapped(o))
      for (uint32_t t = 0; t < o.triangles.size(); ++t) area += o.triangleArea(t);
  return area;
}

bool chartsTooThin(double surfaceTexels, double coveredTexels) {
  return coveredTexels > 0.0 && surfaceTexels < kAutoThinCoverage * coveredTexels;
}

bool tooSmallForLightmap(const Object& object, float resolution, float minTexels,
                         double sceneArea) {
  const double texels = lightmapTexels(object, resolution);
  if (minTexels >= 0.0f) return minTexels > 0.0f && texels < double(minTexels);
  if (object.thinCharts && object.uv1.size() != object.positions.size()) return true;
  const double density = double(resolution) * object.settings.scaleInLightmap;
  return object.uv1.size() != object.positions.size() &&
         texels < double(kAutoObjectTexelsPerUnit) * resolution &&
         texels / (density * density) < kAutoObjectAreaShare * sceneArea;
}

std::pair<vec2, vec2> uv1Bounds(const Object& object) {
  vec2 lo(kInfinity), hi(-kInfinity);
  for (const uvec3& tri : object.triangles)
    for (int k = 0; k < 3; ++k) {
      lo = glm::min(lo, object.uv1[tri[k]]);
      hi = glm::max(hi, object.uv1[tri[k]]);
    }
  return {lo, hi};
}

Status checkTexelBudget(const std::vector<AtlasPage>& pages, const std::string& what) {
  uint64_t texels = 0;
  for (const AtlasPage& page : pages) texels += uint64_t(page.width) * uint64_t(page.height);
  if (texels > kMaxLightmapTexels)
    return Error{what + ": " + std::to_string(pages.size()) + " page(s) of " +
                 std::to_string(texels) + " texels in all, more than the budget of " +
                 std::to_string(kMaxLightmapTexels) +
                 " (docs/limits.md): lower the resolution or maxSize"};
  return Status::success();
}

Result<AtlasLayout> packAtlas(const Scene& scene, const AtlasSettings& settings) {
  const int p = settings.padding;
  if (p < 0) return Error{"lightmap padding must be >= 0 (got " + std::to_string(p) + ")"};
  if (!(settings.resolution > 0.0f) || !std::isfinite(settings.resolution))
    return Error{"lightmap resolution must be > 0 texels per unit (got " +
                 std::to_string(settings.resolution) + ")"};
  if (!std::isfinite(settings.minObjectTexels))
    return Error{"minObjectTexels must be a finite number (got " +
                 std::to_string(settings.minObjectTexels) + ")"};
  if (settings.maxSize < 1 + 2 * p)
    return Error{"lightmap maxSize " + std::to_string(settings.maxSize) +
                 " cannot hold one texel with padding " + std::to_string(p) +
                 " on each side (needs maxSize >= 1 + 2 x padding = " + std::to_string(1 + 2 * p) +
                 ")"};

  if (settings.locked) {
    const AtlasLayout& locked = *settings.locked;
    if (locked.objects.size() != scene.objects.size())
      return Error{"locked atlas has " + std::to_string(locked.objects.size()) +
                   " objects, the scene " + std::to_string(scene.objects.size())};
    for (size_t i = 0; i < scene.objects.size(); ++i) {
      const int page = locked.objects[i].lightmapIndex;
      if (isLightmapped(scene.objects[i]) != (page >= 0 || locked.objects[i].probeLit))
        return Error{"locked atlas: " + describe(scene.objects[i]) +
                     (page >= 0 ? " has a lightmap in the locked atlas but is not lightmapped"
                                : " is lightmapped but has no lightmap in the locked atlas")};
      if (page >= int(locked.pages.size()))
        return Error{"locked atlas: " + describe(scene.objects[i]) + ": lightmapIndex " +
                     std::to_string(page) + " out of range"};
    }
    if (Status budget = checkTexelBudget(locked.pages, "locked atlas"); !budget)
      return Error{budget.error()};
    return locked;
  }

  AtlasLayout layout;
  layout.objects.resize(scene.objects.size());
  const int limit = settings.maxSize - 2 * p;  // largest object side, texels
  std::vector<uint32_t> lightmapped;
  std::vector<glm::ivec2> sizes(scene.objects.size(), glm::ivec2(0));
  std::vector<std::pair<vec2, vec2>> bounds(scene.objects.size());
  std::vector<std::string> probeLit, thin;
  const double sceneArea = lightmappedArea(scene);
  for (uint32_t i = 0; i < scene.objects.size(); ++i) {
    const Object& o = scene.objects[i];
    if (!isLightmapped(o)) continue;
    if (tooSmallForLightmap(o, settings.resolution, settings.minObjectTexels, sceneArea)) {
      layout.objects[i].probeLit = true;
      (o.thinCharts && settings.minObjectTexels < 0.0f ? thin : probeLit)
          .push_back("'" + o.name + "'");
      continue;
    }
    if (o.uv1.size() != o.positions.size())
      return Error{describe(o) + ": has no lightmap UVs (TEXCOORD_1); generate them first"};
    bounds[i] = uv1Bounds(o);
    const auto [lo, hi] = bounds[i];
    const AreaPair a = areas(o);
    if (!(a.uv > 0.0) || !(hi.x > lo.x) || !(hi.y > lo.y) || !std::isfinite(a.uv))
      return Error{describe(o) + ": its lightmap UVs (TEXCOORD_1) have zero area"};
    // Texels per UV unit so that the triangles get (resolution x scale)^2 x world area texels.
    const double density = double(settings.resolution) * o.settings.scaleInLightmap;
    const bool generated = i < settings.worldPerUv.size() && settings.worldPerUv[i] > 0.0;
    const double worldPerUv = generated ? settings.worldPerUv[i] : std::sqrt(a.world / a.uv);
    const double eu = double(hi.x) - lo.x, ev = double(hi.y) - lo.y;
    const double k = texelsPerUv(density * worldPerUv, eu, ev, limit);
    glm::ivec2 size(texelsUp(k * eu), texelsUp(k * ev));
    if (k != density * worldPerUv) {
      size = glm::min(size, glm::ivec2(limit));
      std::ostringstream w;
      w << describe(o) << ": lightmap scaled down to " << size.x << " x " << size.y
        << " texels to fit maxSize " << settings.maxSize << " with padding " << p << " ("
        << k / worldPerUv << " instead of " << density << " texels per unit)";
      layout.warnings.push_back(w.str());
    }
    sizes[i] = size;
    layout.objects[i].texelSize = size;
    layout.objects[i].texelsPerUnit = float(k / worldPerUv);
    lightmapped.push_back(i);
  }

  // The first 20 names of a warning's list, then how many more.
  auto listNames = [](const std::vector<std::string>& names) {
    std::string text;
    const size_t shown = std::min<size_t>(names.size(), 20);
    for (size_t k = 0; k < shown; ++k) text += (k ? ", " : "") + names[k];
    if (shown < names.size()) text += " and " + std::to_string(names.size() - shown) + " more";
    return text;
  };
  if (!probeLit.empty()) {
    std::ostringstream w;
    w << probeLit.size() << " object(s) would get fewer than ";
    if (settings.minObjectTexels >= 0.0f)
      w << settings.minObjectTexels;
    else
      w << kAutoObjectTexelsPerUnit * settings.resolution;
    w << " lightmap texels at " << settings.resolution
      << " texels per unit and are lit by probes instead (manifest: \"probeLit\"; "
      << "--min-object-texels 0 gives every object a lightmap): ";
    layout.warnings.push_back(w.str() + listNames(probeLit));
  }
  if (!thin.empty()) {
    std::ostringstream w;
    w << thin.size() << " object(s) have charts too thin for a lightmap at "
      << settings.resolution << " texels per unit (their surface fills under "
      << kAutoThinCoverage * 100.0 << "% of the texels their charts touch) and are lit by "
      << "probes instead (manifest: \"probeLit\"; --min-object-texels 0 gives every object a "
      << "lightmap): ";
    layout.warnings.push_back(w.str() + listNames(thin));
  }

  // The texel budget, before packing and before anything the size of a page is allocated:
  // the objects' padded rectangles are a lower bound of the pages' area.
  {
    uint64_t texels = 0;
    for (uint32_t i : lightmapped) texels += uint64_t(sizes[i].x + p) * uint64_t(sizes[i].y + p);
    if (texels > kMaxLightmapTexels)
      return Error{"lightmap resolution " + std::to_string(settings.resolution) +
                   " texels per unit needs at least " + std::to_string(texels) +
                   " texels, more than the budget of " + std::to_string(kMaxLightmapTexels) +
                   " (docs/limits.md): lower the resolution or scaleInLightmap"};
  }

  // Fill maxSize pages in packing order; then shrink each page.
  std::vector<glm::ivec2> sortKey(lightmapped.size());
  for (size_t j = 0; j < lightmapped.size(); ++j) sortKey[j] = sizes[lightmapped[j]];
  std::vector<uint32_t> remaining;
  for (uint32_t j : packingOrder(sortKey)) remaining.push_back(lightmapped[j]);
  std::vector<glm::ivec2> corners(scene.objects.size());
  std::vector<ChartFootprint> footprints(scene.objects.size());
  Progress progress("atlas", lightmapped.size(), "objects",
                    settings.showProgress && !lightmapped.empty());
  while (!remaining.empty()) {
    if (settings.cancel && settings.cancel->load()) return Error{"cancelled"};
    SkylinePacker packer(settings.maxSize - p, settings.maxSize - p);
    std::vector<uint32_t> members, rest;
    for (uint32_t i : remaining) {
      if (packer.insert(sizes[i].x + p, sizes[i].y + p))
        members.push_back(i);
      else
        rest.push_back(i);
    }
    if (members.empty())  // cannot happen: sizes are clamped to fit an empty page
      return Error{describe(scene.objects[remaining.front()]) + ": does not fit a lightmap page"};
    glm::ivec2 best = smallestPage(settings.maxSize, p, members, sizes);
    const bool packed = packPage(best, p, members, sizes, corners);
    assert(packed);  // smallestPage found it by this very packing (or maxSize, which holds all)
    (void)packed;
    // Shapes instead of rectangles, when that gives a smaller page.
    if (members.size() > 1) {
      for (uint32_t i : members)
        if (footprints[i].columns == 0)
          footprints[i] = objectFootprint(scene.objects[i], bounds[i], sizes[i]);
      if (const auto shaped = shapePage(settings.maxSize, p, members, footprints);
          shaped && int64_t(shaped->first.x) * shaped->first.y < int64_t(best.x) * best.y) {
        best = shaped->first;
        for (size_t m = 0; m < members.size(); ++m) corners[members[m]] = shaped->second[m];
      }
    }
    AtlasPage page{best.x, best.y};
    const int index = int(layout.pages.size());
    layout.pages.push_back(page);
    for (uint32_t i : members) {
      AtlasObject& ao = layout.objects[i];
      ao.lightmapIndex = index;
      ao.texelMin = corners[i];
      ao.scaleOffset =
          scaleOffsetFor(bounds[i].first, bounds[i].second, ao.texelMin, ao.texelSize, page);
    }
    remaining = std::move(rest);
    progress.advance(members.size());
  }
  progress.finish();
  // Pages may exceed the objects' area (skyline waste, alignment to 4 texels).
  if (Status budget = checkTexelBudget(layout.pages, "lightmap pages"); !budget)
    return Error{budget.error()};
  return layout;
}

Status packChartsIntoPages(Scene& scene, AtlasLayout& layout, const AtlasSettings& settings,
                           std::vector<std::optional<UnwrapResult>>& unwraps) {
  const int p = settings.padding, gutter = std::max(1, p);
  const int limit = settings.maxSize - 2 * p;
  auto generated = [&](uint32_t i) {
    return i < unwraps.size() && unwraps[i].has_value() &&
           unwraps[i]->uv1.size() == scene.objects[i].uv1.size();
  };
  const vec4 identity(1.0f, 1.0f, 0.0f, 0.0f);
  for (int page = 0; page < int(layout.pages.size()); ++page) {
    if (settings.cancel && settings.cancel->load()) return Error{"cancelled"};
    std::vector<uint32_t> members;
    bool anyGenerated = false, allIdentity = true;
    for (uint32_t i = 0; i < layout.objects.size(); ++i) {
      if (layout.objects[i].lightmapIndex != page) continue;
      members.push_back(i);
      if (!generated(i)) continue;
      anyGenerated = true;
      allIdentity = allIdentity && layout.objects[i].scaleOffset == identity;
    }
    // A locked page is chart-packed when its generated objects have identity scaleOffsets
    // (packAtlas's rectangles never do: they are inset).
    if (!anyGenerated || (settings.locked && !allIdentity)) continue;

    // One item per chart of a generated object (triangles in texels at the object's density,
    // moved to the origin), one rigid item per other object (its footprint in its rectangle).
    struct Item {
      uint32_t object = 0;
      uint32_t chart = 0;  // generated objects: UnwrapResult::triangleChart
      glm::dvec2 min{0.0}, extent{0.0};
    };
    std::vector<Item> items;
    std::vector<ChartFootprint> upright, quarter;
    std::vector<bool> rigid;
    std::map<std::pair<uint32_t, uint32_t>, size_t> itemOf;  // (object, chart) -> item
    std::vector<double> scale(layout.objects.size(), 0.0);
    for (uint32_t i : members) {
      const Object& o = scene.objects[i];
      const auto bounds = uv1Bounds(o);
      if (!generated(i)) {
        items.push_back({i, 0, glm::dvec2(0.0), glm::dvec2(layout.objects[i].texelSize)});
        upright.push_back(objectFootprint(o, bounds, layout.objects[i].texelSize));
        quarter.push_back(upright.back());
        rigid.push_back(true);
        continue;
      }
      const UnwrapResult& u = *unwraps[i];
      const double density = double(settings.resolution) * o.settings.scaleInLightmap;
      scale[i] = texelsPerUv(density * u.worldPerUv, double(bounds.second.x) - bounds.first.x,
                             double(bounds.second.y) - bounds.first.y, limit);
      std::map<uint32_t, std::vector<std::array<glm::dvec2, 3>>> charts;
      for (uint32_t t = 0; t < o.triangles.size(); ++t) {
        if (u.triangleChart[t] >= uint32_t(u.stats.chartCount)) continue;  // degenerate
        std::array<glm::dvec2, 3> tri;
        for (int k = 0; k < 3; ++k)
          tri[size_t(k)] = glm::dvec2(o.uv1[o.triangles[t][k]]) * scale[i];
        charts[u.triangleChart[t]].push_back(tri);
      }
      for (auto& [chart, tris] : charts) {
        Item item{i, chart, glm::dvec2(1e300), glm::dvec2(0.0)};
        glm::dvec2 hi(-1e300);
        for (const auto& tri : tris)
          for (const glm::dvec2& q : tri) {
            item.min = glm::min(item.min, q);
            hi = glm::max(hi, q);
          }
        item.extent = hi - item.min;
        for (auto& tri : tris)
          for (glm::dvec2& q : tri) q -= item.min;
        upright.push_back(chartFootprint(tris, item.extent));
        for (auto& tri : tris)
          for (glm::dvec2& q : tri) q = glm::dvec2(item.extent.y - q.y, q.x);
        quarter.push_back(chartFootprint(tris, glm::dvec2(item.extent.y, item.extent.x)));
        rigid.push_back(false);
        itemOf[{i, chart}] = items.size();
        items.push_back(item);
      }
    }
    ChartPackOptions options;
    options.rigid = rigid;
    options.maxWidth = limit;
    options.fromWidest = true;
    options.cost = paddedPageArea(p, settings.maxSize);
    const ChartPacking packed = packCharts(upright, quarter, gutter, options);
    const AtlasPage before = layout.pages[size_t(page)];
    const bool fits = packed.size.x > 0 && packed.size.y <= limit;
    const glm::ivec2 size =
        fits ? paddedPage(packed.size.x, packed.size.y, p, settings.maxSize) : glm::ivec2(0);
    if (settings.locked) {
      if (size != glm::ivec2(before.width, before.height))
        return Error{"locked atlas: lightmap " + std::to_string(page) +
                     "'s charts no longer pack into its " + std::to_string(before.width) +
                     " x " + std::to_string(before.height) +
                     " texels (did the geometry, its lights or the atlas settings change?)"};
    } else if (!fits || int64_t(size.x) * size.y >= int64_t(before.width) * before.height) {
      continue;  // the objects' rectangles packed it as well
    }
    const AtlasPage after{size.x, size.y};
    // Where a point of item j (texels relative to the item's min) lands in the page:
    // turned as the packer chose (rotations: the orientation is kept), as uv_unwrap.cpp does.
    auto pagePoint = [&](size_t j, glm::dvec2 q) {
      const Item& item = items[j];
      if (packed.quarter[j]) q = glm::dvec2(item.extent.y - q.y, q.x);
      const ChartFootprint& f = packed.quarter[j] ? quarter[j] : upright[j];
      q += f.offset;
      return glm::dvec2(packed.corners[j] + glm::ivec2(p)) +
             (packed.turned[j] ? glm::dvec2(f.columns, f.rows) - q : q);
    };
    for (size_t j = 0; j < items.size(); ++j) {
      if (!rigid[j]) continue;
      AtlasObject& ao = layout.objects[items[j].object];
      const glm::ivec2 corner = packed.corners[j] + glm::ivec2(p);
      if (settings.locked && corner != ao.texelMin)
        return Error{"locked atlas: " + describe(scene.objects[items[j].object]) +
                     " no longer packs where the manifest puts it"};
      ao.texelMin = corner;
      ao.scaleOffset = scaleOffsetFor(uv1Bounds(scene.objects[items[j].object]).first,
                                      uv1Bounds(scene.objects[items[j].object]).second,
                                      ao.texelMin, ao.texelSize, after);
    }
    for (uint32_t i : members) {
      if (!generated(i)) continue;
      Object& o = scene.objects[i];
      UnwrapResult& u = *unwraps[i];
      std::vector<vec2> uv(o.uv1.size(), vec2(-1.0f));
      glm::dvec2 lo(1e300), hi(-1e300);
      for (uint32_t t = 0; t < o.triangles.size(); ++t) {
        const auto found = itemOf.find({i, u.triangleChart[t]});
        if (found == itemOf.end()) continue;  // degenerate: below
        for (int k = 0; k < 3; ++k) {
          const uint32_t v = o.triangles[t][k];
          const glm::dvec2 q = pagePoint(
              found->second, glm::dvec2(o.uv1[v]) * scale[i] - items[found->second].min);
          lo = glm::min(lo, q);
          hi = glm::max(hi, q);
          uv[v] = vec2(q / glm::dvec2(after.width, after.height));
        }
      }
      // Degenerate triangles (no area, no texels) collapse onto a point of the object.
      const vec2 anchor = vec2(lo / glm::dvec2(after.width, after.height));
      for (vec2& x : uv)
        if (x.x < 0.0f) x = anchor;
      o.uv1 = uv;
      u.uv1 = uv;
      AtlasObject& ao = layout.objects[i];
      ao.scaleOffset = identity;
      ao.texelMin = glm::ivec2(glm::floor(lo));
      ao.texelSize = glm::ivec2(glm::ceil(hi)) - ao.texelMin;
      ao.texelsPerUnit = float(scale[i] / u.worldPerUv);
    }
    layout.pages[size_t(page)] = after;
  }
  return Status::success();
}

nlohmann::json atlasToJson(const AtlasLayout& layout, const Scene& scene) {
  const nlohmann::json manifest = manifestJson(atlasManifest(layout, scene));
  return {{"lightmaps", manifest["lightmaps"]}, {"objects", manifest["objects"]}};
}

Result<AtlasLayout> atlasFromManifest(const nlohmann::json& manifest, const Scene& scene) {
  const std::string where = "lock-atlas manifest";
  Result<Manifest> read = readManifest(manifest, where, ManifestUse::kAtlas);
  if (!read) return Error{read.error()};
  return atlasFromManifest(*read, scene, where);
}

Result<AtlasLayout> atlasFromManifest(const Manifest& manifest, const Scene& scene,
                                      const std::string& where) {
  // readManifest checked the manifest by itself (sizes, indices, finite scaleOffset, each
  // node listed once); what is left is whether it fits `scene`.
  AtlasLayout layout;
  for (const ManifestPage& p : manifest.lightmaps) layout.pages.push_back({p.width, p.height});
  std::map<int, uint32_t> byNode;
  for (uint32_t i = 0; i < scene.objects.size(); ++i) byNode[scene.objects[i].nodeIndex] = i;
  layout.objects.resize(scene.objects.size());
  for (size_t e = 0; e < manifest.objects.size(); ++e) {
    const ManifestObject& mo = manifest.objects[e];
    const std::string at = where + ": objects[" + std::to_string(e) + "]";
    const auto found = byNode.find(mo.nodeIndex);
    if (found == byNode.end())
      return Error{at + ": node '" + mo.node + "' (nodeIndex " + std::to_string(mo.nodeIndex) +
                   ") has no mesh object in the scene"};
    const uint32_t i = found->second;
    const Object& o = scene.objects[i];
    if (mo.node != o.name)
      return Error{at + ": nodeIndex " + std::to_string(mo.nodeIndex) + " is '" + mo.node +
                   "' in the manifest but '" + o.name + "' in the scene"};
    const int page = mo.lightmapIndex;
    if (mo.probeLit) {
      if (!isLightmapped(o))
        return Error{at + ": " + describe(o) +
                     " is probe-lit in the manifest but is not lightmapped in the scene"};
      layout.objects[i].probeLit = true;
    }
    if (page < 0) continue;
    if (!isLightmapped(o))
      return Error{at + ": " + describe(o) +
                   " has a lightmap in the manifest but is not lightmapped in the scene "
                   "(static, scaleInLightmap or receiveGI changed)"};
    if (o.uv1.size() != o.positions.size() && o.thinCharts)
      return Error{at + ": " + describe(o) + " has a lightmap in the manifest, but its " +
                   "generated charts are too thin for one and it is lit by probes now " +
                   "(--min-object-texels 0 gives every object a lightmap)"};
    if (o.uv1.size() != o.positions.size())
      return Error{at + ": " + describe(o) + " has no lightmap UVs (TEXCOORD_1)"};
    AtlasObject& ao = layout.objects[i];
    ao.lightmapIndex = page;
    ao.scaleOffset = mo.scaleOffset;
    const AtlasPage pg = layout.pages[size_t(page)];
    const auto [lo, hi] = uv1Bounds(o);
    const glm::dvec2 s(ao.scaleOffset.x, ao.scaleOffset.y), off(ao.scaleOffset.z, ao.scaleOffset.w);
    const glm::dvec2 dims(pg.width, pg.height);
    const glm::dvec2 a = (glm::dvec2(lo) * s + off) * dims, b = (glm::dvec2(hi) * s + off) * dims;
    // The texel rectangle in double, checked against the page before it becomes integers (a
    // hostile scaleOffset would overflow int).
    const glm::dvec2 texelMin = glm::round(a), texelSize = glm::round(b - a);
    if (!(texelMin.x >= 0.0 && texelMin.y >= 0.0 && texelSize.x >= 1.0 && texelSize.y >= 1.0 &&
          texelMin.x + texelSize.x <= dims.x && texelMin.y + texelSize.y <= dims.y))
      return Error{at + ": " + describe(o) + ": scaleOffset puts its UV1 rectangle outside " +
                   "lightmap " + std::to_string(page) + " (did its TEXCOORD_1 change?)"};
    ao.texelMin = glm::ivec2(texelMin);
    ao.texelSize = glm::ivec2(texelSize);
    const AreaPair ar = areas(o);
    ao.texelsPerUnit = ar.world > 0.0 ? float(s.x * dims.x * std::sqrt(ar.uv / ar.world)) : 0.0f;
  }
  for (uint32_t i = 0; i < scene.objects.size(); ++i)
    if (isLightmapped(scene.objects[i]) && layout.objects[i].lightmapIndex < 0 &&
        !layout.objects[i].probeLit)
      return Error{where + ": " + describe(scene.objects[i]) +
                   " is lightmapped but the manifest gives it no lightmap"};
  return layout;
}

}  // namespace kiln
