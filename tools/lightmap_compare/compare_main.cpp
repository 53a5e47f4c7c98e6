// compare_main.cpp: `kiln_compare_reference --reference DIR --bake DIR`: prints, per object
// and overall, the relative RMSE and mean ratio of a kiln bake against an independent
// renderer's reference (reference_compare.h). Exit codes: 0 ok (and within the targets when
// given), 1 bad input, 2 bad usage, 3 a target missed.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "tools/lightmap_compare/reference_compare.h"

int main(int argc, char** argv) {
  CLI::App app{"Compare a kiln lightmap bake with reference bakes (e.g. Cycles' Cornell box)",
               "kiln_compare_reference"};
  std::string reference, bake;
  double maxRmse = -1.0, maxRatioError = -1.0;
  app.add_option("--reference", reference,
                 "Reference folder with index.json, <node>.exr, <node>_mask.exr")
      ->required();
  app.add_option("--bake", bake, "kiln bake output folder (manifest.json)")->required();
  app.add_option("--max-rmse", maxRmse, "Fail (exit 3) when the overall relative RMSE exceeds this");
  app.add_option("--max-ratio-error", maxRatioError,
                 "Fail (exit 3) when |overall mean ratio - 1| exceeds this");
  int worst = 0;
  app.add_option("--worst", worst, "Also list the N texels with the largest squared error");
  std::string dump;
  app.add_option("--dump", dump,
                 "Write <node>_kiln.png / <node>_ref.png (x 2, clamped) into this folder to look at");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  kiln::Result<kiln::ReferenceComparison> c =
      kiln::compareWithReference(reference, bake, !dump.empty() || worst > 0);
  if (!c) {
    std::cerr << "kiln_compare_reference: error: " << c.error() << "\n";
    return 1;
  }
  std::cout << kiln::formatReferenceTable(*c);
  if (worst > 0) {
    // Compared texels are those where either image is non-zero (kiln's image is 0 elsewhere).
    struct Texel {
      double error;
      const kiln::ObjectReferenceError* object;
      int x, y;
    };
    std::vector<Texel> texels;
    for (const kiln::ObjectReferenceError& o : c->objects)
      for (int y = 0; y < o.kiln.height; ++y)
        for (int x = 0; x < o.kiln.width; ++x) {
          const kiln::vec3 d = o.kiln.rgb(x, y) - o.reference.rgb(x, y);
          if (o.kiln.rgb(x, y) == kiln::vec3(0.0f)) continue;
          texels.push_back({double(glm::dot(d, d)), &o, x, y});
        }
    const size_t n = std::min(texels.size(), size_t(worst));
    std::partial_sort(texels.begin(), texels.begin() + long(n), texels.end(),
                      [](const Texel& a, const Texel& b) { return a.error > b.error; });
    for (size_t i = 0; i < n; ++i) {
      const Texel& t = texels[i];
      const kiln::vec3 k = t.object->kiln.rgb(t.x, t.y), r = t.object->reference.rgb(t.x, t.y);
      std::printf("%-12s (%3d, %3d)  kiln %.4f %.4f %.4f  reference %.4f %.4f %.4f\n",
                  t.object->node.c_str(), t.x, t.y, k.r, k.g, k.b, r.r, r.g, r.b);
    }
  }
  for (const kiln::ObjectReferenceError& o : c->objects) {
    if (dump.empty()) break;
    // Crop to the compared texels and enlarge 4x (nearest), so the images can be looked at.
    int x0 = o.kiln.width, y0 = o.kiln.height, x1 = -1, y1 = -1;
    for (int y = 0; y < o.kiln.height; ++y)
      for (int x = 0; x < o.kiln.width; ++x)
        if (o.kiln.rgb(x, y) != kiln::vec3(0.0f)) {
          x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
        }
    if (x1 < x0) continue;
    const int zoom = 4;
    for (auto [image, suffix] : {std::pair{&o.kiln, "_kiln.png"}, std::pair{&o.reference, "_ref.png"}}) {
      kiln::Image scaled((x1 - x0 + 1) * zoom, (y1 - y0 + 1) * zoom, 3);
      for (int y = 0; y < scaled.height; ++y)
        for (int x = 0; x < scaled.width; ++x)
          for (int ch = 0; ch < 3; ++ch)
            scaled.at(x, y)[ch] = kiln::linearToSrgb(
                std::min(1.0f, 2.0f * image->at(x0 + x / zoom, y0 + y / zoom)[ch]));
      if (kiln::Status s = kiln::writePng(dump + "/" + o.node + suffix, scaled); !s)
        std::cerr << "kiln_compare_reference: warning: " << s.error() << "\n";
    }
  }
  bool ok = true;
  if (maxRmse >= 0.0 && c->overall.relativeRmse() > maxRmse) ok = false;
  if (maxRatioError >= 0.0 && std::abs(c->overall.meanRatio() - 1.0) > maxRatioError) ok = false;
  if (!ok) std::cout << "target missed\n";
  return ok ? 0 : 3;
}
