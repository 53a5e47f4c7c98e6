// lightmap_writer.cpp: kiln bake's output files (see lightmap_writer.h and
// docs/lightmap_outputs.md). Every file is first written under a temporary name in the
// output directory ("<name>.kiln-tmp"); only when all were written are they renamed, the
// manifest last, so that a failure leaves the previous outputs as they were.
#include "lightmap/lightmap_writer.h"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <system_error>

#include "lightmap/gltf_writer.h"
#include "lightmap/ldr_encoding.h"
#include "lightmap/manifest.h"
#include "src/light_modes.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

Status writeBytes(const std::string& path, const void* data, size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) return Error{path + ": cannot open for writing"};
  out.write(static_cast<const char*>(data), std::streamsize(size));
  out.close();
  if (!out) return Error{path + ": write failed"};
  return Status::success();
}

// Files written under temporary names, renamed together by commit().
class StagedFiles {
 public:
  explicit StagedFiles(fs::path dir) : dir_(std::move(dir)) {}
  ~StagedFiles() { discard(); }

  // Writes `name` (relative to the directory; its folders are created) through
  // `write(temporaryPath)`.
  Status stage(const std::string& name, const std::function<Status(const std::string&)>& write) {
    const std::string tmp = temporaryPath(name);
    staged_.push_back({tmp, (dir_ / name).string()});
    names_.push_back(name);
    std::error_code ec;
    fs::create_directories((dir_ / name).parent_path(), ec);
    if (ec) return Error{(dir_ / name).parent_path().string() + ": " + ec.message()};
    Status s = write(tmp);
    if (!s) return Error{(dir_ / name).string() + ": " + s.error()};
    return Status::success();
  }

  Status commit() {
    for (size_t i = 0; i < staged_.size(); ++i) {
      std::error_code ec;
      fs::rename(staged_[i].first, staged_[i].second, ec);
      if (ec) {
        staged_.erase(staged_.begin(), staged_.begin() + long(i));
        return Error{staged_.front().second + ": " + ec.message()};
      }
    }
    staged_.clear();
    return Status::success();
  }

  std::string temporaryPath(const std::string& name) const {
    return (dir_ / (name + ".kiln-tmp")).string();
  }
  const std::vector<std::string>& names() const { return names_; }

  void discard() {
    for (const auto& [tmp, final] : staged_) {
      std::error_code ec;
      fs::remove(tmp, ec);
      fs::remove(tmp + ".tmp", ec);  // writeExr/writeLdrPng's own temporary
    }
    staged_.clear();
  }

 private:
  fs::path dir_;
  std::vector<std::pair<std::string, std::string>> staged_;  // temporary, final
  std::vector<std::string> names_;                           // every name staged
};

Result<std::vector<uint8_t>> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open the file"};
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return Error{path + ": read failed"};
  return bytes;
}

// A share of a page's valid texels above dLDR's range, in percent, worth a warning: the PNG
// clamps them (RGBM's range is 8).
constexpr double kDldrClampWarningPercent = 1.0;

const char* ldrName(LdrEncoding e) {
  switch (e) {
    case LdrEncoding::Rgbm:
      return "rgbm";
    case LdrEncoding::Dldr:
      return "dldr";
    case LdrEncoding::None:
      break;
  }
  return "none";
}

// A float setting as the shortest decimal that reads back as the same float: 0.1f is written
// "0.1", not "0.10000000149011612".
double shortestDecimal(float v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  if (ec != std::errc()) return double(v);
  return std::strtod(std::string(buf, end).c_str(), nullptr);
}

}  // namespace

std::string lightmapFileName(int page, const char* kind) {
  return "lightmap-" + std::to_string(page) + "_" + kind + ".exr";
}

