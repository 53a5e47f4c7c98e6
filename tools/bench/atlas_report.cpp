// atlas_report.cpp: where a scene's lightmap atlas spends its texels, without baking light.
// Runs the bake's first three stages (UV generation, atlas, rasterization) as kiln bake does
// them and prints, per object, its charts, its rectangle and the texels the rasterizer gives
// samples, then the totals the docs quote (texels per chart, page fill); with --png, a picture
// of each page (one colour per object, black = empty).
//
//   kiln_atlas_report SCENE RESOLUTION [--padding P] [--max-size S] [--min-object-texels N]
//                     [--png PREFIX] [--zoom Z]
#include <sys/resource.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "lightmap/atlas.h"
#include "lightmap/lightmap_baker.h"
#include "lightmap/texel_raster.h"
#include "lightmap/uv_unwrap.h"
#include "src/gltf_loader.h"
#include "src/image.h"

namespace {

double cpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

kiln::vec3 colourOf(uint32_t i) {
  uint32_t h = i * 2654435761u + 12345u;
  h ^= h >> 15;
  h *= 2246822519u;
  h ^= h >> 13;
  return kiln::vec3(0.3f + 0.7f * float(h & 255) / 255.0f,
                    0.3f + 0.7f * float((h >> 8) & 255) / 255.0f,
                    0.3f + 0.7f * float((h >> 16) & 255) / 255.0f);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace kiln;
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s SCENE RESOLUTION [--padding P] [--max-size S] "
                         "[--min-object-texels N|auto] [--png PREFIX]\n", argv[0]);
    return 2;
  }
  LightmapBakeSettings bake;
  bake.resolution = std::strtof(argv[2], nullptr);
  std::string png;
  int zoom = 1;  // --zoom Z: each texel Z x Z pixels in the PNG
  for (int a = 3; a + 1 < argc; a += 2) {
    if (!std::strcmp(argv[a], "--padding")) bake.padding = std::atoi(argv[a + 1]);
    else if (!std::strcmp(argv[a], "--max-size")) bake.maxSize = std::atoi(argv[a + 1]);
    else if (!std::strcmp(argv[a], "--min-object-texels"))
      bake.minObjectTexels =
          std::strcmp(argv[a + 1], "auto") ? std::strtof(argv[a + 1], nullptr) : -1.0f;
    else if (!std::strcmp(argv[a], "--png")) png = argv[a + 1];
    else if (!std::strcmp(argv[a], "--zoom")) zoom = std::max(1, std::atoi(argv[a + 1]));
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[a]);
      return 2;
    }
  }
  LoadOptions load;
  load.loadTextures = false;
  Result<Scene> loaded = loadScene(argv[1], load);
  if (!loaded) {
    std::fprintf(stderr, "%s\n", loaded.error().c_str());
    return 1;
  }
  Scene scene = std::move(loaded).value();
  const double t0 = cpuSeconds();
  UnwrapSettings unwrap;
  unwrap.gutterTexels = std::max(1, bake.padding);
  unwrap.minObjectTexels = bake.minObjectTexels;
  auto unwraps = generateMissingLightmapUvs(scene, bake.resolution, unwrap);
  if (!unwraps) {
    std::fprintf(stderr, "%s\n", unwraps.error().c_str());
    return 1;
  }
  const double t1 = cpuSeconds();
  AtlasSettings atlas;
  atlas.resolution = bake.resolution;
  atlas.padding = bake.padding;
  atlas.maxSize = bake.maxSize;
  atlas.minObjectTexels = bake.minObjectTexels;
  for (const auto& u : *unwraps) atlas.worldPerUv.push_back(u ? u->worldPerUv : 0.0);
  auto layout = packAtlas(scene, atlas);
  if (!layout) {
    std::fprintf(stderr, "%s\n", layout.error().c_str());
    return 1;
  }
  if (Status s = packChartsIntoPages(scene, *layout, atlas, *unwraps); !s) {
    std::fprintf(stderr, "%s\n", s.error().c_str());
    return 1;
  }
  const double t2 = cpuSeconds();
  RasterSettings raster;
  auto pages = rasterizeAtlas(scene, *layout, raster);
  if (!pages) {
    std::fprintf(stderr, "%s\n", pages.error().c_str());
    return 1;
  }
  for (const std::string& w : layout->warnings) std::printf("warning: %s\n", w.c_str());

  std::vector<size_t> covered(scene.objects.size(), 0);
  size_t texels = 0, pageTexels = 0;
  for (const RasterPage& p : *pages) {
    pageTexels += size_t(p.width) * p.height;
    for (const TexelSample& t : p.texels)
      if (t.valid()) {
        ++covered[size_t(t.object)];
        ++texels;
      }
  }
  std::printf("%-28s %8s %9s %6s %10s %8s %6s %6s\n", "object", "tris", "area", "charts",
              "rect", "texels", "t/ch", "fill");
  int charts = 0;
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const Object& o = scene.objects[i];
    const AtlasObject& ao = layout->objects[i];
    double area = 0.0;
    for (uint32_t t = 0; t < o.triangles.size(); ++t) area += o.triangleArea(t);
    const int c = (*unwraps)[i] ? (*unwraps)[i]->stats.chartCount : 0;
    charts += c;
    char rect[32];
    std::snprintf(rect, sizeof rect, "%dx%d", ao.texelSize.x, ao.texelSize.y);
    const double rectTexels = double(ao.texelSize.x) * ao.texelSize.y;
    std::printf("%-28.28s %8zu %9.4f %6d %10s %8zu %6.0f %5.0f%%%s\n", o.name.c_str(),
                o.triangles.size(), area, c, ao.probeLit ? "probes" : rect, covered[i],
                c ? double(covered[i]) / c : 0.0,
                rectTexels > 0 ? 100.0 * double(covered[i]) / rectTexels : 0.0,
                ao.lightmapIndex >= 0 ? "" : " (no lightmap)");
  }
  for (size_t p = 0; p < pages->size(); ++p)
    std::printf("page %zu: %d x %d\n", p, (*pages)[p].width, (*pages)[p].height);
  std::printf("charts %d, texels %zu, page texels %zu, texels per chart %.0f, fill %.1f%%\n",
              charts, texels, pageTexels, charts ? double(texels) / charts : 0.0,
              pageTexels ? 100.0 * double(texels) / double(pageTexels) : 0.0);
  std::printf("cpu seconds: uv generation %.2f, atlas %.2f\n", t1 - t0, t2 - t1);
  if (!png.empty())
    for (size_t p = 0; p < pages->size(); ++p) {
      const RasterPage& page = (*pages)[p];
      Image image(page.width * zoom, page.height * zoom, 3);
      for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) {
          const TexelSample& t = page.at(x / zoom, y / zoom);
          if (!t.valid()) continue;
          const vec3 c = colourOf(uint32_t(t.object));
          float* px = image.at(x, y);
          px[0] = c.x;
          px[1] = c.y;
          px[2] = c.z;
        }
      const std::string path = png + std::to_string(p) + ".png";
      if (Status s = writePng(path, image); !s) std::fprintf(stderr, "%s\n", s.error().c_str());
    }
  return 0;
}
