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
  // Which objects are too small for a lightmap (atlas.h): "auto" or a texel count.
  j["minObjectTexels"] = s.minObjectTexels < 0.0f ? Json("auto")
                                                  : Json(shortestDecimal(s.minObjectTexels));
  j["lockAtlas"] = o.lockAtlas.empty() ? Json(nullptr) : Json(o.lockAtlas);
  j["samplesPerTexel"] = s.samplesPerTexel;
  j["supersampling"] = s.supersampling;
  j["errorTarget"] = shortestDecimal(s.errorTarget);
  j["bounceCacheSamples"] = s.bounceCacheSamples;
  j["adaptiveSamples"] = s.adaptiveSamples;
  j["footprintGrid"] = s.footprintGrid;
  j["minSamples"] = s.minSamples;
  j["pilotSamples"] = s.pilotSamples;
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

namespace {

// Copies `source` to the temporary path `p` (a staged copy of an input file).
Status copyInputFile(const std::string& source, const std::string& p) {
  std::error_code failed;
  fs::copy_file(source, p, fs::copy_options::overwrite_existing, failed);
  if (failed) return Error{"cannot copy " + source + ": " + failed.message()};
  // A read-only input makes a read-only copy otherwise.
  fs::permissions(p, fs::perms::owner_read | fs::perms::owner_write, fs::perm_options::add, failed);
  return Status::success();
}

// Writes one bake's outputs; writeLightmapOutputs runs it. Every stage stages its files
// (StagedFiles); nothing replaces an earlier output until commit, after the manifest.
class LightmapOutputWriter {
 public:
  LightmapOutputWriter(const std::string& scenePath, const LightmapBakeResult& result,
                       const LightmapBakeSettings& settings,
                       const LightmapOutputSettings& requested)
      : scenePath_(scenePath),
        result_(result),
        settings_(settings),
        requested_(requested),
        output_(outputSettings(requested)),
        ldr_(output_.ldr),
        files_(fs::path(output_.outDir)) {
    gltfOptions_.outDir = output_.outDir;
    gltfOptions_.ldr = ldr_;
    gltfOptions_.atlasUv = output_.atlasUv;
    gltfOptions_.glb = output_.glb;
  }

  Status run(std::vector<std::string>* warningsOut) {
    if (Status s = createOutputDirectory(); !s) return s;
    manifest_ = bakeManifest(result_, scenePath_);
    for (size_t i = 0; i < result_.pages.size(); ++i)
      if (Status s = stagePage(i); !s) return s;
    recordSettings();
    if (output_.writeGltf)
      if (Status s = stageGltf(); !s) return s;
    if (Status s = stageManifest(warningsOut); !s) return s;
    return files_.commit();
  }

 private:
  // The output glTF's lightmap textures are the LDR pages: dLDR unless --ldr chose RGBM.
  static LightmapOutputSettings outputSettings(const LightmapOutputSettings& requested) {
    LightmapOutputSettings output = requested;
    if (output.writeGltf && output.ldr == LdrEncoding::None) output.ldr = LdrEncoding::Dldr;
    return output;
  }

  // Checks that there is an output directory and that the bake result is whole, then creates
  // the directory.
  Status createOutputDirectory() {
    if (requested_.outDir.empty()) return Error{"no output directory given"};
    if (result_.pages.size() != result_.layout.pages.size())
      return Error{"bake result has " + std::to_string(result_.pages.size()) +
                   " pages but its atlas " + std::to_string(result_.layout.pages.size())};
    const fs::path dir(output_.outDir);
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec || !fs::is_directory(dir))
      return Error{output_.outDir + ": cannot create the output directory" +
                   (ec ? ": " + ec.message() : std::string())};
    return Status::success();
  }

  // Page i: its EXRs (light; AO, direction and shadowmask when baked) and its LDR PNG,
  // recorded in the manifest.
  Status stagePage(size_t i) {
    const LightmapPageResult& page = result_.pages[i];
    const int index = int(i);
    const AtlasPage& size = result_.layout.pages[i];
    if (page.light.width != size.width || page.light.height != size.height ||
        page.light.channels < 3)
      return Error{"bake result: lightmap " + std::to_string(i) + " is " +
                   std::to_string(page.light.width) + " x " + std::to_string(page.light.height) +
                   " x " + std::to_string(page.light.channels) + ", its atlas page " +
                   std::to_string(size.width) + " x " + std::to_string(size.height) + " RGB"};
    ManifestFiles& fileNames = manifest_.lightmaps[i].files;
    fileNames.light = lightmapFileName(index, "light");
    if (Status s = files_.stage(fileNames.light,
                                [&](const std::string& p) { return writeExr(p, page.light); });
        !s)
      return s;
    if (!page.ambientOcclusion.empty()) {
      fileNames.ao = lightmapFileName(index, "ao");
      if (Status s = files_.stage(
              fileNames.ao,
              [&](const std::string& p) { return writeExr(p, page.ambientOcclusion); });
          !s)
        return s;
    }
    if (!page.coverage.empty()) {
      fileNames.coverage = lightmapFileName(index, "coverage");
      if (Status s = files_.stage(fileNames.coverage,
                                  [&](const std::string& p) { return writeExr(p, page.coverage); });
          !s)
        return s;
    }
    // Directional mode and shadowmask (docs/mixed_lighting.md): RGBA, half floats.
    for (auto [image, kind, name] :
         {std::tuple{&page.direction, "direction", &fileNames.direction},
          std::tuple{&page.shadowmask, "shadowmask", &fileNames.shadowmask}}) {
      if (image->empty()) continue;
      *name = lightmapFileName(index, kind);
      if (Status s = files_.stage(*name, [&](const std::string& p) { return writeExr(p, *image); });
          !s)
        return s;
    }
    if (ldr_ == LdrEncoding::None) return Status::success();
    return stageLdrPage(page, index, fileNames);
  }

