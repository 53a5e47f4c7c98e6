// reference_compare.cpp: see reference_compare.h.
#include "tools/lightmap_compare/reference_compare.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lightmap/manifest.h"
#include "src/image.h"
#include "src/math.h"
#include "src/text_file.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

// The mean of kiln's texels over one reference texel's footprint, the UV square
// [x, x + 1] / W x [y, y + 1] / H mapped through scaleOffset: kFootprintSamples^2 lookups of
// the nearest kiln texel on a regular grid, i.e. kiln's texels weighted by their overlap with
// the footprint. A kiln texel holds the mean E/pi over its own (smaller) footprint, and a
// reference texel the mean over its footprint (Cycles jitters its samples over the texel,
// README), so both sides are then the same quantity. kiln's value at the footprint's centre
// would count the difference between a box filter and a point sample as error, which where
// the footprint is partly hidden (a block's foot, the ceiling around the lamp) or crosses a
// shadow edge is a large part of the value. The reference compared with itself stays exact.
constexpr int kFootprintSamples = 8;

vec3 sampleFootprint(const Image& atlas, const Image* coverage, int x, int y, int w, int h,
                     vec2 scale, vec2 offset) {
  glm::dvec3 sum(0.0);
  for (int j = 0; j < kFootprintSamples; ++j)
    for (int i = 0; i < kFootprintSamples; ++i) {
      const vec2 uv((float(x) + (float(i) + 0.5f) / kFootprintSamples) / float(w),
                    (float(y) + (float(j) + 0.5f) / kFootprintSamples) / float(h));
      const vec2 a = uv * scale + offset;
      const int ax = std::clamp(int(std::floor(a.x * float(atlas.width))), 0, atlas.width - 1);
      const int ay = std::clamp(int(std::floor(a.y * float(atlas.height))), 0, atlas.height - 1);
      const double visible = coverage ? double(coverage->at(ax, ay)[0]) : 1.0;
      sum += glm::dvec3(atlas.rgb(ax, ay)) * visible;
    }
  return vec3(sum / double(kFootprintSamples * kFootprintSamples));
}

}  // namespace

void ReferenceErrorSums::add(const ReferenceErrorSums& o) {
  texels += o.texels;
  sumSquaredError += o.sumSquaredError;
  sumSquaredReference += o.sumSquaredReference;
  sumKiln += o.sumKiln;
  sumReference += o.sumReference;
}

double ReferenceErrorSums::relativeRmse() const {
  return sumSquaredReference > 0.0 ? std::sqrt(sumSquaredError / sumSquaredReference) : 0.0;
}

double ReferenceErrorSums::meanRatio() const {
  return sumReference > 0.0 ? sumKiln / sumReference : 0.0;
}

void addBakeDifference(const Image& bake, const Image& reference, const Image* coverage,
                       ReferenceErrorSums& sums) {
  for (int y = 0; y < reference.height; ++y)
    for (int x = 0; x < reference.width; ++x) {
      const vec3 r = reference.rgb(x, y), k = bake.rgb(x, y);
      if (coverage ? !(coverage->at(x, y)[0] > 0.0f) : r == vec3(0.0f)) continue;
      const vec3 d = k - r;
      sums.sumSquaredError += double(glm::dot(d, d));
      sums.sumSquaredReference += double(glm::dot(r, r));
      sums.sumKiln += double(luminance(k));
      sums.sumReference += double(luminance(r));
      ++sums.texels;
    }
}

