// atlas.h: packing lightmapped objects into lightmap pages (MISSION.md "Lightmaps: Atlas").
//
// Each lightmapped object's UV1 bounding rectangle becomes one rectangle of texels whose size
// gives it `resolution x scaleInLightmap` texels per world unit (Unity's rule); rectangles are
// packed (skyline bottom-left, Jylänki 2010) into pages of at most maxSize x maxSize, and the
// object gets Unity's unity_LightmapST: atlasUV = uv1 * (sx, sy) + (ox, oy).
//
// Frames: texel (x, y) of a W x H page covers atlas UV [x, x+1]/W x [y, y+1]/H, with (0, 0)
// the top-left corner = the first image row (glTF texture coordinates, MISSION.md
// "Conventions"). scaleOffset maps the UV1 bounding rectangle [u0, u1] x [v0, v1] onto the
// object's texel rectangle [x, x + w] x [y, y + h] (texel edges, no half-texel inset; only
// 1/2000 texel, so that float rounding on pages that are not powers of two never reaches
// outside): the rasterizer is conservative, so border texels partly covered still get
// samples.
#pragma once

#include <atomic>
#include <nlohmann/json_fwd.hpp>
#include <optional>
#include <string>
#include <vector>

#include "src/math.h"
#include "kiln/result.h"
#include "src/scene.h"

