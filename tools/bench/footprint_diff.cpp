// footprint_diff.cpp: what the footprint grid (docs/lightmap_outputs.md, "Hidden-edge
// texels") changes on a scene. Bakes it twice in one process, with --no-footprint-grid and
// with the grid (the denoiser off, so that a texel without a grid is bit for bit the same on
// both sides), and prints the texel statistics the docs quote (non-zero texels, how many
// differ by more than 1%, are more than twice as bright or less than half, the page sum),
// then classifies the texels the grid makes more than twice as bright:
//   - by validity (valid/invalid without and with the grid) and whether the grid left
//     part of the footprint out (coverage < 1);
//   - against the light at the visible points around them: the largest value, without the
//     grid, over the texel itself and its 8 neighbours of the same object that are valid and
//     whose main sample the texel's main sample reaches along the surface without crossing
//     geometry (the footprint stage's own segment test). A visible-part mean lies within the
//     light of the visible surface around it; a texel brighter than all of that (beyond
//     `--margin`, relative) took light from somewhere no visible neighbour sees: a leak.
// and lists the largest changes with object, world position, validity, coverage and bound.
//
// With --reference F, a third bake at F texels per unit (no grid) gives each such texel the
// mean over the finer valid texels within its footprint that its main sample reaches: which
// of the two values is nearer it, and how many exceed twice it.
//
//   kiln_footprint_diff SCENE [--preset P] [--resolution R] [--samples N] [--seed S]
//                       [--top K] [--margin M] [--reference F]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "lightmap/lightmap_baker.h"
#include "src/gltf_loader.h"
#include "src/math.h"
#include "src/tracer.h"

