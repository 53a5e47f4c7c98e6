// compare_bakes_main.cpp: `kiln_compare_bakes --bake DIR --reference DIR`: two kiln bakes of
// the same scene and atlas (same resolution, padding and size; e.g. a preset against a
// converged fixed-count bake) compared texel by texel over every page: the relative RMSE
// sqrt(sum |k - r|^2 / sum |r|^2) (RGB) and the mean ratio sum k / sum r (luminance). The
// texels compared are the reference's baked, visible ones: coverage > 0 when the reference
// was baked with --coverage-map (padding and hidden texels have 0), else every texel whose
// reference value is not 0 (padding included, as dilated copies). Exit codes: 0 ok, 1 bad
// input (unreadable manifest or page, pages that differ in size), 2 bad usage.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>

#include "lightmap/manifest.h"
#include "tools/lightmap_compare/reference_compare.h"
#include "src/image.h"

namespace {

struct Loaded {
  std::filesystem::path dir;
  kiln::Manifest manifest;
};

kiln::Result<Loaded> load(const std::string& dir) {
  const std::filesystem::path path = std::filesystem::path(dir) / "manifest.json";
  kiln::Result<kiln::Manifest> m =
      kiln::readManifestFile(path.string(), kiln::ManifestUse::kLightmaps);
  if (!m) return kiln::Error{m.error()};
  return Loaded{dir, std::move(m).value()};
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"Compare a kiln lightmap bake with another of the same atlas", "kiln_compare_bakes"};
  std::string bake, reference;
  app.add_option("--bake", bake, "kiln bake output folder (manifest.json)")->required();
  app.add_option("--reference", reference,
                 "kiln bake output folder of the same scene and atlas (e.g. a converged bake)")
      ->required();
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  auto fail = [](const std::string& what) {
    std::cerr << "kiln_compare_bakes: error: " << what << "\n";
    return 1;
  };
  kiln::Result<Loaded> a = load(bake), b = load(reference);
  if (!a) return fail(a.error());
  if (!b) return fail(b.error());
  if (a->manifest.lightmaps.size() != b->manifest.lightmaps.size())
    return fail("the bakes have different page counts");
  kiln::ReferenceErrorSums sums;
  bool weighted = false;
  for (size_t p = 0; p < a->manifest.lightmaps.size(); ++p) {
    const auto& pa = a->manifest.lightmaps[p];
    const auto& pb = b->manifest.lightmaps[p];
    kiln::Result<kiln::Image> ka = kiln::readHdrImage((a->dir / pa.files.light).string());
    kiln::Result<kiln::Image> rb = kiln::readHdrImage((b->dir / pb.files.light).string());
    if (!ka) return fail(ka.error());
    if (!rb) return fail(rb.error());
    if (ka->width != rb->width || ka->height != rb->height)
      return fail("page " + std::to_string(p) + " differs in size between the bakes");
    std::optional<kiln::Image> coverage;
    if (!pb.files.coverage.empty()) {
      kiln::Result<kiln::Image> c = kiln::readHdrImage((b->dir / pb.files.coverage).string());
      if (!c) return fail(c.error());
      coverage = std::move(c).value();
      weighted = true;
    }
    kiln::addBakeDifference(*ka, *rb, coverage ? &*coverage : nullptr, sums);
  }
  if (sums.texels == 0 || !(sums.sumSquaredReference > 0.0))
    return fail("no texel to compare (a black reference?)");
  std::printf("texels %zu (%s), relative RMSE %.4f%%, mean ratio %.5f\n", sums.texels,
              weighted ? "reference coverage > 0" : "reference not 0",
              100.0 * sums.relativeRmse(), sums.meanRatio());
  return 0;
}