namespace kiln {

struct Manifest;      // lightmap/manifest.h
struct UnwrapResult;  // lightmap/uv_unwrap.h

struct AtlasPage {
  int width = 0, height = 0;  // texels
};

// One scene object's place in the atlas. Index-aligned with Scene::objects.
struct AtlasObject {
  int lightmapIndex = -1;  // page, or -1: no lightmap (not static, scale 0, or probe-lit)
  // Texel rectangle [min, min + size) in its page, holding every texel of the object (other
  // objects' rectangles may overlap it, their texels never: packAtlas, packChartsIntoPages).
  glm::ivec2 texelMin{0};
  glm::ivec2 texelSize{0};
  vec4 scaleOffset{1.0f, 1.0f, 0.0f, 0.0f};  // (sx, sy, ox, oy)
  // Texels per world unit the object actually got (below resolution x scale when clamped).
  float texelsPerUnit = 0.0f;
  // Lightmapped by its settings, but its surface would get fewer than minObjectTexels
  // texels: lit by probes instead (Unity's receiveGI = probes), no page (lightmapIndex -1).
  bool probeLit = false;
};

struct AtlasLayout {
  std::vector<AtlasPage> pages;
  std::vector<AtlasObject> objects;   // one per Scene::objects entry
  std::vector<std::string> warnings;  // e.g. objects scaled down to fit maxSize
};

// The most texels all of a bake's pages may hold together (2^27: eight 4096^2 pages). Every
// texel costs the bake tens of bytes, so packAtlas refuses layouts above it (before anything
// the size of a page is allocated) instead of running out of memory (docs/limits.md).
inline constexpr uint64_t kMaxLightmapTexels = uint64_t(1) << 27;

// Success when `pages` hold at most kMaxLightmapTexels; else an error starting with `what`.
Status checkTexelBudget(const std::vector<AtlasPage>& pages, const std::string& what);

// Default of AtlasSettings::minObjectTexels, UnwrapSettings::minObjectTexels and kiln bake's
// --min-object-texels: negative = automatic (tooSmallForLightmap; `--min-object-texels auto`);
// 0 = every lightmapped object gets a lightmap; N > 0 = objects under N texels are lit by
// probes. Automatic by default: kiln bake gives each probe-lit object its own probe light
// (lightmap/probe_lit.h) in the manifest and the output glTF, which kiln render and the three.js
// plugin (tools/web/kiln-lightmap.js) light it with.
inline constexpr float kMinObjectTexels = -1.0f;

// The automatic rule takes small props, as a Unity user sets Receive GI: Light Probes on
// them: an object whose UVs kiln generates (no TEXCOORD_1: nobody made it a lightmap) whose
// lightmap would get fewer than 5 x resolution texels (area under 5 / resolution: 0.2 m^2 at
// 25 texels per unit, 0.08 m^2 at 64) and which holds under 1% of the scene's lightmapped
// surface. At 25-64 texels per unit such a lightmap holds little more than the one colour
// the probes around the object give as well (with direction), in charts of a texel or two
// that cost more gutter than they hold (tea cups, spoons, chair legs). The share keeps
// scenes modelled small (a 0.55 m Cornell box at 8 texels per unit, whose walls get 20
// texels each) and quick bakes at a few texels per unit from losing their rooms.
inline constexpr float kAutoObjectTexelsPerUnit = 5.0f;
inline constexpr double kAutoObjectAreaShare = 0.01;

// The automatic rule also takes thin props, whatever their area: an object whose generated
// charts (UnwrapStats) hold surface for under kAutoThinCoverage of the texels they touch on
// average, i.e. charts about a texel across, each texel of which the object covers only in
// part (the breakfast room's turned chair legs: 68-70 charts, 0.10-0.18 at 25-64 texels per
// unit; a chair 0.70-0.76, the teapot 0.52-0.66, a tea cup 0.38-0.63, a lamp 0.28-0.40). Such a
// lightmap holds no detail the probes do not (a texel is wider than the leg), and its charts
// of a few texels each cost more gutter than they hold. Also under kAutoObjectAreaShare of
// the scene's lightmapped surface, and only for UVs kiln generates.
inline constexpr double kAutoThinCoverage = 0.25;

// Whether an unwrap's charts are too thin for a lightmap (kAutoThinCoverage): surfaceTexels
// < kAutoThinCoverage x coveredTexels.
bool chartsTooThin(double surfaceTexels, double coveredTexels);

// The texels an object's surface gets at `resolution` (Unity's rule, before packing):
// (resolution x scaleInLightmap)^2 x its world area.
double lightmapTexels(const Object& object, float resolution);

// The world area of the scene's lightmapped objects (isLightmapped).
double lightmappedArea(const Scene& scene);

// Whether a lightmapped object (isLightmapped) is lit by probes instead: lightmapTexels <
// minTexels when minTexels >= 0, else the automatic rule above (sceneArea: lightmappedArea),
// or Object::thinCharts (set by generateMissingLightmapUvs under the automatic rule).
bool tooSmallForLightmap(const Object& object, float resolution, float minTexels,
                         double sceneArea);

struct AtlasSettings {
  float resolution = 10.0f;  // texels per world unit (before scaleInLightmap)
  // Lightmapped objects whose surface would get fewer texels than this are lit by probes
  // instead (AtlasObject::probeLit), named in a warning. 0 = every object gets a lightmap;
  // negative = automatic (tooSmallForLightmap).
  float minObjectTexels = kMinObjectTexels;
  // Per scene object (or empty): the world units per UV unit its generated UVs were made
  // with (UnwrapResult::worldPerUv), 0 = not generated. Such an object gets exactly
  // resolution x scaleInLightmap x worldPerUv texels per UV unit, the density its charts
  // were packed for, instead of the area rule below (which shrunk charts of sealed surfaces
  // would skew).
  std::vector<double> worldPerUv;
  int padding = 2;           // texels kept empty around every object (see packAtlas)
  int maxSize = 1024;        // largest page width and height, texels
  // When set, packAtlas checks it against the scene and returns it instead of packing
  // (--lock-atlas: several lightmap sets of one scene stay interchangeable).
  std::optional<AtlasLayout> locked;
  // A progress line on stderr ("atlas", in objects placed), and a flag polled between pages
  // that stops packing with an Error "cancelled".
  bool showProgress = false;
  const std::atomic<bool>* cancel = nullptr;
};

// Whether an object gets a lightmap: static, scaleInLightmap > 0 and receiveGI = lightmaps
// (objects lit by probes get none, as in Unity). Others still cast and bounce light.
bool isLightmapped(const Object& object);

// UV1 bounding rectangle (min, max) of an object's triangles' vertices.
std::pair<vec2, vec2> uv1Bounds(const Object& object);

// Packs every lightmapped object of the scene. Size rule: an object with world area A, UV1
// triangle area A_uv (sum of |UV triangle areas|) and UV1 bounding rectangle of extent
// (eu, ev) gets k = resolution x scaleInLightmap x sqrt(A / A_uv) texels per UV unit (with
// generated UVs: resolution x scaleInLightmap x settings.worldPerUv), so its
// triangles cover (resolution x scale)^2 x A texels, and a rectangle of
// w = ceil(k eu) x h = ceil(k ev) texels (at least 1). When max(w, h) > maxSize - 2 padding,
// k is scaled down to fit and a warning names the object.
// Padding: every object keeps `padding` empty texels on each side inside its page (so two
// objects are at least `padding` texels apart, and at least `padding` from the page border).
// Pages: objects are sorted by height, then width (descending), then object index, and
// filled into maxSize pages in that order, a new page when one is full; each page is then
// shrunk to the smallest size (by area; sides multiples of 4 as block compression needs, or
// maxSize) that holds its objects, inserted in that order or by width, area or longer side,
// or packed by their shapes (each object's covered texels per column, chart_packer.h, upright;
// their rectangles may then overlap, their texels never) when that page is smaller. Pages
// need not be powers of two: every
// GPU API kiln targets samples such textures (lightmaps are not mipmapped), and
// power-of-two pages left up to half of a page empty. Deterministic.
// Objects too small for a useful lightmap (tooSmallForLightmap) get no page and probeLit,
// and one warning names them; they need no uv1.
// Errors name the setting (maxSize < 1 + 2 padding, resolution <= 0) or the object (no uv1,
// zero-area uv1).
Result<AtlasLayout> packAtlas(const Scene& scene, const AtlasSettings& settings);

// Generated UVs packed chart by chart into their pages. Rectangles waste what an object's
// charts leave empty of its rectangle (a wall's window, a chair's curved pieces, the ragged
// top of its packing); here the charts of every object with generated UVs (`unwraps`, as
// generateMissingLightmapUvs returned them) on a page, and the texel rectangles of the page's
// other objects (upright, as one scale and offset places them), are packed together by
// shape (chart_packer.h) with max(1, padding) empty texels between any two and `padding` to
// the page's border. When that gives a smaller page, the generated objects' uv1 (in `scene`
// and `unwraps`) become atlas UVs of that page, their scaleOffset the identity (1, 1, 0, 0)
// and their texel rectangle the bounds of their charts (it may overlap other objects'
// rectangles, never their texels); the other objects keep their rectangle's size and get a
// new place. With settings.locked (a layout from a manifest), pages whose generated objects
// have identity scaleOffsets are packed again the same way, and the result must match the
// manifest (page size, the other objects' places): else an Error. Deterministic.
Status packChartsIntoPages(Scene& scene, AtlasLayout& layout, const AtlasSettings& settings,
                           std::vector<std::optional<UnwrapResult>>& unwraps);

// The manifest's atlas part (manifest.h writes it): {"lightmaps": [{"index", "width",
// "height"}], "objects": [{"node", "nodeIndex", "lightmapIndex", "scaleOffset": [sx, sy, ox,
// oy], "unityScaleOffset"}]}. Objects without a lightmap are listed with lightmapIndex -1,
// and "probeLit": true when they are lit by probes for being too small.
nlohmann::json atlasToJson(const AtlasLayout& layout, const Scene& scene);

// Reads a layout back from a manifest (checked by readManifest, ManifestUse::kAtlas; errors
// start with "lock-atlas manifest") for `scene`. See the overload below.
Result<AtlasLayout> atlasFromManifest(const nlohmann::json& manifest, const Scene& scene);

// The layout of a manifest that readManifest returned, for `scene`: objects are matched by
// nodeIndex and their node name must agree; every lightmapped scene object needs an entry
// with a page or probeLit, and entries with a page must be lightmapped objects. Texel rectangles are
// recovered from scaleOffset and the objects' UV1 bounds and must lie inside their page.
// Errors start with `where` (the manifest's file) and name the object.
Result<AtlasLayout> atlasFromManifest(const Manifest& manifest, const Scene& scene,
                                      const std::string& where);

}  // namespace kiln