  // A page's LDR PNG: one of the output glTF's lightmap textures (for a .glb, its bytes).
  Status stageLdrPage(const LightmapPageResult& page, int index, ManifestFiles& fileNames) {
    const std::string name =
        "lightmap-" + std::to_string(index) + "_light_" + ldrName(ldr_) + ".png";
    fileNames.lightLdr = name;
    const LdrImage ldrImage =
        ldr_ == LdrEncoding::Rgbm ? encodeRgbm(page.light) : encodeDldr(page.light, true);
    if (Status s =
            files_.stage(name, [&](const std::string& p) { return writeLdrPng(p, ldrImage); });
        !s)
      return s;
    gltfOptions_.ldrPages.push_back(name);
    if (output_.glb && output_.writeGltf) {  // the .glb embeds the PNG's very bytes
      Result<std::vector<uint8_t>> png = readBytes(files_.temporaryPath(name));
      if (!png) return Error{png.error()};
      gltfOptions_.ldrPngs.push_back(std::move(png).value());
    }
    if (ldr_ == LdrEncoding::Dldr) warnAboutDldrClamp(page, name);
    return Status::success();
  }

  // Texels dLDR clamps: a bright scene wants RGBM.
  void warnAboutDldrClamp(const LightmapPageResult& page, const std::string& name) {
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
      extraWarnings_.push_back(
          name + ": " + text + " exceed dLDR's range " + std::to_string(int(kDldrRange)) +
          " and are clamped; --ldr rgbm keeps values up to " + std::to_string(int(kRgbmRange)));
    }
  }

  // The manifest's "settings", with how to decode the LDR pages.
  void recordSettings() {
    manifest_.settings = lightmapSettingsJson(settings_, output_);
    if (ldr_ != LdrEncoding::None)
      manifest_.settings["ldrDecode"] =
          ldr_ == LdrEncoding::Rgbm
              ? "rgb = png.rgb * png.a * " + std::to_string(int(kRgbmRange)) +
                    " (PNG sampled as linear UNORM)"
              : std::string("rgb = 2 * png.rgb (PNG sampled as sRGB, i.e. linearised)");
  }

  // The output glTF (gltf_writer.h) and the files it references: new binaries, copies of the
  // input's files. Its names avoid every file staged so far and the manifest.
  Status stageGltf() {
    const Json lightmaps = manifestPagesJson(manifest_);
    gltfOptions_.reservedNames = files_.names();
    gltfOptions_.reservedNames.push_back(kManifestFileName);
    Result<OutputGltf> gltf = buildOutputGltf(scenePath_, result_, lightmaps, gltfOptions_);
    if (!gltf) return Error{gltf.error()};
    for (const std::string& w : gltf->warnings) extraWarnings_.push_back(w);
    for (const auto& [name, bytes] : gltf->binaries)
      if (Status s = files_.stage(
              name,
              [&](const std::string& p) { return writeBytes(p, bytes.data(), bytes.size()); });
          !s)
        return s;
    for (const auto& [name, source] : gltf->copies)
      if (Status s =
              files_.stage(name, [&](const std::string& p) { return copyInputFile(source, p); });
          !s)
        return s;
    const std::vector<uint8_t>& contents = gltf->contents;
    if (Status s = files_.stage(
            gltf->fileName,
            [&](const std::string& p) { return writeBytes(p, contents.data(), contents.size()); });
        !s)
      return s;
    manifest_.gltf = gltf->fileName;
    return Status::success();
  }

  // manifest.json, with the bake's warnings and the writing's.
  Status stageManifest(std::vector<std::string>* warningsOut) {
    std::vector<std::string> warnings = result_.warnings;
    warnings.insert(warnings.end(), extraWarnings_.begin(), extraWarnings_.end());
    if (warningsOut) *warningsOut = extraWarnings_;
    manifest_.warnings = warnings;
    const std::string text = manifestText(manifest_);
    // The manifest is staged last, so it is renamed last: once it is there, everything it
    // names is too.
    return files_.stage(kManifestFileName, [&](const std::string& p) {
      return writeBytes(p, text.data(), text.size());
    });
  }

  const std::string& scenePath_;
  const LightmapBakeResult& result_;
  const LightmapBakeSettings& settings_;
  const LightmapOutputSettings& requested_;
  const LightmapOutputSettings output_;  // requested, with the LDR pages the glTF needs
  const LdrEncoding ldr_;
  StagedFiles files_;
  Manifest manifest_;
  OutputGltfOptions gltfOptions_;
  std::vector<std::string> extraWarnings_;  // the writing's warnings (not the bake's)
};

}  // namespace

Status writeLightmapOutputs(const std::string& scenePath, const LightmapBakeResult& result,
                            const LightmapBakeSettings& settings,
                            const LightmapOutputSettings& requested,
                            std::vector<std::string>* warningsOut) {
  return LightmapOutputWriter(scenePath, result, settings, requested).run(warningsOut);
}

}  // namespace kiln