Json lightmapSettingsJson(const LightmapBakeSettings& s, const LightmapOutputSettings& o) {
  // Everything that changes the output; `threads` does not (deterministic) and is left out.
  Json j;
  j["preset"] = o.preset.empty() ? Json(nullptr) : Json(o.preset);
  j["resolution"] = shortestDecimal(s.resolution);
  j["padding"] = s.padding;
  j["maxSize"] = s.maxSize;
  j["lockAtlas"] = o.lockAtlas.empty() ? Json(nullptr) : Json(o.lockAtlas);
  j["samplesPerTexel"] = s.samplesPerTexel;
  j["supersampling"] = s.supersampling;
  j["seed"] = s.seed;
  j["bounces"] = s.bounces;
  j["albedoBoost"] = shortestDecimal(s.albedoBoost);
  j["indirectIntensity"] = shortestDecimal(s.indirectIntensity);
  j["backfaceTolerance"] = shortestDecimal(s.backfaceTolerance);
  j["ambientOcclusion"] = s.ambientOcclusion;
  j["aoMaxDistance"] = shortestDecimal(s.aoMaxDistance);
  j["aoAmount"] = shortestDecimal(s.aoAmount);
  j["lightingMode"] = lightingModeName(s.lightingMode);
  j["directional"] = s.directional;
  j["shadowColor"] = {shortestDecimal(s.shadowColor.r), shortestDecimal(s.shadowColor.g),
                      shortestDecimal(s.shadowColor.b)};
  j["denoise"] = s.denoise;
  j["stitchSeams"] = s.stitchSeams;
  j["ldr"] = ldrName(o.ldr);
  // The output glTF's TEXCOORD_1 already holds the atlas UV (identity scale/offset there), and
  // whether it is one .glb: a reader of the output glTF needs to know the first.
  j["atlasUv"] = o.atlasUv;
  j["glb"] = o.glb;
  j["value"] = "E/pi (outgoing radiance of a white Lambertian surface), linear";
  j["kilnVersion"] = o.kilnVersion;
  return j;
}