Result<ReferenceComparison> compareWithReference(const std::string& referenceDir,
                                                 const std::string& bakeDir, bool keepImages) {
  const fs::path refDir(referenceDir), outDir(bakeDir);
  const std::string indexPath = (refDir / "index.json").string();
  Result<Json> index = readJsonFile(indexPath);
  if (!index) return Error{index.error()};
  const std::string manifestPath = (outDir / "manifest.json").string();
  // kiln's one manifest reader (lightmap/manifest.h) checks it: pages, files, scaleOffset.
  Result<Manifest> manifest = readManifestFile(manifestPath, ManifestUse::kLightmaps);
  if (!manifest) return Error{manifest.error()};
  if (!index->contains("objects") || !(*index)["objects"].is_array())
    return Error{indexPath + ": needs an \"objects\" array"};

  std::map<int, const ManifestObject*> bakedObjects;
  for (const ManifestObject& o : manifest->objects) bakedObjects[o.nodeIndex] = &o;
  std::map<int, Image> pages, coverages;  // loaded on first use

  ReferenceComparison comparison;
  for (const Json& ref : (*index)["objects"]) {
    ObjectReferenceError result;
    try {
      result.node = ref.at("node").get<std::string>();
      result.nodeIndex = ref.at("nodeIndex").get<int>();
    } catch (const Json::exception&) {
      return Error{indexPath + ": objects need \"node\" and \"nodeIndex\""};
    }
    const std::string who = "node " + std::to_string(result.nodeIndex) + " '" + result.node + "'";
    auto it = bakedObjects.find(result.nodeIndex);
    if (it == bakedObjects.end()) return Error{manifestPath + ": no object for " + who};
    const ManifestObject& baked = *it->second;
    if (baked.node != result.node)
      return Error{manifestPath + ": " + who + " is called '" + baked.node + "' in the manifest"};
    const int page = baked.lightmapIndex;
    if (page < 0) return Error{manifestPath + ": " + who + " has no lightmap"};
    const vec2 scale(baked.scaleOffset.x, baked.scaleOffset.y),
        offset(baked.scaleOffset.z, baked.scaleOffset.w);
    if (!pages.count(page)) {
      const std::string& file = manifest->lightmaps[size_t(page)].files.light;
      Result<Image> img = readHdrImage((outDir / file).string());
      if (!img) return Error{img.error()};
      pages[page] = std::move(img).value();
      const std::string& coverageFile = manifest->lightmaps[size_t(page)].files.coverage;
      if (!coverageFile.empty()) {
        Result<Image> cov = readHdrImage((outDir / coverageFile).string());
        if (!cov) return Error{cov.error()};
        if (cov->width != pages[page].width || cov->height != pages[page].height)
          return Error{manifestPath + ": lightmap " + std::to_string(page) +
                       ": the coverage map and the light map differ in size"};
        coverages[page] = std::move(cov).value();
      }
    }
    const Image& atlas = pages[page];
    const Image* coverage = coverages.count(page) ? &coverages[page] : nullptr;
    result.coverageWeighted = coverage != nullptr;

    Result<Image> refImage = readHdrImage((refDir / ref.value("file", result.node + ".exr")).string());
    if (!refImage) return Error{refImage.error()};
    Result<Image> mask = readHdrImage((refDir / ref.value("mask", result.node + "_mask.exr")).string());
    if (!mask) return Error{mask.error()};
    if (mask->width != refImage->width || mask->height != refImage->height)
      return Error{referenceDir + ": " + who + ": the mask and the image differ in size"};
    const int w = refImage->width, h = refImage->height;
    if (keepImages) {
      result.kiln = Image(w, h, 3);
      result.reference = *refImage;
    }
    auto covered = [&](int x, int y) {
      return x >= 0 && y >= 0 && x < w && y < h && mask->rgb(x, y).r > 0.5f;
    };
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        bool inside = true;
        for (int dy = -1; dy <= 1 && inside; ++dy)
          for (int dx = -1; dx <= 1 && inside; ++dx) inside = covered(x + dx, y + dy);
        if (!inside) continue;
        const vec3 k = sampleFootprint(atlas, coverage, x, y, w, h, scale, offset), r = refImage->rgb(x, y);
        bool hiddenNeighbour = false;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const vec3 q = refImage->rgb(x + dx, y + dy);
            hiddenNeighbour |= q.r + q.g + q.b < kHiddenReference;
          }
        if (keepImages)
          for (int c = 0; c < 3; ++c) result.kiln.at(x, y)[c] = k[c];
        ReferenceErrorSums texel;
        texel.texels = 1;
        for (int c = 0; c < 3; ++c) {
          texel.sumSquaredError += double(k[c] - r[c]) * double(k[c] - r[c]);
          texel.sumSquaredReference += double(r[c]) * double(r[c]);
          texel.sumKiln += k[c];
          texel.sumReference += r[c];
        }
        result.sums.add(texel);
        if (!hiddenNeighbour) result.visible.add(texel);
      }
    comparison.overall.add(result.sums);
    comparison.overallVisible.add(result.visible);
    comparison.objects.push_back(std::move(result));
  }
  return comparison;
}

std::string formatReferenceTable(const ReferenceComparison& c) {
  std::ostringstream out;
  char line[160];
  std::snprintf(line, sizeof line, "%-14s | %-29s | %-29s\n", "", "all covered texels",
                "visible texels (no hidden nbr)");
  out << line;
  std::snprintf(line, sizeof line, "%-14s | %7s %10s %10s | %7s %10s %10s\n", "object", "texels",
                "rel.RMSE", "ratio", "texels", "rel.RMSE", "ratio");
  out << line;
  auto row = [&](const std::string& name, const ReferenceErrorSums& s, const ReferenceErrorSums& v) {
    std::snprintf(line, sizeof line, "%-14s | %7zu %9.2f%% %10.4f | %7zu %9.2f%% %10.4f\n",
                  name.c_str(), s.texels, 100.0 * s.relativeRmse(), s.meanRatio(), v.texels,
                  100.0 * v.relativeRmse(), v.meanRatio());
    out << line;
  };
  for (const ObjectReferenceError& o : c.objects) row(o.node, o.sums, o.visible);
  row("overall", c.overall, c.overallVisible);
  return out.str();
}

}  // namespace kiln