namespace {

using namespace kiln;

float lum(const Image& im, size_t i) {
  return luminance(vec3(im.pixels[3 * i], im.pixels[3 * i + 1], im.pixels[3 * i + 2]));
}

// The geometric normal of the triangle of `o` nearest to p.
vec3 nearestNormal(const Object& o, vec3 p) {
  float best = kInfinity;
  vec3 n(0.0f, 1.0f, 0.0f);
  for (uint32_t t = 0; t < o.triangles.size(); ++t) {
    const uvec3 v = o.triangles[t];
    const vec3 q = closestPointOnTriangle(p, o.positions[v.x], o.positions[v.y], o.positions[v.z]);
    const float d = glm::dot(q - p, q - p);
    if (d < best) {
      best = d;
      n = o.faceNormal(t);
    }
  }
  return n;
}

// lightmap_baker.cpp's hiddenFromAnchor between two main samples (positions and normals).
bool hidden(const Scene& scene, const Tracer& tracer, vec3 a, vec3 na, vec3 p, vec3 np) {
  const float lift = std::max({0.0f, -glm::dot(p - a, na), -glm::dot(a - p, np)});
  const vec3 from = offsetRayOrigin(a, na) + lift * na, to = offsetRayOrigin(p, np) + lift * np;
  const vec3 d = to - from;
  const float length = glm::length(d);
  if (!(length > 0.0f)) return false;
  Ray ray{from, d / length, 0.0f, length};
  for (int layer = 0; layer < 8; ++layer) {
    const auto hit = tracer.intersect(ray);
    if (!hit) return false;
    if (scene.materialOf(hit->object, hit->triangle).alphaMode != AlphaMode::Blend) return true;
    ray.tMin = hit->t + 1e-4f;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s SCENE [--preset P] [--resolution R] [--samples N] "
                         "[--seed S] [--top K] [--margin M]\n", argv[0]);
    return 2;
  }
  LightmapBakeSettings s;
  std::string preset = "preview";
  float resolution = 8.0f, margin = 0.25f;
  int samples = 0, top = 25;
  float reference = 0.0f;  // --reference R: texels per unit of the finer bake (0 = none)
  for (int a = 2; a + 1 < argc; a += 2) {
    if (!std::strcmp(argv[a], "--preset")) preset = argv[a + 1];
    else if (!std::strcmp(argv[a], "--resolution")) resolution = std::strtof(argv[a + 1], nullptr);
    else if (!std::strcmp(argv[a], "--samples")) samples = std::atoi(argv[a + 1]);
    else if (!std::strcmp(argv[a], "--seed")) s.seed = std::strtoull(argv[a + 1], nullptr, 10);
    else if (!std::strcmp(argv[a], "--top")) top = std::atoi(argv[a + 1]);
    else if (!std::strcmp(argv[a], "--margin")) margin = std::strtof(argv[a + 1], nullptr);
    else if (!std::strcmp(argv[a], "--reference")) reference = std::strtof(argv[a + 1], nullptr);
    else {
      std::fprintf(stderr, "unknown option %s\n", argv[a]);
      return 2;
    }
  }
  if (Status st = applyLightmapPreset(preset, s); !st) {
    std::fprintf(stderr, "%s\n", st.error().c_str());
    return 2;
  }
  s.resolution = resolution;
  if (samples > 0) {
    s.samplesPerTexel = samples;
    s.errorTarget = 0.0f;
  }
  s.denoise = false;
  s.coverageMap = true;
  Result<Scene> loaded = loadScene(argv[1]);
  if (!loaded) {
    std::fprintf(stderr, "%s\n", loaded.error().c_str());
    return 1;
  }
  const Scene scene = std::move(loaded).value();
  std::vector<LightmapBakeResult> r;
  for (bool grid : {false, true}) {
    s.footprintGrid = grid;
    auto baked = bakeLightmaps(scene, s);
    if (!baked) {
      std::fprintf(stderr, "%s\n", baked.error().c_str());
      return 1;
    }
    r.push_back(std::move(baked).value());
  }
  if (reference > 0.0f) {
    s.footprintGrid = false;
    s.resolution = reference;
    auto baked = bakeLightmaps(scene, s);
    if (!baked) {
      std::fprintf(stderr, "%s\n", baked.error().c_str());
      return 1;
    }
    r.push_back(std::move(baked).value());
  }
  const LightmapBakeResult &off = r[0], &on = r[1];
  auto tracer = Tracer::create(on.scene);
  if (!tracer) {
    std::fprintf(stderr, "%s\n", tracer.error().c_str());
    return 1;
  }
  // Texel -> object: the object of the surface nearest its main sample (with generated
  // UVs an object's charts are packed one by one, so its rectangle holds other objects' too).
  auto ownerOf = [&](const LightmapPageResult& pg, size_t j) {
    const vec3 q(pg.position.pixels[3 * j], pg.position.pixels[3 * j + 1],
                 pg.position.pixels[3 * j + 2]);
    const auto ns = (*tracer)->nearestSurface(q, 1.0f);
    return ns ? int(ns->object) : -1;
  };
  std::vector<std::vector<int>> owner(on.pages.size());
  for (size_t p = 0; p < on.pages.size(); ++p) {
    owner[p].assign(on.pages[p].valid.size(), -1);
    for (size_t j = 0; j < owner[p].size(); ++j)
      if (on.pages[p].samples[j] > 0) owner[p][j] = ownerOf(on.pages[p], j);
  }
  // The finer bake's valid texels per object: (main sample, value).
  std::vector<std::vector<std::pair<vec3, float>>> fine(on.scene.objects.size());
  if (reference > 0.0f)
    for (const LightmapPageResult& pg : r[2].pages)
      for (size_t j = 0; j < pg.valid.size(); ++j) {
        if (!pg.valid[j] || pg.samples[j] == 0) continue;
        const int o = ownerOf(pg, j);
        if (o < 0) continue;
        fine[size_t(o)].push_back({vec3(pg.position.pixels[3 * j], pg.position.pixels[3 * j + 1],
                                        pg.position.pixels[3 * j + 2]),
                                   lum(pg.light, j)});
      }
  size_t nonzero = 0, identical = 0, differ = 0, brighter = 0, darker = 0;
  double sumOff = 0.0, sumOn = 0.0;
  struct Change {
    size_t page, index;
    float a, b, bound, coverage, ref;
    int refCount;
    bool validOff, validOn, leak;
  };
  std::vector<Change> bright;
  for (size_t p = 0; p < on.pages.size(); ++p) {
    const LightmapPageResult &pa = off.pages[p], &pb = on.pages[p];
    const int w = pb.light.width, h = pb.light.height;
    for (size_t i = 0; i < pb.valid.size(); ++i) {
      const float a = lum(pa.light, i), b = lum(pb.light, i);
      sumOff += a;
      sumOn += b;
      if (!(a > 0.0f || b > 0.0f)) continue;
      ++nonzero;
      if (a == b) ++identical;
      if (std::abs(b - a) > 0.01f * std::max(a, b)) ++differ;
      if (b < 0.5f * a - 0.001f) ++darker;
      if (!(b > 2.0f * a + 0.001f)) continue;
      ++brighter;
      if (pb.samples[i] == 0 || owner[p][i] < 0) continue;  // padding: dilated
      const Object& o = on.scene.objects[size_t(owner[p][i])];
      auto pos = [&](const LightmapPageResult& pg, size_t j) {
        return vec3(pg.position.pixels[3 * j], pg.position.pixels[3 * j + 1],
                    pg.position.pixels[3 * j + 2]);
      };
      const vec3 anchor = pos(pb, i), na = nearestNormal(o, anchor);
      float bound = pa.valid[i] ? a : 0.0f;
      const int x = int(i % size_t(w)), y = int(i / size_t(w));
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int nx = x + dx, ny = y + dy;
          if ((dx == 0 && dy == 0) || nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
          const size_t j = size_t(ny) * size_t(w) + size_t(nx);
          if (owner[p][j] != owner[p][i] || !pa.valid[j] || pa.samples[j] == 0) continue;
          const vec3 q = pos(pa, j);
          if (hidden(on.scene, **tracer, anchor, na, q, nearestNormal(o, q))) continue;
          bound = std::max(bound, lum(pa.light, j));
        }
      const float coverage = pb.coverage.empty() ? 1.0f : pb.coverage.pixels[i];
      // The finer bake's mean over its valid texels of this object within the texel's
      // footprint (main samples within 0.75 of a texel of its main sample) that its main
      // sample reaches along the surface: the visible part's mean light at a finer scale.
      double refSum = 0.0;
      int refCount = 0;
      const float radius = 0.75f / on.layout.objects[size_t(owner[p][i])].texelsPerUnit;
      for (const auto& [q, v] : fine[size_t(owner[p][i])]) {
        if (glm::length(q - anchor) > radius) continue;
        if (hidden(on.scene, **tracer, anchor, na, q, nearestNormal(o, q))) continue;
        refSum += v;
        ++refCount;
      }
      const float ref = refCount > 0 ? float(refSum / refCount) : -1.0f;
      bright.push_back({p, i, a, b, bound, coverage, ref, refCount, pa.valid[i] != 0,
                        pb.valid[i] != 0,
                        b > (1.0f + margin) * bound + 0.001f});
    }
  }
  std::printf("texels: %zu non-zero (padding included), %zu identical, %zu differ by more "
              "than 1%%, %zu more than twice as bright (+0.001), %zu less than half; page sum "
              "with / without the grid %.4f\n",
              nonzero, identical, differ, brighter, darker, sumOn / sumOff);
  std::printf("invalid texels: %zu without the grid, %zu with it\n", off.stats.invalidTexels,
              on.stats.invalidTexels);
  // Classes of the covered texels more than twice as bright.
  size_t cls[2][2][2][2] = {};  // validOff, validOn, coverage < 1, exceeds the bound
  for (const Change& c : bright)
    ++cls[c.validOff][c.validOn][c.coverage < 1.0f][c.leak];
  std::printf("covered texels more than twice as bright: %zu\n", bright.size());
  std::printf("  valid off -> on | part hidden | within visible neighbours' light | beyond it "
              "(x %.2f)\n", 1.0 + margin);
  for (int vo = 1; vo >= 0; --vo)
    for (int vn = 1; vn >= 0; --vn)
      for (int hc = 1; hc >= 0; --hc) {
        const size_t within = cls[vo][vn][hc][0], beyond = cls[vo][vn][hc][1];
        if (within + beyond == 0) continue;
        std::printf("  %s -> %s | %s | %zu | %zu\n", vo ? "valid" : "invalid",
                    vn ? "valid" : "invalid", hc ? "yes" : "no ", within, beyond);
      }
  if (reference > 0.0f) {
    // Against the finer bake: which of the two values is nearer its visible-part mean, and
    // how many with the grid exceed twice that mean (light no visible point there has).
    size_t nearer = 0, farther = 0, none = 0, overTwice = 0, overTwiceOff = 0;
    double refOn = 0.0, refOff = 0.0, sumRef = 0.0;
    for (const Change& c : bright) {
      if (c.refCount == 0) {
        ++none;
        continue;
      }
      (std::abs(c.b - c.ref) < std::abs(c.a - c.ref) ? nearer : farther)++;
      overTwice += c.b > 2.0f * c.ref + 0.01f ? 1 : 0;
      overTwiceOff += c.a > 2.0f * c.ref + 0.01f ? 1 : 0;
      refOn += c.b;
      refOff += c.a;
      sumRef += c.ref;
    }
    std::printf("against a bake at %g texels per unit (no grid): the grid's value is nearer "
                "its visible-part mean for %zu, farther for %zu (%zu without finer texels); "
                "above twice it (+0.01): %zu with the grid, %zu without; sums on / ref %.3f, "
                "off / ref %.3f\n",
                reference, nearer, farther, none, overTwice, overTwiceOff, refOn / sumRef,
                refOff / sumRef);
  }
  std::sort(bright.begin(), bright.end(), [](const Change& l, const Change& m) {
    if (l.leak != m.leak) return l.leak;
    return l.b - l.a > m.b - m.a;
  });
  std::printf("largest (texels beyond their visible neighbours' light first):\n");
  for (int k = 0; k < top && k < int(bright.size()); ++k) {
    const Change& c = bright[size_t(k)];
    const LightmapPageResult& pb = on.pages[c.page];
    const int w = pb.light.width;
    std::printf("  %-28s page %zu (%4d,%4d) pos %7.3f %7.3f %7.3f  off %.4f%s  on %.4f%s  "
                "coverage %.3f  bound %.4f  ref %.4f (%d)%s\n",
                on.scene.objects[size_t(owner[c.page][c.index])].name.c_str(), c.page,
                int(c.index % size_t(w)), int(c.index / size_t(w)),
                pb.position.pixels[3 * c.index], pb.position.pixels[3 * c.index + 1],
                pb.position.pixels[3 * c.index + 2], c.a, c.validOff ? "" : "(i)", c.b,
                c.validOn ? "" : "(i)", c.coverage, c.bound, c.ref, c.refCount,
                c.leak ? "  BEYOND" : "");
  }
  return 0;
}