Status writeLightmapOutputs(const std::string& scenePath, const LightmapBakeResult& result,
                            const LightmapBakeSettings& settings,
                            const LightmapOutputSettings& requested,
                            std::vector<std::string>* warningsOut) {
  if (requested.outDir.empty()) return Error{"no output directory given"};
  // The output glTF's lightmap textures are the LDR pages: dLDR unless --ldr chose RGBM.
  LightmapOutputSettings output = requested;
  if (output.writeGltf && output.ldr == LdrEncoding::None) output.ldr = LdrEncoding::Dldr;
  const LdrEncoding ldr = output.ldr;
  OutputGltfOptions gltfOptions;
  gltfOptions.outDir = output.outDir;
  gltfOptions.ldr = ldr;
  gltfOptions.atlasUv = output.atlasUv;
  gltfOptions.glb = output.glb;
  std::vector<std::string> extraWarnings;
  if (result.pages.size() != result.layout.pages.size())
    return Error{"bake result has " + std::to_string(result.pages.size()) + " pages but its atlas " +
                 std::to_string(result.layout.pages.size())};
  const fs::path dir(output.outDir);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec || !fs::is_directory(dir))
    return Error{output.outDir + ": cannot create the output directory" +
                 (ec ? ": " + ec.message() : std::string())};

  StagedFiles files(dir);
  Manifest manifest = bakeManifest(result, scenePath);
  for (size_t i = 0; i < result.pages.size(); ++i) {
    const LightmapPageResult& page = result.pages[i];
    const int index = int(i);
    const AtlasPage& size = result.layout.pages[i];
    if (page.light.width != size.width || page.light.height != size.height ||
        page.light.channels < 3)
      return Error{"bake result: lightmap " + std::to_string(i) + " is " +
                   std::to_string(page.light.width) + " x " + std::to_string(page.light.height) +
                   " x " + std::to_string(page.light.channels) + ", its atlas page " +
                   std::to_string(size.width) + " x " + std::to_string(size.height) + " RGB"};
    ManifestFiles& fileNames = manifest.lightmaps[i].files;
    fileNames.light = lightmapFileName(index, "light");
    if (Status s = files.stage(fileNames.light,
                               [&](const std::string& p) { return writeExr(p, page.light); });
        !s)
      return s;
    if (!page.ambientOcclusion.empty()) {
      fileNames.ao = lightmapFileName(index, "ao");
      if (Status s = files.stage(
              fileNames.ao,
              [&](const std::string& p) { return writeExr(p, page.ambientOcclusion); });
          !s)
        return s;
    }
    // Directional mode and shadowmask (docs/mixed_lighting.md): RGBA, half floats.
    for (auto [image, kind, name] :
         {std::tuple{&page.direction, "direction", &fileNames.direction},
          std::tuple{&page.shadowmask, "shadowmask", &fileNames.shadowmask}}) {
      if (image->empty()) continue;
      *name = lightmapFileName(index, kind);
      if (Status s = files.stage(*name,
                                 [&](const std::string& p) { return writeExr(p, *image); });
          !s)
        return s;
    }
    if (ldr != LdrEncoding::None) {
      const std::string name =
          "lightmap-" + std::to_string(index) + "_light_" + ldrName(ldr) + ".png";
      fileNames.lightLdr = name;
      const LdrImage ldrImage =
          ldr == LdrEncoding::Rgbm ? encodeRgbm(page.light) : encodeDldr(page.light, true);
      if (Status s =
              files.stage(name, [&](const std::string& p) { return writeLdrPng(p, ldrImage); });
          !s)
        return s;
      gltfOptions.ldrPages.push_back(name);
      if (output.glb && output.writeGltf) {  // the .glb embeds the PNG's very bytes
        Result<std::vector<uint8_t>> png = readBytes(files.temporaryPath(name));
        if (!png) return Error{png.error()};
        gltfOptions.ldrPngs.push_back(std::move(png).value());
      }
      if (ldr == LdrEncoding::Dldr) {
        // Texels dLDR clamps: a bright scene wants RGBM.
        size_t valid = 0, clamped = 0;
        float brightest = 0.0f;
        for (size_t t = 0; t < page.valid.size(); ++t) {
          if (!page.valid[t]) continue;
          const float* p = &page.light.pixels[t * size_t(page.light.channels)];
          const float m = std::max({p[0], p[1], p[2]});
          ++valid;
          if (m > kDldrRange) ++clamped;
          brightest = std::max(brightest, m);
        }
        const double percent = valid ? 100.0 * double(clamped) / double(valid) : 0.0;
        if (percent > kDldrClampWarningPercent) {
          char text[64];
          std::snprintf(text, sizeof text, "%.1f%% of the valid texels (E/pi up to %.3g)", percent,
                        double(brightest));
          extraWarnings.push_back(name + ": " + text + " exceed dLDR's range " +
                                  std::to_string(int(kDldrRange)) +
                                  " and are clamped; --ldr rgbm keeps values up to " +
                                  std::to_string(int(kRgbmRange)));
        }
      }
    }
  }
  manifest.settings = lightmapSettingsJson(settings, output);
  if (ldr != LdrEncoding::None)
    manifest.settings["ldrDecode"] =
        ldr == LdrEncoding::Rgbm
            ? "rgb = png.rgb * png.a * " + std::to_string(int(kRgbmRange)) +
                  " (PNG sampled as linear UNORM)"
            : std::string("rgb = 2 * png.rgb (PNG sampled as sRGB, i.e. linearised)");

  const Json lightmaps = manifestPagesJson(manifest);
  if (output.writeGltf) {
    gltfOptions.reservedNames = files.names();
    gltfOptions.reservedNames.push_back(kManifestFileName);
    Result<OutputGltf> gltf = buildOutputGltf(scenePath, result, lightmaps, gltfOptions);
    if (!gltf) return Error{gltf.error()};
    for (const std::string& w : gltf->warnings) extraWarnings.push_back(w);
    for (const auto& [name, bytes] : gltf->binaries)
      if (Status s = files.stage(name,
                                 [&](const std::string& p) {
                                   return writeBytes(p, bytes.data(), bytes.size());
                                 });
          !s)
        return s;
    for (const auto& [name, source] : gltf->copies)
      if (Status s = files.stage(name,
                                 [&](const std::string& p) -> Status {
                                   std::error_code failed;
                                   fs::copy_file(source, p, fs::copy_options::overwrite_existing,
                                                 failed);
                                   if (failed)
                                     return Error{"cannot copy " + source + ": " + failed.message()};
                                   // A read-only input makes a read-only copy otherwise.
                                   fs::permissions(p, fs::perms::owner_read | fs::perms::owner_write,
                                                   fs::perm_options::add, failed);
                                   return Status::success();
                                 });
          !s)
        return s;
    const std::vector<uint8_t>& contents = gltf->contents;
    if (Status s = files.stage(gltf->fileName,
                               [&](const std::string& p) {
                                 return writeBytes(p, contents.data(), contents.size());
                               });
        !s)
      return s;
    manifest.gltf = gltf->fileName;
  }
  std::vector<std::string> warnings = result.warnings;
  warnings.insert(warnings.end(), extraWarnings.begin(), extraWarnings.end());
  if (warningsOut) *warningsOut = extraWarnings;
  manifest.warnings = warnings;
  const std::string text = manifestText(manifest);
  // The manifest is staged last, so it is renamed last: once it is there, everything it
  // names is too.
  if (Status s = files.stage(kManifestFileName,
                             [&](const std::string& p) {
                               return writeBytes(p, text.data(), text.size());
                             });
      !s)
    return s;
  return files.commit();
}

}  // namespace kiln
