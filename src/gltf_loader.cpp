// gltf_loader.cpp: glTF 2.0 (.gltf + .bin, .glb) to kiln's Scene, through tinygltf.
//
// Loading runs in four passes:
//  1. the file is read, a .glb header checked, and the JSON parsed with nlohmann (depth-limited)
//     so that malformed JSON gets a precise message;
//  2. a pre-pass over that JSON checks every index that refers to another element, buffer
//     files and sizes, and bufferView ranges. tinygltf trusts some of these (it reads images
//     straight out of bufferViews), so nothing reaches it unchecked;
//  3. tinygltf builds its Model (buffers loaded, images kept as encoded bytes by our own
//     image callback so that a missing or broken image only warns);
//  4. the Model is validated (accessor ranges) and flattened into world space.
// Errors inside the passes are thrown as a private exception and turned into a kiln::Error at
// the top: the loader is deep, and every failure ends the load, so this keeps each check on
// one line. Nothing escapes loadScene().
#include "src/gltf_loader.h"

#include <stb_image.h>
#include <meshoptimizer.h>
#ifdef KILN_HAVE_DRACO
#include <draco/compression/decode.h>
#endif
#include <tiny_gltf.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <map>
#include <tuple>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "src/image.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr int kMaxJsonDepth = 128;                // deeper documents are rejected
constexpr uint64_t kMaxImagePixels = 1ull << 26;  // 64 Mpixel: larger images are skipped
const char* const kSupportedExtensions[] = {
    "KHR_lights_punctual",   "KHR_materials_emissive_strength", "KHR_mesh_quantization",
    "KHR_texture_transform", "EXT_meshopt_compression",
#ifdef KILN_HAVE_DRACO
    "KHR_draco_mesh_compression",
#endif
};
// Texture-source extensions (an alternative image format for a texture): kiln cannot decode
// them, but a texture that keeps its core 'source' (PNG/JPEG) is read through that, so a file
// that lists one as required is accepted when every texture using it has a 'source'.
const char* const kTextureSourceExtensions[] = {"MSFT_texture_dds", "EXT_texture_webp",
                                                "KHR_texture_basisu", "EXT_texture_avif"};
// EXT_meshopt_compression: a decoded bufferView may be at most this many times larger than
// its compressed bytes. meshopt's codecs cannot do better (the vertex codec spends at least
// 2 bits per 16 bytes, the index codecs a byte per triangle or index), so a larger claim is
// hostile, and this bounds what a small file can make the loader allocate.
constexpr uint64_t kMaxMeshoptExpansion = 128;
constexpr uint64_t kMeshoptSlack = 4096;
// Accessor elements without a bufferView (docs/limits.md): per accessor and summed over every
// read of such accessors in one file.
constexpr uint64_t kMaxElementsWithoutData = 1ull << 24;
// World-space coordinates of kept triangles, metres per axis (as for probe positions).
constexpr float kMaxWorldCoordinate = 1e7f;

// Thrown by Loader::fail; caught in loadScene.
struct LoadFailure {
  std::string message;
};

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  for (char& c : s)
    if (c == '\n') c = ';';
  return s;
}

bool isDataUri(const std::string& uri) { return uri.rfind("data:", 0) == 0; }

// The deepest nesting of arrays and objects in JSON text (brackets inside strings do not
// count), stopping early once past kMaxJsonDepth. Malformed text gives some depth: the parser
// that follows reports the syntax error.
int jsonNestingDepth(const char* text, size_t size) {
  int depth = 0, deepest = 0;
  bool inString = false;
  for (size_t i = 0; i < size; ++i) {
    char c = text[i];
    if (inString) {
      if (c == '\\')
        ++i;
      else if (c == '"')
        inString = false;
    } else if (c == '"') {
      inString = true;
    } else if (c == '[' || c == '{') {
      deepest = std::max(deepest, ++depth);
      if (deepest > kMaxJsonDepth) break;
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return deepest;
}

uint32_t readU32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// tinygltf image callback: keeps the encoded bytes; kiln decodes them itself once it knows
// which textures are used and how (sRGB or not), and turns decode failures into warnings.
bool keepEncodedImage(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                      const unsigned char* bytes, int size, void*) {
  image->image.assign(bytes, bytes + std::max(size, 0));
  image->as_is = true;
  return true;
}

const char* modeName(int mode) {
  switch (mode) {
    case TINYGLTF_MODE_POINTS:
      return "POINTS";
    case TINYGLTF_MODE_LINE:
      return "LINES";
    case TINYGLTF_MODE_LINE_LOOP:
      return "LINE_LOOP";
    case TINYGLTF_MODE_LINE_STRIP:
      return "LINE_STRIP";
    default:
      return "unknown";
  }
}

int componentSize(int componentType) {
  switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return 4;
    default:
      return 0;  // INT and DOUBLE are not valid glTF 2.0 accessor types
  }
}

// One component as a double; normalized integers per glTF 2.0 ("Animations" / accessor
// normalization: signed values are clamped to -1).
double readComponent(const uint8_t* p, int componentType, bool normalized) {
  switch (componentType) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      return normalized ? p[0] / 255.0 : p[0];
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return v;
    }
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default:
      assert(false);
      return 0.0;
  }
}

// Everything one primitive contributes to its object, in world space.
struct PrimitiveGeometry {
  std::vector<vec3> positions, normals;
  std::vector<vec2> uv0, uv1;
  bool hasUv0 = false, hasUv1 = false;
  std::vector<uvec3> triangles;
  uint32_t material = 0;
};

struct DropCounts {
  size_t nonFinite = 0, degenerate = 0, badNormals = 0;
  bool generatedNormals = false;
};

class Loader {
 public:
  Loader(std::string path, const LoadOptions& options)
      : path_(std::move(path)), options_(options) {}

  Scene load() {
    scene_.path = path_;
    readDocument();
    precheck();
    runTinyGltf();
    decodeMeshopt();
    decodeDraco();
    checkAccessors();
    convertMaterials();
    convertScene();
    scene_.updateBounds();
    return std::move(scene_);
  }

 private:
  // ---- messages ---------------------------------------------------------------------------

  [[noreturn]] void fail(const std::string& element, const std::string& what) const {
    throw LoadFailure{path_ + ": " + (element.empty() ? "" : element + ": ") + what};
  }
  void warn(const std::string& element, const std::string& what) {
    scene_.warnings.push_back(path_ + ": " + (element.empty() ? "" : element + ": ") + what);
  }

  // ---- pass 1: the file and its JSON -------------------------------------------------------

  void readDocument() {
    std::error_code ec;
    if (fs::is_directory(path_, ec)) fail("", "is a directory, not a glTF file");
    // Regular files only: a FIFO or a device would block the read or never end.
    if (fs::exists(path_, ec) && !fs::is_regular_file(path_, ec))
      fail("", "is not a regular file (a FIFO, device or socket)");
    std::ifstream in(path_, std::ios::binary);
    if (!in) fail("", std::string("cannot open the file: ") + std::strerror(errno));
    bytes_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (in.bad()) fail("", "read error");
    baseDir_ = fs::path(path_).parent_path().string();

    std::string ext = fs::path(path_).extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](char c) { return char(std::tolower(c)); });
    isGlb_ = bytes_.size() >= 4 && std::memcmp(bytes_.data(), "glTF", 4) == 0;
    if (!isGlb_ && ext == ".glb") fail("GLB header", "bad magic (expected 'glTF')");

    const char* jsonBegin = reinterpret_cast<const char*>(bytes_.data());
    size_t jsonSize = bytes_.size();
    if (isGlb_) parseGlbHeader(&jsonBegin, &jsonSize);
    if (jsonSize == 0) fail("", "empty file");

    // Depth-limited so that nesting bombs are refused before anything recursive sees them.
    // Measured by a scan of its own rather than nlohmann's parser callback: with a callback,
    // nlohmann searches the parent for discarded values at every object's end, which is
    // quadratic in an array's length (400,000 empty nodes took 118 s).
    if (int depth = jsonNestingDepth(jsonBegin, jsonSize); depth > kMaxJsonDepth)
      fail("", "JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    try {
      doc_ = Json::parse(jsonBegin, jsonBegin + jsonSize);
    } catch (const Json::exception& e) {
      fail("", std::string("malformed JSON: ") + e.what());
    }
    if (!doc_.is_object()) fail("", "malformed glTF: the JSON root is not an object");
  }

  // Binary glTF layout (glTF 2.0 spec, "GLB File Format Specification").
  void parseGlbHeader(const char** json, size_t* jsonSize) {
    const uint8_t* b = bytes_.data();
    size_t size = bytes_.size();
    if (size < 20) fail("GLB header", "file too short (" + std::to_string(size) + " bytes)");
    uint32_t version = readU32(b + 4), length = readU32(b + 8);
    if (version != 2) fail("GLB header", "version " + std::to_string(version) + " (expected 2)");
    if (length > size || length < 20)
      fail("GLB header", "length " + std::to_string(length) + " does not match the file size " +
                             std::to_string(size));
    uint32_t chunk0Length = readU32(b + 12), chunk0Type = readU32(b + 16);
    if (chunk0Type != 0x4E4F534Au) fail("GLB header", "the first chunk is not JSON");
    if (uint64_t(chunk0Length) + 20 > length || chunk0Length == 0)
      fail("GLB header",
           "JSON chunk length " + std::to_string(chunk0Length) + " runs past the end of the file");
    *json = reinterpret_cast<const char*>(b + 20);
    *jsonSize = chunk0Length;
    uint64_t binHeader = 20 + uint64_t(chunk0Length);
    if (binHeader + 8 <= length) {
      uint32_t chunk1Length = readU32(b + binHeader), chunk1Type = readU32(b + binHeader + 4);
      if (chunk1Type != 0x004E4942u) fail("GLB header", "the second chunk is not BIN");
      if (binHeader + 8 + chunk1Length > length)
        fail("GLB header",
             "BIN chunk length " + std::to_string(chunk1Length) + " runs past the end of the file");
      glbBinSize_ = chunk1Length;
    }
  }

  // ---- pass 2: references and buffers, on the raw JSON --------------------------------------

  const Json& array(const char* key) const {
    static const Json kEmpty = Json::array();
    auto it = doc_.find(key);
    if (it == doc_.end()) return kEmpty;
    if (!it->is_array()) fail(key, "must be an array");
    return *it;
  }

  // Checks an optional reference `obj[key]` into an array of `count` elements.
  void checkIndex(const Json& obj, const char* key, const std::string& element, size_t count,
                  const char* target) const {
    if (!obj.is_object()) return;
    auto it = obj.find(key);
    if (it == obj.end()) return;
    checkIndexValue(*it, element + "." + key, count, target);
  }
  void checkIndexValue(const Json& v, const std::string& element, size_t count,
                       const char* target) const {
    if (!v.is_number_integer() || v.get<int64_t>() < 0)
      fail(element, "must be an index (an integer >= 0)");
    if (uint64_t(v.get<int64_t>()) >= count)
      fail(element, "refers to " + std::string(target) + "[" + std::to_string(v.get<int64_t>()) +
                        "], but there are only " + std::to_string(count));
  }
  // A non-negative integer property (byteOffset, byteLength...), 0 when absent.
  uint64_t unsignedProperty(const Json& obj, const char* key, const std::string& element,
                            bool required) const {
    auto it = obj.find(key);
    if (it == obj.end()) {
      if (required) fail(element, std::string("missing required '") + key + "'");
      return 0;
    }
    if (!it->is_number_integer() || it->get<int64_t>() < 0)
      fail(element + "." + key, "must be an integer >= 0");
    return it->get<uint64_t>();
  }

  void checkTextureInfo(const Json& material, const std::string& element, const char* key,
                        size_t textureCount) const {
    const Json* info = &material;
    std::string where = element;
    if (std::string(key) == "baseColorTexture" || std::string(key) == "metallicRoughnessTexture") {
      auto pbr = material.find("pbrMetallicRoughness");
      if (pbr == material.end() || !pbr->is_object()) return;
      info = &*pbr;
      where += ".pbrMetallicRoughness";
    }
    auto it = info->find(key);
    if (it == info->end()) return;
    if (!it->is_object()) fail(where + "." + key, "must be an object");
    if (!it->contains("index")) fail(where + "." + key, "missing required 'index'");
    checkIndex(*it, "index", where + "." + key, textureCount, "textures");
  }

  void precheck() {
    // extensionsRequired: refuse what kiln would silently get wrong.
    std::vector<std::string> unsupported;
    for (const Json& e : array("extensionsRequired")) {
      if (!e.is_string()) fail("extensionsRequired", "must be an array of strings");
      std::string name = e.get<std::string>();
      if (std::find(std::begin(kTextureSourceExtensions), std::end(kTextureSourceExtensions),
                    name) != std::end(kTextureSourceExtensions)) {
        checkTextureSourceExtension(name);
        continue;
      }
      if (std::find(std::begin(kSupportedExtensions), std::end(kSupportedExtensions), name) ==
          std::end(kSupportedExtensions))
        unsupported.push_back(name);
    }
    if (!unsupported.empty()) {
      std::string list, supported;
      for (const auto& u : unsupported) list += (list.empty() ? "" : ", ") + u;
      for (const char* s : kSupportedExtensions)
        supported += (supported.empty() ? "" : ", ") + std::string(s);
      fail("extensionsRequired",
           "unsupported extension(s) " + list + " (kiln supports " + supported + ")");
    }

    const Json& buffers = array("buffers");
    const Json& bufferViews = array("bufferViews");
    const Json& accessors = array("accessors");
    const Json& meshes = array("meshes");
    const Json& materials = array("materials");
    const Json& textures = array("textures");
    const Json& images = array("images");
    const Json& samplers = array("samplers");
    const Json& nodes = array("nodes");
    const Json& scenes = array("scenes");
    const Json& cameras = array("cameras");
    size_t lightCount = 0;
    if (auto ext = doc_.find("extensions"); ext != doc_.end() && ext->is_object()) {
      if (auto lp = ext->find("KHR_lights_punctual"); lp != ext->end() && lp->is_object()) {
        if (auto lights = lp->find("lights"); lights != lp->end()) {
          if (!lights->is_array())
            fail("extensions.KHR_lights_punctual.lights", "must be an array");
          lightCount = lights->size();
        }
      }
    }

    // Buffers: files present and long enough, before tinygltf reads them.
    bufferLengths_.clear();
    noDataBuffer_.assign(buffers.size(), false);
    for (size_t i = 0; i < buffers.size(); ++i) {
      std::string element = "buffers[" + std::to_string(i) + "]";
      const Json& b = buffers[i];
      if (!b.is_object()) fail(element, "must be an object");
      uint64_t byteLength = unsignedProperty(b, "byteLength", element, true);
      if (byteLength == 0) fail(element + ".byteLength", "must be >= 1");
      bufferLengths_.push_back(byteLength);
      auto uriIt = b.find("uri");
      if (uriIt == b.end() && !(isGlb_ && i == 0) && isMeshoptFallback(b, element)) {
        // EXT_meshopt_compression: a fallback buffer may have no data; only the compressed
        // bufferViews refer to it, and kiln decodes those instead.
        noDataBuffer_[i] = true;
        continue;
      }
      if (uriIt == b.end()) {
        if (!isGlb_ || i != 0) fail(element, "has no uri (only a .glb's first buffer may omit it)");
        if (byteLength > glbBinSize_)
          fail(element, "byteLength " + std::to_string(byteLength) +
                            " is longer than the GLB BIN chunk (" + std::to_string(glbBinSize_) +
                            " bytes)");
        continue;
      }
      if (!uriIt->is_string()) fail(element + ".uri", "must be a string");
      std::string uri = uriIt->get<std::string>();
      if (isDataUri(uri)) continue;  // tinygltf decodes and checks its length
      fs::path file = fs::path(baseDir_) / percentDecode(uri);
      std::error_code ec;
      if (fs::exists(file, ec) && !fs::is_regular_file(file, ec))
        fail(element + ".uri",
             "'" + uri + "' is not a regular file (a FIFO, device or directory)");
      if (!fs::is_regular_file(file, ec)) fail(element, "file '" + uri + "' not found");
      uint64_t fileSize = fs::file_size(file, ec);
      if (ec) fail(element, "cannot read '" + uri + "'");
      if (fileSize < byteLength)
        fail(element, "file '" + uri + "' is " + std::to_string(fileSize) +
                          " bytes, shorter than byteLength " + std::to_string(byteLength));
      if (fileSize > byteLength)  // tinygltf insists on equality
        fail(element, "file '" + uri + "' is " + std::to_string(fileSize) +
                          " bytes, but byteLength is " + std::to_string(byteLength));
    }

    for (size_t i = 0; i < bufferViews.size(); ++i) {
      std::string element = "bufferViews[" + std::to_string(i) + "]";
      const Json& v = bufferViews[i];
      if (!v.is_object()) fail(element, "must be an object");
      if (!v.contains("buffer")) fail(element, "missing required 'buffer'");
      checkIndex(v, "buffer", element, buffers.size(), "buffers");
      uint64_t buffer = v["buffer"].get<uint64_t>();
      uint64_t offset = unsignedProperty(v, "byteOffset", element, false);
      uint64_t length = unsignedProperty(v, "byteLength", element, true);
      if (length == 0) fail(element + ".byteLength", "must be >= 1");
      if (offset > bufferLengths_[buffer] || length > bufferLengths_[buffer] - offset)
        fail(element, "byteOffset " + std::to_string(offset) + " + byteLength " +
                          std::to_string(length) + " runs past buffers[" + std::to_string(buffer) +
                          "] (" + std::to_string(bufferLengths_[buffer]) + " bytes)");
      if (v.contains("byteStride")) {
        uint64_t stride = unsignedProperty(v, "byteStride", element, false);
        if (stride < 4 || stride > 252 || stride % 4 != 0)
          fail(element + ".byteStride", "must be a multiple of 4 in [4, 252]");
      }
      bool compressed = checkMeshoptView(i, v, element, buffers.size(), length);
      if (!compressed && noDataBuffer_[buffer])
        fail(element, "refers to buffers[" + std::to_string(buffer) +
                          "], an EXT_meshopt_compression fallback buffer without data, but is "
                          "not compressed");
    }

    for (size_t i = 0; i < accessors.size(); ++i) {
      std::string element = "accessors[" + std::to_string(i) + "]";
      const Json& a = accessors[i];
      if (!a.is_object()) fail(element, "must be an object");
      checkIndex(a, "bufferView", element, bufferViews.size(), "bufferViews");
      // tinygltf reads a negative byteOffset as 0 and a count past 64 bits as something else.
      unsignedProperty(a, "byteOffset", element, false);
      unsignedProperty(a, "count", element, true);
      if (auto sparse = a.find("sparse"); sparse != a.end()) {
        if (!sparse->is_object()) fail(element + ".sparse", "must be an object");
        for (const char* part : {"indices", "values"}) {
          std::string where = element + ".sparse." + part;
          auto p = sparse->find(part);
          if (p == sparse->end() || !p->is_object()) fail(where, "missing or not an object");
          if (!p->contains("bufferView")) fail(where, "missing required 'bufferView'");
          checkIndex(*p, "bufferView", where, bufferViews.size(), "bufferViews");
        }
      }
    }

    for (size_t i = 0; i < meshes.size(); ++i) {
      std::string element = "meshes[" + std::to_string(i) + "]";
      if (!meshes[i].is_object()) fail(element, "must be an object");
      auto prims = meshes[i].find("primitives");
      if (prims == meshes[i].end() || !prims->is_array())
        fail(element, "missing required 'primitives' array");
      for (size_t j = 0; j < prims->size(); ++j) {
        std::string where = element + ".primitives[" + std::to_string(j) + "]";
        const Json& p = (*prims)[j];
        if (!p.is_object()) fail(where, "must be an object");
        checkIndex(p, "indices", where, accessors.size(), "accessors");
        // tinygltf refuses an indices accessor without a bufferView (Draco's have none): it
        // gets a document without them, and they are put back after (runTinyGltf).
        if (auto ix = p.find("indices"); ix != p.end() && accessors[ix->get<size_t>()].is_object() &&
                                         !accessors[ix->get<size_t>()].contains("bufferView"))
          viewlessIndices_.push_back({i, j, ix->get<int>()});
        checkIndex(p, "material", where, materials.size(), "materials");
        auto attrs = p.find("attributes");
        if (attrs == p.end() || !attrs->is_object())
          fail(where, "missing required 'attributes' object");
        for (auto it = attrs->begin(); it != attrs->end(); ++it)
          checkIndexValue(it.value(), where + ".attributes." + it.key(), accessors.size(),
                          "accessors");
        if (auto targets = p.find("targets"); targets != p.end() && targets->is_array())
          for (const Json& t : *targets)
            if (t.is_object())
              for (auto it = t.begin(); it != t.end(); ++it)
                checkIndexValue(it.value(), where + ".targets." + it.key(), accessors.size(),
                                "accessors");
      }
    }

    for (size_t i = 0; i < materials.size(); ++i) {
      std::string element = "materials[" + std::to_string(i) + "]";
      if (!materials[i].is_object()) fail(element, "must be an object");
      for (const char* key : {"baseColorTexture", "metallicRoughnessTexture", "normalTexture",
                              "occlusionTexture", "emissiveTexture"})
        checkTextureInfo(materials[i], element, key, textures.size());
    }
    for (size_t i = 0; i < textures.size(); ++i) {
      std::string element = "textures[" + std::to_string(i) + "]";
      if (!textures[i].is_object()) fail(element, "must be an object");
      checkIndex(textures[i], "source", element, images.size(), "images");
      checkIndex(textures[i], "sampler", element, samplers.size(), "samplers");
    }
    for (size_t i = 0; i < images.size(); ++i) {
      std::string element = "images[" + std::to_string(i) + "]";
      if (!images[i].is_object()) fail(element, "must be an object");
      checkIndex(images[i], "bufferView", element, bufferViews.size(), "bufferViews");
      bool hasUri = images[i].contains("uri"), hasView = images[i].contains("bufferView");
      if (hasUri == hasView) fail(element, "must have exactly one of 'uri' and 'bufferView'");
      if (hasUri && !images[i]["uri"].is_string()) fail(element + ".uri", "must be a string");
      if (hasUri && !isDataUri(images[i]["uri"].get<std::string>())) {
        // tinygltf reads the file whole: a FIFO or device there would block or never end.
        fs::path file = fs::path(baseDir_) / percentDecode(images[i]["uri"].get<std::string>());
        std::error_code ec;
        if (fs::exists(file, ec) && !fs::is_regular_file(file, ec))
          fail(element + ".uri", "'" + images[i]["uri"].get<std::string>() +
                                     "' is not a regular file (a FIFO, device or directory)");
      }
      if (hasView) {
        size_t view = images[i]["bufferView"].get<size_t>();
        if (isMeshoptView_.count(view))
          fail(element, "is stored in bufferViews[" + std::to_string(view) +
                            "], which is EXT_meshopt_compression-compressed (only vertex and "
                            "index data may be)");
      }
    }
    for (size_t i = 0; i < samplers.size(); ++i)
      if (!samplers[i].is_object())
        fail("samplers[" + std::to_string(i) + "]", "must be an object");
    for (size_t i = 0; i < cameras.size(); ++i)
      if (!cameras[i].is_object()) fail("cameras[" + std::to_string(i) + "]", "must be an object");

    for (size_t i = 0; i < nodes.size(); ++i) {
      std::string element = "nodes[" + std::to_string(i) + "]";
      const Json& n = nodes[i];
      if (!n.is_object()) fail(element, "must be an object");
      checkIndex(n, "mesh", element, meshes.size(), "meshes");
      checkIndex(n, "camera", element, cameras.size(), "cameras");
      checkIndex(n, "skin", element, array("skins").size(), "skins");
      if (auto children = n.find("children"); children != n.end()) {
        if (!children->is_array()) fail(element + ".children", "must be an array");
        for (size_t c = 0; c < children->size(); ++c)
          checkIndexValue((*children)[c], element + ".children[" + std::to_string(c) + "]",
                          nodes.size(), "nodes");
      }
      if (auto ext = n.find("extensions"); ext != n.end() && ext->is_object()) {
        if (auto lp = ext->find("KHR_lights_punctual"); lp != ext->end()) {
          std::string where = element + ".extensions.KHR_lights_punctual";
          if (!lp->is_object() || !lp->contains("light"))
            fail(where, "must be an object with a 'light' index");
          checkIndex(*lp, "light", where, lightCount, "lights");
        }
      }
    }
    for (size_t i = 0; i < scenes.size(); ++i) {
      std::string element = "scenes[" + std::to_string(i) + "]";
      if (!scenes[i].is_object()) fail(element, "must be an object");
      if (auto sn = scenes[i].find("nodes"); sn != scenes[i].end()) {
        if (!sn->is_array()) fail(element + ".nodes", "must be an array");
        for (size_t k = 0; k < sn->size(); ++k)
          checkIndexValue((*sn)[k], element + ".nodes[" + std::to_string(k) + "]", nodes.size(),
                          "nodes");
      }
    }
    if (doc_.contains("scene")) checkIndexValue(doc_["scene"], "scene", scenes.size(), "scenes");
  }

  // A required texture-source extension (MSFT_texture_dds...): every texture that uses it must
  // keep a core 'source' kiln reads instead; said once as a warning.
  void checkTextureSourceExtension(const std::string& name) {
    const Json& textures = array("textures");
    size_t users = 0;
    for (size_t i = 0; i < textures.size(); ++i) {
      const Json& t = textures[i];
      if (!t.is_object()) continue;  // reported by the texture checks below
      auto ext = t.find("extensions");
      if (ext == t.end() || !ext->is_object() || !ext->contains(name)) continue;
      ++users;
      if (!t.contains("source"))
        fail("textures[" + std::to_string(i) + "]",
             "has only an image in " + name +
                 " (listed in extensionsRequired), which kiln cannot decode, and no 'source' "
                 "(PNG or JPEG) to read instead");
    }
    if (users == 0)
      warn("extensionsRequired", name + " is listed but no texture uses it; ignored");
    else
      warn("extensionsRequired",
           name + " is required; kiln reads the 'source' image (PNG or JPEG) of the " +
               std::to_string(users) + " texture(s) that use it instead");
  }

  // ---- EXT_meshopt_compression ------------------------------------------------------------------

  bool isMeshoptFallback(const Json& buffer, const std::string& element) const {
    auto ext = buffer.find("extensions");
    if (ext == buffer.end() || !ext->is_object()) return false;
    auto mo = ext->find("EXT_meshopt_compression");
    if (mo == ext->end()) return false;
    if (!mo->is_object()) fail(element + ".extensions.EXT_meshopt_compression", "must be an object");
    auto fb = mo->find("fallback");
    return fb != mo->end() && fb->is_boolean() && fb->get<bool>();
  }

  // Checks bufferViews[i]'s EXT_meshopt_compression object (extension spec: buffer, byteOffset,
  // byteLength, byteStride, count, mode, filter) and records it; false when the view has none.
  bool checkMeshoptView(size_t i, const Json& v, const std::string& viewElement,
                        size_t bufferCount, uint64_t viewLength) {
    auto ext = v.find("extensions");
    if (ext == v.end() || !ext->is_object()) return false;
    auto mo = ext->find("EXT_meshopt_compression");
    if (mo == ext->end()) return false;
    std::string element = viewElement + ".extensions.EXT_meshopt_compression";
    if (!mo->is_object()) fail(element, "must be an object");
    if (!mo->contains("buffer")) fail(element, "missing required 'buffer'");
    checkIndex(*mo, "buffer", element, bufferCount, "buffers");
    MeshoptView m;
    m.view = i;
    m.buffer = (*mo)["buffer"].get<uint64_t>();
    m.offset = unsignedProperty(*mo, "byteOffset", element, false);
    m.length = unsignedProperty(*mo, "byteLength", element, true);
    m.stride = unsignedProperty(*mo, "byteStride", element, true);
    m.count = unsignedProperty(*mo, "count", element, true);
    m.viewLength = viewLength;
    if (noDataBuffer_[m.buffer])
      fail(element + ".buffer", "refers to buffers[" + std::to_string(m.buffer) +
                                    "], a fallback buffer without data");
    if (m.offset > bufferLengths_[m.buffer] || m.length > bufferLengths_[m.buffer] - m.offset)
      fail(element, "byteOffset " + std::to_string(m.offset) + " + byteLength " +
                        std::to_string(m.length) + " runs past buffers[" +
                        std::to_string(m.buffer) + "] (" +
                        std::to_string(bufferLengths_[m.buffer]) + " bytes)");
    auto modeIt = mo->find("mode");
    std::string mode = modeIt != mo->end() && modeIt->is_string() ? modeIt->get<std::string>() : "";
    std::string filter = "NONE";
    if (auto f = mo->find("filter"); f != mo->end()) {
      if (!f->is_string()) fail(element + ".filter", "must be a string");
      filter = f->get<std::string>();
    }
    if (mode == "ATTRIBUTES") {
      m.mode = MeshoptMode::Attributes;
      if (m.stride == 0 || m.stride > 256 || m.stride % 4 != 0)
        fail(element + ".byteStride", "must be a multiple of 4 in [4, 256] for ATTRIBUTES");
    } else if (mode == "TRIANGLES" || mode == "INDICES") {
      m.mode = mode == "TRIANGLES" ? MeshoptMode::Triangles : MeshoptMode::Indices;
      if (m.stride != 2 && m.stride != 4)
        fail(element + ".byteStride", "must be 2 or 4 for " + mode);
      if (m.mode == MeshoptMode::Triangles && m.count % 3 != 0)
        fail(element + ".count", "must be a multiple of 3 for TRIANGLES");
      if (filter != "NONE") fail(element + ".filter", "must be NONE for " + mode);
    } else {
      fail(element + ".mode", "must be \"ATTRIBUTES\", \"TRIANGLES\" or \"INDICES\"");
    }
    if (filter == "NONE") {
      m.filter = MeshoptFilter::None;
    } else if (filter == "OCTAHEDRAL") {
      m.filter = MeshoptFilter::Octahedral;
      if (m.stride != 4 && m.stride != 8) fail(element + ".byteStride", "must be 4 or 8 for OCTAHEDRAL");
    } else if (filter == "QUATERNION") {
      m.filter = MeshoptFilter::Quaternion;
      if (m.stride != 8) fail(element + ".byteStride", "must be 8 for QUATERNION");
    } else if (filter == "EXPONENTIAL") {
      m.filter = MeshoptFilter::Exponential;
    } else {
      fail(element + ".filter", "must be NONE, OCTAHEDRAL, QUATERNION or EXPONENTIAL (got '" +
                                    filter + "')");
    }
    if (m.count == 0) fail(element + ".count", "must be >= 1");
    // The decoded bytes fill the bufferView; both are bounded by the compressed size.
    uint64_t limit = m.length > (uint64_t(1) << 48) ? UINT64_MAX
                                                    : kMaxMeshoptExpansion * m.length + kMeshoptSlack;
    if (m.count > limit || m.count * m.stride > limit || viewLength > limit)
      fail(element, "decodes to " + std::to_string(std::max(viewLength, m.count * m.stride)) +
                        " bytes from " + std::to_string(m.length) +
                        " compressed bytes, more than meshopt's codecs can produce (at most " +
                        std::to_string(kMaxMeshoptExpansion) + "x)");
    if (m.count * m.stride > viewLength)
      fail(element, "count " + std::to_string(m.count) + " x byteStride " +
                        std::to_string(m.stride) + " is longer than " + viewElement +
                        ".byteLength " + std::to_string(viewLength));
    if (auto vs = v.find("byteStride"); m.mode == MeshoptMode::Attributes && vs != v.end() &&
                                        vs->get<uint64_t>() != m.stride)
      fail(element + ".byteStride", "must equal " + viewElement + ".byteStride");
    meshopt_.push_back(m);
    isMeshoptView_.insert(i);
    return true;
  }

  // After tinygltf: every compressed bufferView decoded into a buffer of its own, and the view
  // pointed at it, so that everything downstream reads plain bufferViews.
  void decodeMeshopt() {
    for (const MeshoptView& m : meshopt_) {
      std::string element =
          "bufferViews[" + std::to_string(m.view) + "].extensions.EXT_meshopt_compression";
      tinygltf::BufferView& view = model_.bufferViews[m.view];
      const auto& src = model_.buffers[m.buffer].data;
      if (src.size() < m.offset + m.length) fail(element, "compressed bytes missing");
      tinygltf::Buffer decoded;
      decoded.data.assign(m.viewLength, 0);
      const unsigned char* in = src.data() + m.offset;
      int rc = 0;
      switch (m.mode) {
        case MeshoptMode::Attributes:
          rc = meshopt_decodeVertexBuffer(decoded.data.data(), m.count, m.stride, in, m.length);
          break;
        case MeshoptMode::Triangles:
          rc = meshopt_decodeIndexBuffer(decoded.data.data(), m.count, m.stride, in, m.length);
          break;
        case MeshoptMode::Indices:
          rc = meshopt_decodeIndexSequence(decoded.data.data(), m.count, m.stride, in, m.length);
          break;
      }
      if (rc != 0)
        fail(element, "meshopt could not decode the data (error " + std::to_string(rc) +
                          ": malformed or truncated)");
      switch (m.filter) {
        case MeshoptFilter::None:
          break;
        case MeshoptFilter::Octahedral:
          meshopt_decodeFilterOct(decoded.data.data(), m.count, m.stride);
          break;
        case MeshoptFilter::Quaternion:
          meshopt_decodeFilterQuat(decoded.data.data(), m.count, m.stride);
          break;
        case MeshoptFilter::Exponential:
          meshopt_decodeFilterExp(decoded.data.data(), m.count, m.stride);
          break;
      }
      model_.buffers.push_back(std::move(decoded));
      bufferLengths_.push_back(m.viewLength);
      view.buffer = int(model_.buffers.size() - 1);
      view.byteOffset = 0;
      view.byteLength = m.viewLength;
    }
    // Fallback buffers without data reached tinygltf as 1-byte placeholders (runTinyGltf);
    // nothing refers to them any more.
    for (size_t i = 0; i < noDataBuffer_.size(); ++i)
      if (noDataBuffer_[i]) bufferLengths_[i] = model_.buffers[i].data.size();
  }

  // ---- KHR_draco_mesh_compression --------------------------------------------------------------

  // After tinygltf: each Draco-compressed primitive decoded; its accessors (which have no
  // bufferView of their own) pointed at new buffers holding the decoded values, so that the
  // rest of the loader reads plain accessors. Without Draco support in the build the extension
  // is refused in extensionsRequired (kSupportedExtensions) and, when only used, the
  // primitive's uncompressed fallback accessors are read.
  void decodeDraco() {
#ifdef KILN_HAVE_DRACO
    const Json& meshes = array("meshes");
    std::set<int> rewritten;
    for (size_t m = 0; m < meshes.size(); ++m) {
      const Json& prims = meshes[m]["primitives"];
      for (size_t j = 0; j < prims.size(); ++j) {
        auto ext = prims[j].find("extensions");
        if (ext == prims[j].end() || !ext->is_object()) continue;
        auto dr = ext->find("KHR_draco_mesh_compression");
        if (dr == ext->end()) continue;
        std::string element = "meshes[" + std::to_string(m) + "].primitives[" +
                              std::to_string(j) + "].extensions.KHR_draco_mesh_compression";
        decodeDracoPrimitive(*dr, model_.meshes[m].primitives[j], element, &rewritten);
      }
    }
#endif
  }

#ifdef KILN_HAVE_DRACO
  void decodeDracoPrimitive(const Json& dr, const tinygltf::Primitive& prim,
                            const std::string& element, std::set<int>* rewritten) {
    if (!dr.is_object()) fail(element, "must be an object");
    if (!dr.contains("bufferView")) fail(element, "missing required 'bufferView'");
    checkIndex(dr, "bufferView", element, model_.bufferViews.size(), "bufferViews");
    auto attrs = dr.find("attributes");
    if (attrs == dr.end() || !attrs->is_object())
      fail(element, "missing required 'attributes' object");
    const auto& view = model_.bufferViews[dr["bufferView"].get<size_t>()];
    const auto& data = model_.buffers[size_t(view.buffer)].data;
    if (view.byteOffset + view.byteLength > data.size())
      fail(element, "bufferView runs past its buffer's data");
    draco::DecoderBuffer in;
    in.Init(reinterpret_cast<const char*>(data.data() + view.byteOffset), view.byteLength);
    draco::Decoder decoder;
    auto decoded = decoder.DecodeMeshFromBuffer(&in);
    if (!decoded.ok())
      fail(element, "Draco could not decode the mesh: " + decoded.status().error_msg_string());
    std::unique_ptr<draco::Mesh> mesh = std::move(decoded).value();
    const size_t points = mesh->num_points(), faces = mesh->num_faces();
    auto claim = [&](int accessor, const std::string& what, size_t count) {
      std::string where = "accessors[" + std::to_string(accessor) + "]";
      if (!rewritten->insert(accessor).second)
        fail(where, "is used by more than one Draco-compressed primitive");
      if (model_.accessors[size_t(accessor)].count != count)
        fail(element, what + " (" + where + ") has count " +
                          std::to_string(model_.accessors[size_t(accessor)].count) +
                          ", the Draco mesh has " + std::to_string(count));
    };
    if (prim.indices >= 0) {
      claim(prim.indices, "indices", 3 * faces);
      std::vector<uint32_t> idx(3 * faces);
      for (draco::FaceIndex f(0); f < mesh->num_faces(); ++f)
        for (int c = 0; c < 3; ++c) idx[3 * f.value() + size_t(c)] = mesh->face(f)[c].value();
      replaceAccessorData(prim.indices, idx.data(), idx.size() * 4,
                          TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT);
    } else if (faces > 0) {
      fail(element, "the primitive has no 'indices' accessor for the Draco mesh's faces");
    }
    for (auto it = attrs->begin(); it != attrs->end(); ++it) {
      std::string where = element + ".attributes." + it.key();
      auto target = prim.attributes.find(it.key());
      if (target == prim.attributes.end())
        fail(where, "names an attribute the primitive does not have");
      if (!it.value().is_number_integer()) fail(where, "must be a Draco attribute id");
      const draco::PointAttribute* attr =
          mesh->GetAttributeByUniqueId(uint32_t(it.value().get<int64_t>()));
      if (!attr) fail(where, "no such attribute in the Draco mesh");
      int accessor = target->second;
      claim(accessor, it.key(), points);
      const auto& a = model_.accessors[size_t(accessor)];
      int components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
      if (components <= 0 || components > 16) fail(where, "invalid accessor type");
      // Integer attributes that are not normalized (JOINTS_n) keep their type; everything
      // else becomes FLOAT (normalized values arrive in [0, 1] or [-1, 1]).
      bool integer = !a.normalized && a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT;
      std::vector<float> f(integer ? 0 : points * size_t(components));
      std::vector<uint16_t> u(integer ? points * size_t(components) : 0);
      for (draco::PointIndex p(0); p < mesh->num_points(); ++p) {
        draco::AttributeValueIndex v = attr->mapped_index(p);
        bool ok = integer ? attr->ConvertValue<uint16_t>(v, int8_t(components),
                                                         &u[p.value() * size_t(components)])
                          : attr->ConvertValue<float>(v, int8_t(components),
                                                      &f[p.value() * size_t(components)]);
        if (!ok) fail(where, "Draco could not convert point " + std::to_string(p.value()));
      }
      if (integer)
        replaceAccessorData(accessor, u.data(), u.size() * 2,
                            TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT);
      else
        replaceAccessorData(accessor, f.data(), f.size() * 4, TINYGLTF_COMPONENT_TYPE_FLOAT);
    }
  }

  void replaceAccessorData(int accessor, const void* bytes, size_t size, int componentType) {
    tinygltf::Buffer b;
    b.data.assign(static_cast<const uint8_t*>(bytes), static_cast<const uint8_t*>(bytes) + size);
    model_.buffers.push_back(std::move(b));
    bufferLengths_.push_back(size);
    tinygltf::BufferView v;
    v.buffer = int(model_.buffers.size() - 1);
    v.byteOffset = 0;
    v.byteLength = size;
    model_.bufferViews.push_back(v);
    tinygltf::Accessor& a = model_.accessors[size_t(accessor)];
    a.bufferView = int(model_.bufferViews.size() - 1);
    a.byteOffset = 0;
    a.componentType = componentType;
    a.normalized = false;
    a.sparse.isSparse = false;
  }
#endif

  // ---- pass 3: tinygltf ---------------------------------------------------------------------

  void runTinyGltf() {
    tinygltf::TinyGLTF gltf;
    gltf.SetImageLoader(&keepEncodedImage, nullptr);
    std::string err, warn;
    bool ok;
    if (std::find(noDataBuffer_.begin(), noDataBuffer_.end(), true) != noDataBuffer_.end() ||
        !viewlessIndices_.empty())
      rewriteForTinyGltf();
    if (isGlb_) {
      if (bytes_.size() > std::numeric_limits<unsigned int>::max())
        fail("", "file too large for tinygltf (4 GiB)");
      ok = gltf.LoadBinaryFromMemory(&model_, &err, &warn, bytes_.data(),
                                     static_cast<unsigned int>(bytes_.size()), baseDir_);
    } else {
      std::string text(bytes_.begin(), bytes_.end());
      if (text.size() > std::numeric_limits<unsigned int>::max())
        fail("", "file too large for tinygltf (4 GiB)");
      ok = gltf.LoadASCIIFromString(&model_, &err, &warn, text.data(),
                                    static_cast<unsigned int>(text.size()), baseDir_);
    }
    // tinygltf's own warnings are about images we report ourselves (per texture, with what
    // kiln does about it), so they are not repeated.
    if (!ok) fail("", "invalid glTF: " + trim(err.empty() ? "tinygltf failed" : err));
    for (const ViewlessIndices& v : viewlessIndices_)
      model_.meshes[v.mesh].primitives[v.primitive].indices = v.accessor;
    bytes_.clear();
    bytes_.shrink_to_fit();
  }

  // tinygltf insists on data for every buffer and on a bufferView for every indices accessor:
  // it parses the document rewriteGltfForTinyGltf makes (the indices it leaves out are in
  // viewlessIndices_ too, restored after it).
  void rewriteForTinyGltf() { rewriteGltfForTinyGltf(doc_, &bytes_); }

  // ---- pass 4a: accessors ---------------------------------------------------------------------

  void checkAccessors() const {
    for (size_t i = 0; i < model_.buffers.size(); ++i)
      if (model_.buffers[i].data.size() < bufferLengths_[i])
        fail("buffers[" + std::to_string(i) + "]",
             "holds " + std::to_string(model_.buffers[i].data.size()) +
                 " bytes, shorter than byteLength " + std::to_string(bufferLengths_[i]));
    for (size_t i = 0; i < model_.accessors.size(); ++i) {
      const tinygltf::Accessor& a = model_.accessors[i];
      std::string element = "accessors[" + std::to_string(i) + "]";
      int size = componentSize(a.componentType);
      if (size == 0)
        fail(element, "componentType " + std::to_string(a.componentType) + " is not valid");
      int components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
      if (components <= 0) fail(element, "invalid type");
      if (a.count == 0) fail(element + ".count", "must be >= 1");
      uint64_t elementSize = uint64_t(size) * components;
      if (a.bufferView >= 0) {
        const tinygltf::BufferView& view = model_.bufferViews[size_t(a.bufferView)];
        uint64_t stride = view.byteStride ? view.byteStride : elementSize;
        if (view.byteStride && view.byteStride % size != 0)
          fail(element, "bufferViews[" + std::to_string(a.bufferView) + "].byteStride " +
                            std::to_string(view.byteStride) + " is not a multiple of the " +
                            "component size " + std::to_string(size));
        if (view.byteStride && view.byteStride < elementSize)
          fail(element, "bufferViews[" + std::to_string(a.bufferView) + "].byteStride " +
                            std::to_string(view.byteStride) + " is smaller than an element (" +
                            std::to_string(elementSize) + " bytes)");
        if (a.byteOffset % size != 0)
          fail(element + ".byteOffset", "must be a multiple of the component size");
        // In double first so that a huge count cannot overflow the exact check.
        double approx = double(a.byteOffset) + double(stride) * double(a.count - 1) + elementSize;
        if (approx > double(view.byteLength) + 1.0 ||
            a.byteOffset + stride * (a.count - 1) + elementSize > view.byteLength)
          fail(element, "byteOffset " + std::to_string(a.byteOffset) + " + count " +
                            std::to_string(a.count) + " x stride " + std::to_string(stride) +
                            " runs past bufferViews[" + std::to_string(a.bufferView) + "] (" +
                            std::to_string(view.byteLength) + " bytes)");
      } else if (a.count > kMaxElementsWithoutData) {
        // Without a bufferView the values are zeros (plus sparse entries) that cost the file
        // nothing, so the count alone would decide the allocation: bound it.
        fail(element, "count " + std::to_string(a.count) + " is too large without a bufferView");
      }
      if (a.sparse.isSparse) {
        const auto& s = a.sparse;
        if (s.count <= 0 || size_t(s.count) > a.count)
          fail(element + ".sparse.count", "must be in [1, count]");
        int indexSize = componentSize(s.indices.componentType);
        if (s.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
            s.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
            s.indices.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
          fail(element + ".sparse.indices.componentType", "must be an unsigned integer type");
        checkSparseRange(element + ".sparse.indices", s.indices.bufferView, s.indices.byteOffset,
                         uint64_t(s.count) * indexSize);
        checkSparseRange(element + ".sparse.values", s.values.bufferView, s.values.byteOffset,
                         uint64_t(s.count) * elementSize);
      }
    }
  }

  void checkSparseRange(const std::string& element, int view, int offset, uint64_t bytes) const {
    if (view < 0 || size_t(view) >= model_.bufferViews.size()) fail(element, "invalid bufferView");
    if (offset < 0) fail(element + ".byteOffset", "must be >= 0");
    const auto& v = model_.bufferViews[size_t(view)];
    if (uint64_t(offset) + bytes > v.byteLength)
      fail(element, "runs past bufferViews[" + std::to_string(view) + "] (" +
                        std::to_string(v.byteLength) + " bytes)");
  }

  const uint8_t* viewData(int view) const {
    const auto& v = model_.bufferViews[size_t(view)];
    return model_.buffers[size_t(v.buffer)].data.data() + v.byteOffset;
  }

  // Reads accessor `index` as doubles, `components` per element (sparse entries applied).
  // `expectedComponents` 0 = any. The accessor's ranges were checked by checkAccessors().
  std::vector<double> readAccessor(int index, int expectedComponents, const std::string& use,
                                   int* componentsOut = nullptr) const {
    const tinygltf::Accessor& a = model_.accessors[size_t(index)];
    std::string element = "accessors[" + std::to_string(index) + "]";
    int components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
    if (expectedComponents && (components != expectedComponents || a.type == TINYGLTF_TYPE_MAT2))
      fail(element, "has " + std::to_string(components) + " components, but " + use + " needs " +
                        std::to_string(expectedComponents));
    if (componentsOut) *componentsOut = components;
    int size = componentSize(a.componentType);
    if (a.bufferView < 0) {
      // Elements without a bufferView cost the file nothing (zeros plus sparse entries), and
      // any number of primitives may read one accessor: bound the total over the whole load,
      // so that the work follows the bytes the file really holds.
      zeroElementsRead_ += a.count;
      if (zeroElementsRead_ > kMaxElementsWithoutData)
        fail(element, "read by " + use + ": more than " +
                          std::to_string(kMaxElementsWithoutData) +
                          " accessor elements without a bufferView in the whole file (they "
                          "hold no data: zeros, or sparse values)");
    }
    std::vector<double> out(a.count * size_t(components), 0.0);
    if (a.bufferView >= 0) {
      const auto& view = model_.bufferViews[size_t(a.bufferView)];
      size_t stride = view.byteStride ? view.byteStride : size_t(size) * components;
      const uint8_t* base = viewData(a.bufferView) + a.byteOffset;
      for (size_t e = 0; e < a.count; ++e)
        for (int c = 0; c < components; ++c)
          out[e * components + c] =
              readComponent(base + e * stride + size_t(c) * size, a.componentType, a.normalized);
    }
    if (a.sparse.isSparse) {
      const auto& s = a.sparse;
      const uint8_t* indices = viewData(s.indices.bufferView) + s.indices.byteOffset;
      const uint8_t* values = viewData(s.values.bufferView) + s.values.byteOffset;
      int indexSize = componentSize(s.indices.componentType);
      for (int k = 0; k < s.count; ++k) {
        double target =
            readComponent(indices + size_t(k) * indexSize, s.indices.componentType, false);
        if (target >= double(a.count))
          fail(element + ".sparse.indices", "index " + std::to_string(uint64_t(target)) +
                                                " >= count " + std::to_string(a.count));
        for (int c = 0; c < components; ++c)
          out[size_t(target) * components + c] = readComponent(
              values + (size_t(k) * components + c) * size, a.componentType, a.normalized);
      }
    }
    return out;
  }

  // ---- pass 4b: materials and textures --------------------------------------------------------

  void convertMaterials() {
    const Json& jsonMaterials = array("materials");
    for (size_t m = 0; m < model_.materials.size(); ++m) {
      const tinygltf::Material& src = model_.materials[m];
      std::string element = "materials[" + std::to_string(m) + "]";
      Material dst;
      dst.name = src.name.empty() ? element : src.name;
      const auto& pbr = src.pbrMetallicRoughness;
      if (pbr.baseColorFactor.size() != 4)
        fail(element + ".pbrMetallicRoughness.baseColorFactor", "must have 4 numbers");
      for (int c = 0; c < 4; ++c) dst.baseColorFactor[c] = float(pbr.baseColorFactor[size_t(c)]);
      checkFactor(element + ".pbrMetallicRoughness.baseColorFactor", dst.baseColorFactor, 1.0f);
      dst.metallic = float(pbr.metallicFactor);
      dst.roughness = float(pbr.roughnessFactor);
      checkFactor(element + ".pbrMetallicRoughness.metallicFactor", vec4(dst.metallic), 1.0f);
      checkFactor(element + ".pbrMetallicRoughness.roughnessFactor", vec4(dst.roughness), 1.0f);
      if (src.alphaMode == "OPAQUE")
        dst.alphaMode = AlphaMode::Opaque;
      else if (src.alphaMode == "MASK")
        dst.alphaMode = AlphaMode::Mask;
      else if (src.alphaMode == "BLEND")
        dst.alphaMode = AlphaMode::Blend;
      else
        fail(element + ".alphaMode", "must be OPAQUE, MASK or BLEND (got '" + src.alphaMode + "')");
      dst.alphaCutoff = float(src.alphaCutoff);
      checkFactor(element + ".alphaCutoff", vec4(dst.alphaCutoff), kInfinity);
      dst.doubleSided = src.doubleSided;
      if (src.emissiveFactor.size() != 3) fail(element + ".emissiveFactor", "must have 3 numbers");
      for (int c = 0; c < 3; ++c) dst.emissiveFactor[c] = float(src.emissiveFactor[size_t(c)]);
      checkFactor(element + ".emissiveFactor", vec4(dst.emissiveFactor, 0.0f), 1.0f);

      const Json& jm = jsonMaterials[m];
      if (auto ext = jm.find("extensions"); ext != jm.end() && ext->is_object()) {
        if (auto es = ext->find("KHR_materials_emissive_strength"); es != ext->end()) {
          std::string where = element + ".extensions.KHR_materials_emissive_strength";
          if (!es->is_object()) fail(where, "must be an object");
          if (auto s = es->find("emissiveStrength"); s != es->end()) {
            if (!s->is_number() || !std::isfinite(float(s->get<double>())) || s->get<double>() < 0)
              fail(where + ".emissiveStrength", "must be a finite number >= 0");
            dst.emissiveStrength = float(s->get<double>());
          }
        }
      }

      dst.baseColorTexture = useTexture(pbr.baseColorTexture.index,
                                        element + ".pbrMetallicRoughness.baseColorTexture");
      int baseSet = pbr.baseColorTexture.texCoord, emissiveSet = src.emissiveTexture.texCoord;
      if (auto p = jm.find("pbrMetallicRoughness"); p != jm.end() && p->is_object())
        if (auto t = p->find("baseColorTexture"); t != p->end())
          dst.baseColorTransform = textureTransform(
              *t, element + ".pbrMetallicRoughness.baseColorTexture", &baseSet);
      if (auto t = jm.find("emissiveTexture"); t != jm.end())
        dst.emissiveTransform = textureTransform(*t, element + ".emissiveTexture", &emissiveSet);
      dst.baseColorTexCoord =
          texCoordSet(baseSet, element + ".pbrMetallicRoughness.baseColorTexture");
      dst.emissiveTexture = useTexture(src.emissiveTexture.index, element + ".emissiveTexture");
      dst.emissiveTexCoord = texCoordSet(emissiveSet, element + ".emissiveTexture");
      scene_.materials.push_back(std::move(dst));
    }
  }

  // A textureInfo's KHR_texture_transform (identity when absent); its 'texCoord', when given,
  // replaces *texCoord (the extension's rule).
  TextureTransform textureTransform(const Json& info, const std::string& infoElement,
                                    int* texCoord) const {
    TextureTransform t;
    if (!info.is_object()) return t;
    auto ext = info.find("extensions");
    if (ext == info.end() || !ext->is_object()) return t;
    auto tt = ext->find("KHR_texture_transform");
    if (tt == ext->end()) return t;
    std::string element = infoElement + ".extensions.KHR_texture_transform";
    if (!tt->is_object()) fail(element, "must be an object");
    auto number = [&](const Json& v, const std::string& where) {
      if (!v.is_number() || !std::isfinite(float(v.get<double>())))
        fail(where, "must be a finite number");
      return float(v.get<double>());
    };
    auto pair = [&](const char* key, vec2* out) {
      auto it = tt->find(key);
      if (it == tt->end()) return;
      if (!it->is_array() || it->size() != 2)
        fail(element + "." + key, "must be an array of 2 numbers");
      for (int c = 0; c < 2; ++c) (*out)[c] = number((*it)[size_t(c)], element + "." + key);
    };
    pair("offset", &t.offset);
    pair("scale", &t.scale);
    if (auto r = tt->find("rotation"); r != tt->end()) t.rotation = number(*r, element + ".rotation");
    if (auto c = tt->find("texCoord"); c != tt->end()) {
      if (!c->is_number_integer() || c->get<int64_t>() < 0 || c->get<int64_t>() > 1 << 20)
        fail(element + ".texCoord", "must be an integer >= 0");
      *texCoord = int(c->get<int64_t>());
    }
    return t;
  }

  // Rejects non-finite or negative factors and values above `max`.
  void checkFactor(const std::string& element, vec4 v, float max) const {
    for (int c = 0; c < 4; ++c)
      if (!std::isfinite(v[c]) || v[c] < 0.0f || v[c] > max)
        fail(element, max == kInfinity
                          ? "must be finite and >= 0"
                          : "must be finite and in [0, " + std::to_string(int(max)) + "]");
  }

  int texCoordSet(int set, const std::string& element) {
    if (set == 0 || set == 1) return set;
    if (set < 0) fail(element + ".texCoord", "must be >= 0");
    warn(element + ".texCoord", "TEXCOORD_" + std::to_string(set) +
                                    " is not supported (kiln reads TEXCOORD_0 and _1), using 0");
    return 0;
  }

  // Maps a glTF texture to a kiln texture, decoding it the first time (sRGB: kiln only uses
  // base colour and emissive textures, which glTF defines as sRGB). -1 = use the factor.
  int useTexture(int gltfTexture, const std::string& user) {
    if (gltfTexture < 0 || !options_.loadTextures) return -1;
    auto known = textureMap_.find(gltfTexture);
    if (known != textureMap_.end()) return known->second;
    if (options_.cancel && options_.cancel->load()) fail("", "cancelled");
    int result = decodeTexture(gltfTexture);
    textureMap_[gltfTexture] = result;
    if (options_.textureProgress) {
      if (texturesUsed_ == 0) texturesUsed_ = countUsedTextures();
      options_.textureProgress(textureMap_.size(), texturesUsed_);
    }
    return result;
  }

  // How many distinct textures the materials use (what useTexture will decode), for progress.
  size_t countUsedTextures() const {
    std::vector<uint8_t> used(model_.textures.size(), 0);
    auto mark = [&](int t) {
      if (t >= 0 && size_t(t) < used.size()) used[size_t(t)] = 1;
    };
    for (const tinygltf::Material& m : model_.materials) {
      mark(m.pbrMetallicRoughness.baseColorTexture.index);
      mark(m.emissiveTexture.index);
    }
    return std::max<size_t>(1, size_t(std::count(used.begin(), used.end(), uint8_t(1))));
  }

  int decodeTexture(int t) {
    std::string element = "textures[" + std::to_string(t) + "]";
    const tinygltf::Texture& tex = model_.textures[size_t(t)];
    if (tex.source < 0) {
      warn(element, "no image kiln can read (no 'source'), using the factor");
      return -1;
    }
    // Textures that share an image and sampler state share one decoded kiln texture: many
    // glTF textures may point at one image (40 over a 4096^2 PNG took 10.6 GB when each was
    // decoded anew), so the decoding work follows the images, not the texture count.
    TextureSampler sampler;
    if (tex.sampler >= 0) {
      const tinygltf::Sampler& s = model_.samplers[size_t(tex.sampler)];
      std::string where = "samplers[" + std::to_string(tex.sampler) + "]";
      sampler.wrapS = wrapMode(s.wrapS, where + ".wrapS");
      sampler.wrapT = wrapMode(s.wrapT, where + ".wrapT");
      sampler.nearest = s.magFilter == TINYGLTF_TEXTURE_FILTER_NEAREST;
      if (s.magFilter != -1 && s.magFilter != TINYGLTF_TEXTURE_FILTER_NEAREST &&
          s.magFilter != TINYGLTF_TEXTURE_FILTER_LINEAR)
        fail(where + ".magFilter", "must be 9728 (NEAREST) or 9729 (LINEAR)");
    }
    auto key = std::make_tuple(tex.source, int(sampler.wrapS), int(sampler.wrapT),
                               sampler.nearest);
    if (auto known = decodedImages_.find(key); known != decodedImages_.end())
      return known->second;
    int decoded = decodeImage(t, tex.source, sampler);
    decodedImages_[key] = decoded;
    return decoded;
  }

  int decodeImage(int t, int source, const TextureSampler& sampler) {
    std::string element = "textures[" + std::to_string(t) + "]";
    const tinygltf::Image& img = model_.images[size_t(source)];
    std::string label = !img.uri.empty() && !isDataUri(img.uri) ? img.uri
                        : !img.name.empty()                     ? img.name
                                            : "images[" + std::to_string(source) + "]";
    if (img.image.empty()) {
      warn(element, "image '" + label + "' not found, using the factor");
      return -1;
    }
    const auto* data = img.image.data();
    int size = int(img.image.size());
    int w = 0, h = 0, n = 0;
    // A PNG's size is in its IHDR chunk. Read it here: stb_image refuses PNGs above 2^30 bytes
    // decoded with "too large", then tries its other formats and reports "unknown image type".
    static const uint8_t kPngMagic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    if (size >= 24 && std::memcmp(data, kPngMagic, 8) == 0 &&
        std::memcmp(data + 12, "IHDR", 4) == 0) {
      auto be32 = [&](int at) {
        return uint32_t(data[at]) << 24 | uint32_t(data[at + 1]) << 16 |
               uint32_t(data[at + 2]) << 8 | uint32_t(data[at + 3]);
      };
      uint64_t pw = be32(16), ph = be32(20);
      if (pw * ph > kMaxImagePixels || pw > uint64_t(INT32_MAX) || ph > uint64_t(INT32_MAX)) {
        warn(element, "image '" + label + "' is too large (PNG of " + std::to_string(pw) + "x" +
                          std::to_string(ph) + " pixels; kiln decodes images of up to " +
                          std::to_string(kMaxImagePixels) + " pixels), using the factor");
        return -1;
      }
    }
    if (!stbi_info_from_memory(data, size, &w, &h, &n)) {
      warn(element, "image '" + label + "' could not be decoded (" +
                        (stbi_failure_reason() ? stbi_failure_reason() : "unknown format") +
                        "), using the factor");
      return -1;
    }
    if (w <= 0 || h <= 0 || uint64_t(w) * uint64_t(h) > kMaxImagePixels) {
      warn(element, "image '" + label + "' is too large (" + std::to_string(w) + "x" +
                        std::to_string(h) + " pixels; kiln decodes images of up to " +
                        std::to_string(kMaxImagePixels) + " pixels), using the factor");
      return -1;
    }
    Texture out;
    out.name = element + " (" + label + ")";
    out.image = Image(w, h, 4);
    bool ok = false;
    if (stbi_is_16_bit_from_memory(data, size)) {
      if (stbi_us* px = stbi_load_16_from_memory(data, size, &w, &h, &n, 4)) {
        for (size_t i = 0; i < size_t(w) * h * 4; ++i) out.image.pixels[i] = px[i] / 65535.0f;
        stbi_image_free(px);
        ok = true;
      }
    } else if (stbi_uc* px = stbi_load_from_memory(data, size, &w, &h, &n, 4)) {
      for (size_t i = 0; i < size_t(w) * h * 4; ++i) out.image.pixels[i] = px[i] / 255.0f;
      stbi_image_free(px);
      ok = true;
    }
    if (!ok) {
      warn(element, "image '" + label + "' could not be decoded (" +
                        (stbi_failure_reason() ? stbi_failure_reason() : "unknown") +
                        "), using the factor");
      return -1;
    }
    glm::dvec4 sum(0.0);
    for (size_t i = 0; i < size_t(w) * h; ++i) {
      float* p = &out.image.pixels[i * 4];
      for (int c = 0; c < 3; ++c) p[c] = srgbToLinear(p[c]);
      sum += glm::dvec4(p[0], p[1], p[2], p[3]);
    }
    out.average = vec4(sum / double(size_t(w) * h));
    out.sampler = sampler;
    scene_.textures.push_back(std::move(out));
    return int(scene_.textures.size() - 1);
  }

  Wrap wrapMode(int value, const std::string& element) const {
    if (value == int(Wrap::Repeat) || value == int(Wrap::ClampToEdge) ||
        value == int(Wrap::MirroredRepeat))
      return Wrap(value);
    fail(element, "must be 10497 (REPEAT), 33071 (CLAMP_TO_EDGE) or 33648 (MIRRORED_REPEAT)");
  }

  // ---- pass 4c: the node hierarchy ------------------------------------------------------------

  glm::dmat4 localMatrix(size_t i) const {
    const tinygltf::Node& n = model_.nodes[i];
    std::string element = "nodes[" + std::to_string(i) + "]";
    auto finite = [&](const std::vector<double>& v, const char* what) {
      for (double x : v)
        if (!std::isfinite(float(x))) fail(element + "." + what, "must be finite");
    };
    if (!n.matrix.empty()) {
      if (n.matrix.size() != 16) fail(element + ".matrix", "must have 16 numbers");
      finite(n.matrix, "matrix");
      return glm::make_mat4(n.matrix.data());  // glTF matrices are column-major like GLM
    }
    glm::dmat4 m(1.0);
    if (!n.translation.empty()) {
      if (n.translation.size() != 3) fail(element + ".translation", "must have 3 numbers");
      finite(n.translation, "translation");
      m = glm::translate(m, glm::dvec3(n.translation[0], n.translation[1], n.translation[2]));
    }
    if (!n.rotation.empty()) {
      if (n.rotation.size() != 4) fail(element + ".rotation", "must have 4 numbers (x, y, z, w)");
      finite(n.rotation, "rotation");
      glm::dquat q(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]);
      double len = glm::length(q);
      if (!(len > 1e-12)) fail(element + ".rotation", "is not a unit quaternion");
      m = m * glm::mat4_cast(q / len);
    }
    if (!n.scale.empty()) {
      if (n.scale.size() != 3) fail(element + ".scale", "must have 3 numbers");
      finite(n.scale, "scale");
      m = glm::scale(m, glm::dvec3(n.scale[0], n.scale[1], n.scale[2]));
    }
    return m;
  }

  void convertScene() {
    size_t nodeCount = model_.nodes.size();
    // Parents: glTF requires the node graph to be a forest (one parent at most).
    std::vector<int> parent(nodeCount, -1);
    for (size_t i = 0; i < nodeCount; ++i)
      for (int c : model_.nodes[i].children) {
        if (parent[size_t(c)] != -1 || size_t(c) == i)
          fail("nodes[" + std::to_string(i) + "].children",
               "nodes[" + std::to_string(c) + "] has more than one parent or is its own child");
        parent[size_t(c)] = int(i);
      }
    std::vector<int> roots;
    int sceneIndex = -1;
    size_t sceneCount = model_.scenes.size();
    if (options_.scene >= 0) {
      if (size_t(options_.scene) >= sceneCount)
        fail("scenes", "scene " + std::to_string(options_.scene) + " was asked for, but the file has " +
                           std::to_string(sceneCount) + " scene(s) (numbered from 0)");
      sceneIndex = options_.scene;
    } else if (model_.defaultScene >= 0) {
      sceneIndex = model_.defaultScene;
    } else if (sceneCount > 0) {
      sceneIndex = 0;
    }
    if (options_.scene < 0 && sceneCount > 1)
      warn("scenes", "scene " + std::to_string(sceneIndex) + " of " + std::to_string(sceneCount) +
                         " loaded (the file's default); --scene N chooses another");
    scene_.gltfScene = sceneIndex;
    if (sceneIndex >= 0) {
      roots = model_.scenes[size_t(sceneIndex)].nodes;
      for (int r : roots)
        if (parent[size_t(r)] != -1)
          fail("scenes[" + std::to_string(sceneIndex) + "].nodes",
               "nodes[" + std::to_string(r) + "] is not a root node (it is a child of nodes[" +
                   std::to_string(parent[size_t(r)]) + "])");
    } else {
      for (size_t i = 0; i < nodeCount; ++i)
        if (parent[i] == -1) roots.push_back(int(i));
    }

    // A cycle (0 -> 1 -> 0) gives every node in it a parent, so no root reaches it and it
    // would vanish without a word: say so. One walk up the parents per node, stopping at nodes
    // already walked, keeps this linear in the node count. (A scene that lists a node of a
    // cycle was refused above: it is not a root.)
    {
      std::vector<size_t> walk(nodeCount, 0);  // 0 = not walked yet, else the walk's number
      for (size_t i = 0; i < nodeCount; ++i) {
        size_t j = i;
        while (walk[j] == 0) {
          walk[j] = i + 1;
          if (parent[j] < 0) break;
          j = size_t(parent[j]);
        }
        if (walk[j] == i + 1 && parent[j] >= 0)
          warn("nodes[" + std::to_string(j) + "]",
               "is part of a cycle of children (glTF nodes must form trees): it and its "
               "descendants are ignored");
      }
    }

    // Depth-first, iteratively; with single parents and root starts this visits each node
    // once, and a cycle (nodes reachable only from each other) is never entered.
    std::vector<bool> visited(nodeCount, false);
    std::vector<std::pair<int, glm::dmat4>> stack;
    for (auto it = roots.rbegin(); it != roots.rend(); ++it)
      stack.emplace_back(*it, glm::dmat4(1.0));
    std::vector<std::pair<int, glm::dmat4>> order;  // nodes in visit order with world matrices
    while (!stack.empty()) {
      auto [node, parentWorld] = stack.back();
      stack.pop_back();
      if (visited[size_t(node)])
        fail(sceneIndex >= 0 ? "scenes[" + std::to_string(sceneIndex) + "].nodes" : "nodes",
             "nodes[" + std::to_string(node) + "] is listed more than once");
      visited[size_t(node)] = true;
      glm::dmat4 world = parentWorld * localMatrix(size_t(node));
      order.emplace_back(node, world);
      const auto& children = model_.nodes[size_t(node)].children;
      for (auto it = children.rbegin(); it != children.rend(); ++it) stack.emplace_back(*it, world);
    }

    // World matrices of the scene's nodes first: skins need their joints' before any mesh.
    nodeWorld_.assign(nodeCount, glm::dmat4(1.0));
    inScene_.assign(nodeCount, false);
    for (const auto& [node, world] : order) {
      nodeWorld_[size_t(node)] = world;
      inScene_[size_t(node)] = true;
    }
    for (const auto& [node, world] : order) convertNode(node, world);

    if (defaultMaterialUsed_) {
      Material m;
      m.name = "default";
      scene_.materials.push_back(m);  // glTF's default: white, metallic 1, roughness 1
    }
    if (sceneIndex >= 0) convertSceneExtras(sceneIndex);
  }

  std::string nodeName(int node) const {
    const auto& n = model_.nodes[size_t(node)];
    return n.name.empty() ? "nodes[" + std::to_string(node) + "]" : n.name;
  }

  void convertNode(int node, const glm::dmat4& world) {
    const tinygltf::Node& n = model_.nodes[size_t(node)];
    std::string element = "nodes[" + std::to_string(node) + "]";
    ObjectSettings settings;
    std::vector<vec3> probes;
    bool hasProbes = false;
    readNodeExtras(node, world, &settings, &probes, &hasProbes);

    if (n.mesh >= 0) convertMesh(node, world, settings);
    if (hasProbes) {
      ProbeGroup g;
      g.name = nodeName(node);
      g.nodeIndex = node;
      g.positions = std::move(probes);
      scene_.probeGroups.push_back(std::move(g));
    }
    if (n.camera >= 0) convertCamera(node, world);
    const Json& jn = array("nodes")[size_t(node)];
    if (auto ext = jn.find("extensions"); ext != jn.end() && ext->is_object())
      if (auto lp = ext->find("KHR_lights_punctual"); lp != ext->end())
        convertLight(lp->at("light").get<int>(), node, world);
  }

  // ---- extras.kiln ------------------------------------------------------------------------------

  // The extras.kiln object of a JSON element, or null when absent. `element` names it.
  const Json* kilnExtras(const Json& obj, const std::string& element) const {
    auto extras = obj.find("extras");
    if (extras == obj.end() || !extras->is_object()) return nullptr;
    auto kiln = extras->find("kiln");
    if (kiln == extras->end()) return nullptr;
    if (!kiln->is_object()) fail(element + ".extras.kiln", "must be an object");
    return &*kiln;
  }

  // Typed readers for extras.kiln values; each fails naming the key.
  struct Extras {
    const Loader* loader;
    const Json& obj;
    std::string element;  // "...extras.kiln"
    std::set<std::string> known;

    const Json* find(const char* key) {
      known.insert(key);
      auto it = obj.find(key);
      return it == obj.end() ? nullptr : &*it;
    }
    std::string where(const char* key) const { return element + "." + key; }
    std::optional<bool> boolean(const char* key) {
      const Json* v = find(key);
      if (!v) return std::nullopt;
      if (!v->is_boolean()) loader->fail(where(key), "must be true or false");
      return v->get<bool>();
    }
    // A finite number in [lo, hi]; `range` describes it for the message.
    std::optional<float> number(const char* key, double lo, double hi, const std::string& range,
                                bool loExclusive = false) {
      const Json* v = find(key);
      if (!v) return std::nullopt;
      double d = v->is_number() ? v->get<double>() : std::nan("");
      if (!v->is_number() || !std::isfinite(float(d)) || d < lo || d > hi ||
          (loExclusive && d == lo))
        loader->fail(where(key), "must be a number " + range);
      return float(d);
    }
    std::optional<int> integer(const char* key, int64_t lo, int64_t hi, const std::string& range) {
      const Json* v = find(key);
      if (!v) return std::nullopt;
      bool integral = v->is_number_integer() ||
                      (v->is_number_float() && std::floor(v->get<double>()) == v->get<double>() &&
                       std::abs(v->get<double>()) < 1e15);
      if (!integral) loader->fail(where(key), "must be an integer " + range);
      int64_t i = v->is_number_float() ? int64_t(v->get<double>()) : v->get<int64_t>();
      if (v->is_number_unsigned() && v->get<uint64_t>() > uint64_t(INT64_MAX)) i = INT64_MAX;
      if (i < lo || i > hi) loader->fail(where(key), "must be an integer " + range);
      return int(i);
    }
    std::optional<std::string> choice(const char* key, std::initializer_list<const char*> options) {
      const Json* v = find(key);
      if (!v) return std::nullopt;
      std::string list;
      bool match = false;
      for (const char* o : options) {
        list += std::string(list.empty() ? "" : " | ") + "\"" + o + "\"";
        if (v->is_string() && v->get<std::string>() == o) match = true;
      }
      if (!match) loader->fail(where(key), "must be one of " + list);
      return v->get<std::string>();
    }
    std::optional<std::string> string(const char* key) {
      const Json* v = find(key);
      if (!v) return std::nullopt;
      if (!v->is_string() || v->get<std::string>().empty())
        loader->fail(where(key), "must be a non-empty string");
      return v->get<std::string>();
    }
    // Unknown keys are probably typos: say so instead of ignoring them silently.
    void warnUnknown(Loader* l) const {
      for (auto it = obj.begin(); it != obj.end(); ++it)
        if (!known.count(it.key())) l->warn(element, "unknown key '" + it.key() + "' ignored");
    }
  };

  static vec3 readVec3(const Loader* loader, const Json& v, const std::string& element,
                       bool nonNegative) {
    if (!v.is_array() || v.size() != 3)
      loader->fail(element, std::string("must be an array of 3 ") +
                                (nonNegative ? "numbers >= 0" : "numbers"));
    vec3 out;
    for (int c = 0; c < 3; ++c) {
      if (!v[size_t(c)].is_number()) loader->fail(element, "must be an array of 3 numbers");
      out[c] = float(v[size_t(c)].get<double>());
      if (!std::isfinite(out[c]) || (nonNegative && out[c] < 0.0f))
        loader->fail(element, nonNegative ? "must be finite numbers >= 0" : "must be finite");
    }
    return out;
  }

  void readNodeExtras(int node, const glm::dmat4& world, ObjectSettings* settings,
                      std::vector<vec3>* probes, bool* hasProbes) {
    std::string element = "nodes[" + std::to_string(node) + "]";
    const Json* k = kilnExtras(array("nodes")[size_t(node)], element);
    if (!k) return;
    Extras e{this, *k, element + ".extras.kiln", {}};
    if (auto v = e.boolean("static")) settings->isStatic = *v;
    if (auto v = e.number("scaleInLightmap", 0.0, 1e9, ">= 0")) settings->scaleInLightmap = *v;
    if (auto v = e.choice("receiveGI", {"lightmaps", "probes"}))
      settings->receiveGI = *v == "probes" ? ReceiveGI::Probes : ReceiveGI::Lightmaps;
    if (auto v = e.boolean("lppv")) settings->lppv = *v;
    if (auto v = e.boolean("castShadows")) settings->castShadows = *v;
    e.find("lightmap");  // kiln bake writes it into its output glTF; a bake of that repacks
    e.find("probeSH");         // kiln bake writes them for probe-lit nodes (docs/
    e.find("probeOcclusion");  // lightmap_outputs.md); a bake of that output bakes them again
    if (const Json* p = e.find("probes")) {
      if (!p->is_array()) fail(e.where("probes"), "must be an array of [x, y, z] positions");
      *hasProbes = true;
      for (size_t i = 0; i < p->size(); ++i) {
        vec3 local =
            readVec3(this, (*p)[i], e.where("probes") + "[" + std::to_string(i) + "]", false);
        glm::dvec4 w = world * glm::dvec4(glm::dvec3(local), 1.0);
        vec3 pw(w);
        if (!isFinite(pw))
          fail(e.where("probes") + "[" + std::to_string(i) + "]", "is not finite in world space");
        probes->push_back(pw);
      }
    }
    e.warnUnknown(this);
  }

  // kiln reads scene settings from the scene's extras.kiln, not from the root's. The root's
  // holds only what kiln bake writes there ("lightmaps", the output glTF's list); anything
  // else is a setting put in the wrong place: say where it belongs.
  void checkRootExtras(int sceneIndex) {
    auto extras = doc_.find("extras");
    if (extras == doc_.end() || !extras->is_object()) return;
    auto k = extras->find("kiln");
    if (k == extras->end()) return;
    const std::string where = "scenes[" + std::to_string(std::max(sceneIndex, 0)) + "]";
    if (!k->is_object()) {
      warn("extras.kiln",
           "root extras.kiln is ignored; put scene settings in " + where + ".extras.kiln");
      return;
    }
    std::string keys;
    for (auto it = k->begin(); it != k->end(); ++it)
      if (it.key() != "lightmaps") keys += std::string(keys.empty() ? "'" : ", '") + it.key() + "'";
    if (!keys.empty())
      warn("extras.kiln", "root extras.kiln is ignored (" + keys + "); put scene settings in " +
                              where + ".extras.kiln");
  }

  void convertSceneExtras(int sceneIndex) {
    checkRootExtras(sceneIndex);
    std::string element = "scenes[" + std::to_string(sceneIndex) + "]";
    const Json* k = kilnExtras(array("scenes")[size_t(sceneIndex)], element);
    if (!k) return;
    Extras e{this, *k, element + ".extras.kiln", {}};
    SceneSettings& s = scene_.settings;
    s.lightingMode = e.choice("lightingMode", {"baked-indirect", "shadowmask", "subtractive"});
    s.lightmapResolution = e.number("lightmapResolution", 0.0, 1e6, "> 0", true);
    s.lightmapPadding = e.integer("lightmapPadding", 0, 1024, "in [0, 1024]");
    s.lightmapMaxSize = e.integer("lightmapMaxSize", 1, 65536, "in [1, 65536]");
    s.directionalMode = e.choice("directionalMode", {"non-directional", "directional", "sh"});
    s.bounces = e.integer("bounces", 0, 1000, "in [0, 1000]");
    s.albedoBoost = e.number("albedoBoost", 0.0, 1e3, "> 0", true);
    s.indirectIntensity = e.number("indirectIntensity", 0.0, 1e6, ">= 0");
    s.ambientOcclusion = e.boolean("ambientOcclusion");
    s.aoMaxDistance = e.number("aoMaxDistance", 0.0, 1e9, ">= 0");
    s.aoAmount = e.number("aoAmount", 0.0, 1e3, ">= 0");
    // Preset names belong to the tools that apply them; here only the type is checked.
    s.quality = e.string("quality");
    if (const Json* c = e.find("shadowColor"))
      s.shadowColor = readVec3(this, *c, e.where("shadowColor"), true);
    if (const Json* sky = e.find("sky")) convertSky(*sky, e.where("sky"));
    e.warnUnknown(this);
  }

  void convertSky(const Json& sky, const std::string& element) {
    if (!sky.is_object()) fail(element, "must be an object with 'color' or 'map'");
    Extras e{this, sky, element, {}};
    const Json* color = e.find("color");
    auto map = e.string("map");
    auto intensity = e.number("intensity", 0.0, 1e9, ">= 0");
    auto rotation = e.number("rotation", -1e6, 1e6, "(degrees)");
    e.warnUnknown(this);
    if (color && map) fail(element, "has both 'color' and 'map'");
    if (color) {
      // "intensity" scales a constant colour too, so both kinds of sky read the same way.
      vec3 c = readVec3(this, *color, element + ".color", true);
      scene_.sky = Sky::constant(c * intensity.value_or(1.0f));
      return;
    }
    if (!map) fail(element, "needs 'color' or 'map'");
    if (!options_.loadSkyMap) return;
    std::string file = (fs::path(baseDir_) / *map).string();
    Result<Sky> loaded = Sky::fromFile(file, intensity.value_or(1.0f), rotation.value_or(0.0f));
    if (!loaded) fail(element + ".map", "cannot load '" + *map + "': " + loaded.error());
    scene_.sky = std::move(loaded).value();
  }

  // ---- lights and cameras -----------------------------------------------------------------------

  void convertLight(int index, int node, const glm::dmat4& world) {
    const Json& jl = doc_.at("extensions").at("KHR_lights_punctual").at("lights").at(size_t(index));
    std::string element = "extensions.KHR_lights_punctual.lights[" + std::to_string(index) + "]";
    if (!jl.is_object()) fail(element, "must be an object");
    Light l;
    l.lightIndex = index;
    l.nodeIndex = node;
    Extras e{this, jl, element, {}};
    auto type = e.choice("type", {"directional", "point", "spot"});
    if (!type) fail(element, "missing required 'type'");
    l.type = *type == "directional" ? LightType::Directional
             : *type == "spot"      ? LightType::Spot
                                    : LightType::Point;
    if (const Json* name = e.find("name"); name && name->is_string())
      l.name = name->get<std::string>();
    if (l.name.empty()) l.name = "lights[" + std::to_string(index) + "]";
    if (const Json* c = e.find("color")) l.color = readVec3(this, *c, element + ".color", true);
    if (auto v = e.number("intensity", 0.0, 1e30, ">= 0")) l.intensity = *v;
    if (auto v = e.number("range", 0.0, 1e30, ">= 0 (0 = unlimited)")) l.range = *v;
    if (l.type == LightType::Spot) {
      const Json* spot = e.find("spot");
      if (!spot || !spot->is_object()) fail(element + ".spot", "missing or not an object");
      Extras s{this, *spot, element + ".spot", {}};
      if (auto v = s.number("innerConeAngle", 0.0, kPi / 2, "in [0, pi/2]")) l.innerConeAngle = *v;
      if (auto v = s.number("outerConeAngle", 0.0, kPi / 2, "in (0, pi/2]", true))
        l.outerConeAngle = *v;
      if (l.innerConeAngle >= l.outerConeAngle)
        fail(element + ".spot", "innerConeAngle must be smaller than outerConeAngle");
    }
    l.position = vec3(world[3]);
    glm::dvec3 dir = glm::dvec3(world * glm::dvec4(0.0, 0.0, -1.0, 0.0));
    if (!(glm::length(dir) > 1e-12) || !isFinite(vec3(dir)) || !isFinite(l.position))
      fail("nodes[" + std::to_string(node) + "]", "light transform is degenerate");
    l.direction = vec3(glm::normalize(dir));

    if (const Json* k = kilnExtras(jl, element)) {
      Extras x{this, *k, element + ".extras.kiln", {}};
      if (auto m = x.choice("mode", {"baked", "mixed", "realtime"}))
        l.mode = *m == "mixed"      ? LightMode::Mixed
                 : *m == "realtime" ? LightMode::Realtime
                                    : LightMode::Baked;
      if (auto v = x.number("bounceIntensity", 0.0, 1e6, ">= 0")) l.bounceIntensity = *v;
      if (auto v = x.number("shadowRadius", 0.0, 1e9, ">= 0")) l.shadowRadius = *v;
      if (auto v = x.number("shadowAngle", 0.0, 90.0, "in [0, 90] (degrees)")) l.shadowAngle = *v;
      if (auto v = x.integer("shadowSamples", 1, 65536, "in [1, 65536]")) l.shadowSamples = *v;
      if (auto v = x.boolean("bakedShadows")) l.bakedShadows = *v;
      x.boolean("baked");  // kiln bake's mark in its output glTF, for viewers
      x.warnUnknown(this);
    }
    scene_.lights.push_back(std::move(l));
  }

  void convertCamera(int node, const glm::dmat4& world) {
    int index = model_.nodes[size_t(node)].camera;
    const tinygltf::Camera& c = model_.cameras[size_t(index)];
    std::string element = "cameras[" + std::to_string(index) + "]";
    Camera cam;
    cam.name = !c.name.empty() ? c.name : nodeName(node);
    cam.nodeIndex = node;
    auto positive = [&](double v, const char* what, bool allowZero) {
      if (!std::isfinite(float(v)) || v < 0.0 || (!allowZero && v == 0.0))
        fail(element + "." + what,
             allowZero ? "must be finite and >= 0" : "must be finite and > 0");
      return float(v);
    };
    if (c.type == "perspective") {
      cam.perspective = true;
      cam.yfov = positive(c.perspective.yfov, "perspective.yfov", false);
      cam.aspectRatio = positive(c.perspective.aspectRatio, "perspective.aspectRatio", true);
      cam.znear = positive(c.perspective.znear, "perspective.znear", false);
      cam.zfar = positive(c.perspective.zfar, "perspective.zfar", true);
    } else if (c.type == "orthographic") {
      cam.perspective = false;
      cam.xmag = std::abs(float(c.orthographic.xmag));
      cam.ymag = std::abs(float(c.orthographic.ymag));
      if (!(cam.xmag > 0.0f) || !(cam.ymag > 0.0f) || !std::isfinite(cam.xmag) ||
          !std::isfinite(cam.ymag))
        fail(element + ".orthographic", "xmag and ymag must be finite and non-zero");
      cam.znear = positive(c.orthographic.znear, "orthographic.znear", true);
      cam.zfar = positive(c.orthographic.zfar, "orthographic.zfar", true);
    } else {
      fail(element + ".type", "must be \"perspective\" or \"orthographic\"");
    }
    cam.worldFromCamera = mat4(world);
    scene_.cameras.push_back(std::move(cam));
  }

  // ---- meshes -----------------------------------------------------------------------------------

  void convertMesh(int node, const glm::dmat4& world, const ObjectSettings& settings) {
    const tinygltf::Node& n = model_.nodes[size_t(node)];
    const tinygltf::Mesh& mesh = model_.meshes[size_t(n.mesh)];
    std::string meshElement = "meshes[" + std::to_string(n.mesh) + "]";
    std::string meshLabel =
        mesh.name.empty() ? meshElement : "'" + mesh.name + "' (" + meshElement + ")";

    mat4 positionMatrix(world);
    mat3 linear(world);
    float det = glm::determinant(linear);
    // Normals go by the inverse transpose: the cofactor matrix / det. Only its direction
    // matters, so the cofactor times sign(det) also works for singular (det = 0) transforms.
    mat3 cofactor(glm::cross(linear[1], linear[2]), glm::cross(linear[2], linear[0]),
                  glm::cross(linear[0], linear[1]));
    mat3 normalMatrix = det < 0.0f ? -cofactor : cofactor;
    bool flip = det < 0.0f;  // a mirroring transform turns CCW into CW: flip to keep fronts

    Object obj;
    obj.name = nodeName(node);
    obj.nodeIndex = node;
    obj.meshIndex = n.mesh;
    obj.settings = settings;

    // Skins: posed by the joints' world matrices (glTF ignores the skinned node's own
    // transform); morph targets: the node's weights, else the mesh's default weights.
    std::vector<glm::dmat4> joints;
    if (n.skin >= 0) joints = jointMatrices(n.skin);
    const std::vector<double>& weights = !n.weights.empty() ? n.weights : mesh.weights;
    std::string weightsElement = !n.weights.empty() ? "nodes[" + std::to_string(node) + "].weights"
                                                    : meshElement + ".weights";
    for (double w : weights)
      if (!std::isfinite(w)) fail(weightsElement, "must be finite numbers");

    DropCounts drops;
    std::vector<PrimitiveGeometry> prims;
    for (size_t j = 0; j < mesh.primitives.size(); ++j) {
      std::string element = meshElement + ".primitives[" + std::to_string(j) + "]";
      prims.push_back(convertPrimitive(mesh.primitives[j], element, positionMatrix, normalMatrix,
                                       flip, n.skin >= 0 ? &joints : nullptr, weights,
                                       weightsElement, &drops));
    }

    bool anyUv0 = false, allUv0 = true, anyUv1 = false, allUv1 = true;
    for (const auto& p : prims) {
      anyUv0 |= p.hasUv0;
      allUv0 &= p.hasUv0;
      anyUv1 |= p.hasUv1;
      allUv1 &= p.hasUv1;
    }
    for (auto& p : prims) {
      uint32_t base = uint32_t(obj.positions.size());
      obj.positions.insert(obj.positions.end(), p.positions.begin(), p.positions.end());
      obj.normals.insert(obj.normals.end(), p.normals.begin(), p.normals.end());
      if (anyUv0) {
        if (!p.hasUv0) p.uv0.assign(p.positions.size(), vec2(0.0f));
        obj.uv0.insert(obj.uv0.end(), p.uv0.begin(), p.uv0.end());
      }
      if (anyUv1) {
        if (!p.hasUv1) p.uv1.assign(p.positions.size(), vec2(0.0f));
        obj.uv1.insert(obj.uv1.end(), p.uv1.begin(), p.uv1.end());
      }
      for (uvec3 t : p.triangles) {
        obj.triangles.push_back(t + uvec3(base));
        obj.triangleMaterial.push_back(p.material);
      }
    }

    std::string who = "nodes[" + std::to_string(node) + "] '" + obj.name + "'";
    if (anyUv0 && !allUv0)
      warn(who,
           "mesh " + meshLabel + ": TEXCOORD_0 missing on some primitives, filled with (0, 0)");
    if (anyUv1 && !allUv1)
      warn(who,
           "mesh " + meshLabel + ": TEXCOORD_1 missing on some primitives, filled with (0, 0)");
    if (drops.generatedNormals)
      warn(who, "mesh " + meshLabel +
                    " has no NORMAL, generated area- and angle-weighted vertex normals");
    if (drops.badNormals)
      warn(who, "mesh " + meshLabel + ": replaced " + std::to_string(drops.badNormals) +
                    " zero or non-finite normals with generated ones");
    if (drops.nonFinite || drops.degenerate)
      warn(who, "mesh " + meshLabel + ": dropped " + std::to_string(drops.nonFinite) +
                    " triangle(s) with NaN/Inf positions and " + std::to_string(drops.degenerate) +
                    " zero-area triangle(s)");
    scene_.objects.push_back(std::move(obj));
  }

  // Per joint of skins[skin]: the joint's world matrix times its inverse bind matrix.
  std::vector<glm::dmat4> jointMatrices(int skin) const {
    const tinygltf::Skin& sk = model_.skins[size_t(skin)];
    std::string element = "skins[" + std::to_string(skin) + "]";
    if (sk.joints.empty()) fail(element + ".joints", "must not be empty");
    std::vector<double> ibm;
    if (sk.inverseBindMatrices >= 0) {
      std::string where = element + ".inverseBindMatrices";
      if (size_t(sk.inverseBindMatrices) >= model_.accessors.size())
        fail(where, "refers to a missing accessor");
      const auto& a = model_.accessors[size_t(sk.inverseBindMatrices)];
      if (a.type != TINYGLTF_TYPE_MAT4 || a.componentType != TINYGLTF_COMPONENT_TYPE_FLOAT)
        fail(where, "must be a MAT4 FLOAT accessor");
      if (a.count < sk.joints.size())
        fail(where, "has " + std::to_string(a.count) + " matrices for " +
                        std::to_string(sk.joints.size()) + " joints");
      ibm = readAccessor(sk.inverseBindMatrices, 16, where);
    }
    std::vector<glm::dmat4> out(sk.joints.size());
    for (size_t k = 0; k < sk.joints.size(); ++k) {
      int j = sk.joints[k];
      std::string where = element + ".joints[" + std::to_string(k) + "]";
      if (j < 0 || size_t(j) >= model_.nodes.size()) fail(where, "must be a node index");
      if (!inScene_[size_t(j)])
        fail(where, "nodes[" + std::to_string(j) + "] is not in the scene being loaded");
      glm::dmat4 inverseBind(1.0);
      if (!ibm.empty()) {
        inverseBind = glm::make_mat4(&ibm[16 * k]);
        for (int c = 0; c < 16; ++c)
          if (!std::isfinite(ibm[16 * k + size_t(c)])) fail(where, "inverse bind matrix is not finite");
      }
      out[k] = nodeWorld_[size_t(j)] * inverseBind;
    }
    return out;
  }

  // Accessor types per attribute: glTF 2.0 core plus KHR_mesh_quantization's integer forms.
  enum class AttributeKind { Position, Normal, TexCoord, PositionTarget, NormalTarget };
  void checkAttributeType(int accessor, AttributeKind kind, const std::string& use) const {
    const auto& a = model_.accessors[size_t(accessor)];
    int t = a.componentType;
    bool n = a.normalized;
    bool ok = t == TINYGLTF_COMPONENT_TYPE_FLOAT && !n;
    bool i8 = t == TINYGLTF_COMPONENT_TYPE_BYTE, u8 = t == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
    bool i16 = t == TINYGLTF_COMPONENT_TYPE_SHORT, u16 = t == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
    const char* allowed = "";
    switch (kind) {
      case AttributeKind::Position:
      case AttributeKind::TexCoord:
        ok |= i8 || u8 || i16 || u16;
        allowed = "FLOAT, or (KHR_mesh_quantization) BYTE, UNSIGNED_BYTE, SHORT or UNSIGNED_SHORT";
        break;
      case AttributeKind::Normal:
      case AttributeKind::NormalTarget:
        ok |= (i8 || i16) && n;
        allowed = "FLOAT, or (KHR_mesh_quantization) normalized BYTE or SHORT";
        break;
      case AttributeKind::PositionTarget:
        ok |= i8 || i16;
        allowed = "FLOAT, or (KHR_mesh_quantization) BYTE or SHORT";
        break;
    }
    if (!ok)
      fail("accessors[" + std::to_string(accessor) + "]",
           use + " has componentType " + std::to_string(t) + (n ? " (normalized)" : "") +
               "; it must be " + allowed);
  }

  PrimitiveGeometry convertPrimitive(const tinygltf::Primitive& prim, const std::string& element,
                                     const mat4& positionMatrix, const mat3& normalMatrix,
                                     bool flip, const std::vector<glm::dmat4>* joints,
                                     const std::vector<double>& weights,
                                     const std::string& weightsElement, DropCounts* drops) {
    int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    if (mode >= TINYGLTF_MODE_POINTS && mode <= TINYGLTF_MODE_LINE_STRIP)
      fail(element, std::string("mode ") + modeName(mode) +
                        " is not supported (kiln needs triangles, strips or fans)");
    if (mode > TINYGLTF_MODE_TRIANGLE_FAN) fail(element + ".mode", "must be in [0, 6]");

    auto attribute = [&](const char* name) {
      auto it = prim.attributes.find(name);
      return it == prim.attributes.end() ? -1 : it->second;
    };
    int posAccessor = attribute("POSITION");
    if (posAccessor < 0) fail(element, "has no POSITION attribute");
    checkAttributeType(posAccessor, AttributeKind::Position, element + " POSITION");
    std::vector<double> pos = readAccessor(posAccessor, 3, element + " POSITION");
    size_t vertexCount = pos.size() / 3;
    auto sameCount = [&](int accessor, const std::string& name) {
      if (model_.accessors[size_t(accessor)].count != vertexCount)
        fail(element, name + " (accessors[" + std::to_string(accessor) + "]) has " +
                          std::to_string(model_.accessors[size_t(accessor)].count) +
                          " elements, POSITION has " + std::to_string(vertexCount));
    };

    // Morph targets at the given weights, in the mesh's own space (before skin and node).
    std::vector<double> normalOffset;
    if (!weights.empty() && weights.size() != prim.targets.size())
      fail(weightsElement, "has " + std::to_string(weights.size()) + " weights, but " + element +
                               " has " + std::to_string(prim.targets.size()) + " morph targets");
    for (size_t t = 0; t < prim.targets.size() && !weights.empty(); ++t) {
      double w = weights[t];
      if (w == 0.0) continue;
      std::string where = element + ".targets[" + std::to_string(t) + "]";
      for (const auto& [name, accessor] : prim.targets[t]) {
        bool isPosition = name == "POSITION", isNormal = name == "NORMAL";
        if (!isPosition && !isNormal) continue;  // TANGENT: kiln reads no tangents
        checkAttributeType(accessor,
                           isPosition ? AttributeKind::PositionTarget : AttributeKind::NormalTarget,
                           where + " " + name);
        sameCount(accessor, where + " " + name);
        std::vector<double> delta = readAccessor(accessor, 3, where + " " + name);
        std::vector<double>& dst = isPosition ? pos : normalOffset;
        if (dst.empty()) dst.assign(3 * vertexCount, 0.0);
        for (size_t k = 0; k < dst.size(); ++k) dst[k] += w * delta[k];
      }
    }

    // Skin: per vertex, the weighted sum of its joints' matrices.
    std::vector<glm::dmat4> skinMatrix;
    if (joints) skinMatrix = vertexSkinMatrices(prim, element, vertexCount, *joints);

    PrimitiveGeometry g;
    g.material = prim.material >= 0 ? uint32_t(prim.material) : defaultMaterialIndex();

    // Vertex indices, then triangles in the primitive's own numbering.
    std::vector<uint32_t> indices;
    if (prim.indices >= 0) {
      const auto& a = model_.accessors[size_t(prim.indices)];
      std::string where = "accessors[" + std::to_string(prim.indices) + "]";
      if (a.type != TINYGLTF_TYPE_SCALAR || a.normalized ||
          (a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
           a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
           a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
        fail(where, "indices of " + element + " must be SCALAR unsigned byte/short/int");
      std::vector<double> raw = readAccessor(prim.indices, 1, element + " indices");
      indices.reserve(raw.size());
      for (size_t k = 0; k < raw.size(); ++k) {
        if (raw[k] >= double(vertexCount))
          fail(element, "indices (" + where + ") [" + std::to_string(k) +
                            "] = " + std::to_string(uint64_t(raw[k])) + " >= vertex count " +
                            std::to_string(vertexCount));
        indices.push_back(uint32_t(raw[k]));
      }
    } else {
      indices.resize(vertexCount);
      for (size_t k = 0; k < vertexCount; ++k) indices[k] = uint32_t(k);
    }
    std::vector<uvec3> tris = *gltfTriangles(indices, mode);  // mode checked above

    // World positions.
    std::vector<vec3> positions(vertexCount);
    for (size_t v = 0; v < vertexCount; ++v) {
      vec3 p{float(pos[3 * v]), float(pos[3 * v + 1]), float(pos[3 * v + 2])};
      positions[v] = joints ? vec3(skinMatrix[v] * glm::dvec4(glm::dvec3(p), 1.0))
                            : vec3(positionMatrix * vec4(p, 1.0f));
    }
    pos = {};

    // Drop triangles kiln cannot use, then keep only the vertices still referenced.
    std::vector<uvec3> kept;
    kept.reserve(tris.size());
    for (uvec3 t : tris) {
      // A skinned triangle's facing follows its first vertex's matrix.
      if (joints ? glm::determinant(glm::dmat3(skinMatrix[t.x])) < 0.0 : flip) std::swap(t.y, t.z);
      vec3 a = positions[t.x], b = positions[t.y], c = positions[t.z];
      if (!isFinite(a) || !isFinite(b) || !isFinite(c)) {
        ++drops->nonFinite;
        continue;
      }
      // Finite but far: Embree asserts on rays from beyond ~1.8e18, and float spacing there is
      // kilometres anyway (a node translated by 1e20 aborted the bake).
      for (vec3 q : {a, b, c})
        if (glm::any(glm::greaterThan(glm::abs(q), vec3(kMaxWorldCoordinate))))
        {
          std::ostringstream where;
          where << "a vertex lies at (" << q.x << ", " << q.y << ", " << q.z
                << ") in world space, beyond " << kMaxWorldCoordinate
                << " m from the origin on an axis (docs/limits.md)";
          fail(element, where.str());
        }
      // Zero area relative to the triangle's size (float cross products are noise below
      // ~1e-7 of the edge lengths squared), which also catches repeated indices.
      float maxEdge2 =
          std::max({glm::dot(b - a, b - a), glm::dot(c - b, c - b), glm::dot(a - c, a - c)});
      float cross = glm::length(glm::cross(b - a, c - a));
      if (!(cross > 1e-7f * maxEdge2) || !std::isfinite(cross)) {
        ++drops->degenerate;
        continue;
      }
      kept.push_back(t);
    }
    std::vector<uint32_t> remap(vertexCount, UINT32_MAX);
    std::vector<uint32_t> used;
    {
      std::vector<bool> referenced(vertexCount, false);
      for (uvec3 t : kept) referenced[t.x] = referenced[t.y] = referenced[t.z] = true;
      for (size_t v = 0; v < vertexCount; ++v)
        if (referenced[v]) {
          remap[v] = uint32_t(used.size());
          used.push_back(uint32_t(v));
        }
    }
    for (uvec3& t : kept) t = uvec3(remap[t.x], remap[t.y], remap[t.z]);
    g.triangles = std::move(kept);
    g.positions.resize(used.size());
    for (size_t v = 0; v < used.size(); ++v) g.positions[v] = positions[used[v]];

    // Normals: transformed when given, generated when missing or unusable.
    std::vector<bool> needsNormal(used.size(), true);
    g.normals.assign(used.size(), vec3(0.0f));
    int normalAccessor = attribute("NORMAL");
    if (normalAccessor >= 0) {
      sameCount(normalAccessor, "NORMAL");
      checkAttributeType(normalAccessor, AttributeKind::Normal, element + " NORMAL");
      std::vector<double> nrm = readAccessor(normalAccessor, 3, element + " NORMAL");
      for (size_t k = 0; k < normalOffset.size(); ++k) nrm[k] += normalOffset[k];
      for (size_t v = 0; v < used.size(); ++v) {
        size_t s = used[v];
        vec3 local{float(nrm[3 * s]), float(nrm[3 * s + 1]), float(nrm[3 * s + 2])};
        vec3 nw = joints ? cofactorNormalMatrix(mat3(skinMatrix[s])) * local : normalMatrix * local;
        float len = glm::length(nw);
        if (len > 0.0f && std::isfinite(len)) {
          g.normals[v] = nw / len;
          needsNormal[v] = false;
        } else {
          ++drops->badNormals;
        }
      }
    } else {
      drops->generatedNormals = !used.empty() || drops->generatedNormals;
    }
    if (std::find(needsNormal.begin(), needsNormal.end(), true) != needsNormal.end())
      generateNormals(g, needsNormal);

    g.hasUv0 = readUv(attribute("TEXCOORD_0"), "TEXCOORD_0", element, used, vertexCount, &g.uv0);
    g.hasUv1 = readUv(attribute("TEXCOORD_1"), "TEXCOORD_1", element, used, vertexCount, &g.uv1);
    return g;
  }

  bool readUv(int accessor, const char* name, const std::string& element,
              const std::vector<uint32_t>& used, size_t vertexCount, std::vector<vec2>* out) {
    if (accessor < 0) return false;
    if (model_.accessors[size_t(accessor)].count != vertexCount)
      fail(element, std::string(name) + " (accessors[" + std::to_string(accessor) + "]) has " +
                        std::to_string(model_.accessors[size_t(accessor)].count) +
                        " elements, POSITION has " + std::to_string(vertexCount));
    checkAttributeType(accessor, AttributeKind::TexCoord, element + " " + name);
    std::vector<double> uv = readAccessor(accessor, 2, element + " " + name);
    out->resize(used.size());
    for (size_t v = 0; v < used.size(); ++v) {
      vec2 t{float(uv[2 * used[v]]), float(uv[2 * used[v] + 1])};
      (*out)[v] = std::isfinite(t.x) && std::isfinite(t.y) ? t : vec2(0.0f);
    }
    return true;
  }

  // The normal matrix of a linear map: its cofactor matrix (the inverse transpose times det),
  // negated for a mirroring map so that normals keep their side.
  static mat3 cofactorNormalMatrix(const mat3& linear) {
    mat3 cofactor(glm::cross(linear[1], linear[2]), glm::cross(linear[2], linear[0]),
                  glm::cross(linear[0], linear[1]));
    return glm::determinant(linear) < 0.0f ? -cofactor : cofactor;
  }

  // Per vertex: sum over JOINTS_n/WEIGHTS_n of weight x joint matrix (weights renormalised to
  // sum 1, as glTF expects of exporters).
  std::vector<glm::dmat4> vertexSkinMatrices(const tinygltf::Primitive& prim,
                                             const std::string& element, size_t vertexCount,
                                             const std::vector<glm::dmat4>& joints) const {
    std::vector<glm::dmat4> out(vertexCount, glm::dmat4(0.0));
    std::vector<double> sum(vertexCount, 0.0);
    int sets = 0;
    for (;; ++sets) {
      auto find = [&](const std::string& name) {
        auto it = prim.attributes.find(name);
        return it == prim.attributes.end() ? -1 : it->second;
      };
      std::string jn = "JOINTS_" + std::to_string(sets), wn = "WEIGHTS_" + std::to_string(sets);
      int ja = find(jn), wa = find(wn);
      if (ja < 0 && wa < 0) break;
      if (ja < 0 || wa < 0) fail(element, "has only one of " + jn + " and " + wn);
      for (auto [acc, name] : {std::pair{ja, jn}, std::pair{wa, wn}})
        if (model_.accessors[size_t(acc)].count != vertexCount)
          fail(element, name + " (accessors[" + std::to_string(acc) + "]) has " +
                            std::to_string(model_.accessors[size_t(acc)].count) +
                            " elements, POSITION has " + std::to_string(vertexCount));
      const auto& ja_ = model_.accessors[size_t(ja)];
      if (ja_.normalized || (ja_.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                             ja_.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT))
        fail("accessors[" + std::to_string(ja) + "]",
             element + " " + jn + " must be UNSIGNED_BYTE or UNSIGNED_SHORT");
      const auto& wa_ = model_.accessors[size_t(wa)];
      if (!(wa_.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ||
            (wa_.normalized && (wa_.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                                wa_.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT))))
        fail("accessors[" + std::to_string(wa) + "]",
             element + " " + wn + " must be FLOAT or normalized UNSIGNED_BYTE/SHORT");
      std::vector<double> j = readAccessor(ja, 4, element + " " + jn);
      std::vector<double> w = readAccessor(wa, 4, element + " " + wn);
      for (size_t v = 0; v < vertexCount; ++v)
        for (size_t c = 0; c < 4; ++c) {
          double weight = w[4 * v + c];
          if (weight == 0.0) continue;
          if (!std::isfinite(weight) || weight < 0.0)
            fail(element, wn + "[" + std::to_string(v) + "] must be finite and >= 0");
          size_t joint = size_t(j[4 * v + c]);
          if (joint >= joints.size())
            fail(element, jn + "[" + std::to_string(v) + "] = " + std::to_string(joint) +
                              ", but the skin has " + std::to_string(joints.size()) + " joints");
          out[v] += joints[joint] * weight;
          sum[v] += weight;
        }
    }
    if (sets == 0)
      fail(element, "belongs to a skinned node but has no JOINTS_0/WEIGHTS_0");
    for (size_t v = 0; v < vertexCount; ++v) {
      if (!(sum[v] > 0.0))
        fail(element, "vertex " + std::to_string(v) + " has no joint weight (all WEIGHTS are 0)");
      out[v] /= sum[v];
    }
    return out;
  }

  // Vertex normals weighted by each corner's angle times its triangle's area (the cross
  // product's length), from the world-space, front-facing triangles; a vertex whose
  // contributions cancel takes the normal of its first triangle.
  static void generateNormals(PrimitiveGeometry& g, const std::vector<bool>& needs) {
    std::vector<glm::dvec3> sum(g.positions.size(), glm::dvec3(0.0));
    std::vector<vec3> first(g.positions.size(), vec3(0.0f));
    for (uvec3 t : g.triangles) {
      vec3 p[3] = {g.positions[t.x], g.positions[t.y], g.positions[t.z]};
      vec3 face = glm::cross(p[1] - p[0], p[2] - p[0]);
      vec3 unit = glm::normalize(face);
      for (int c = 0; c < 3; ++c) {
        vec3 e1 = glm::normalize(p[(c + 1) % 3] - p[c]);
        vec3 e2 = glm::normalize(p[(c + 2) % 3] - p[c]);
        double angle = std::acos(std::clamp(double(glm::dot(e1, e2)), -1.0, 1.0));
        sum[t[c]] += glm::dvec3(face) * angle;
        if (first[t[c]] == vec3(0.0f)) first[t[c]] = unit;
      }
    }
    for (size_t v = 0; v < g.positions.size(); ++v) {
      if (!needs[v]) continue;
      double len = glm::length(sum[v]);
      g.normals[v] = len > 1e-30 ? vec3(sum[v] / len) : first[v];
      if (g.normals[v] == vec3(0.0f)) g.normals[v] = vec3(0.0f, 1.0f, 0.0f);
    }
  }

  uint32_t defaultMaterialIndex() {
    defaultMaterialUsed_ = true;
    return uint32_t(model_.materials.size());  // appended after the file's materials
  }

  std::string path_;
  LoadOptions options_;
  size_t texturesUsed_ = 0;  // countUsedTextures(), once, when progress is reported
  std::string baseDir_;
  std::vector<uint8_t> bytes_;
  bool isGlb_ = false;
  uint64_t glbBinSize_ = 0;
  Json doc_;
  std::vector<uint64_t> bufferLengths_;
  std::vector<bool> noDataBuffer_;  // EXT_meshopt_compression fallback buffers without data
  enum class MeshoptMode { Attributes, Triangles, Indices };
  enum class MeshoptFilter { None, Octahedral, Quaternion, Exponential };
  struct MeshoptView {
    size_t view = 0;
    uint64_t buffer = 0, offset = 0, length = 0, stride = 0, count = 0;
    uint64_t viewLength = 0;  // the bufferView's byteLength: the decoded size
    MeshoptMode mode = MeshoptMode::Attributes;
    MeshoptFilter filter = MeshoptFilter::None;
  };
  std::vector<MeshoptView> meshopt_;
  struct ViewlessIndices {
    size_t mesh = 0, primitive = 0;
    int accessor = -1;
  };
  std::vector<ViewlessIndices> viewlessIndices_;
  std::set<size_t> isMeshoptView_;
  tinygltf::Model model_;
  std::map<int, int> textureMap_;
  mutable uint64_t zeroElementsRead_ = 0;  // see readAccessor
  std::map<std::tuple<int, int, int, bool>, int> decodedImages_;  // (image, sampler) -> texture
  std::vector<glm::dmat4> nodeWorld_;  // world matrices of the loaded scene's nodes
  std::vector<bool> inScene_;
  bool defaultMaterialUsed_ = false;
  Scene scene_;
};

}  // namespace

std::string percentDecode(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '%' && i + 2 < s.size() && std::isxdigit(uint8_t(s[i + 1])) &&
        std::isxdigit(uint8_t(s[i + 2]))) {
      out += char(std::stoi(s.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += s[i];
    }
  }
  return out;
}

std::optional<std::vector<uvec3>> gltfTriangles(std::span<const uint32_t> indices, int mode) {
  std::vector<uvec3> tris;
  if (mode == TINYGLTF_MODE_TRIANGLES) {
    for (size_t k = 0; k + 2 < indices.size(); k += 3)
      tris.emplace_back(indices[k], indices[k + 1], indices[k + 2]);
  } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
    // glTF 2.0 spec, "Topology types": odd triangles swap their first two vertices so that
    // every triangle keeps the strip's winding.
    for (size_t k = 0; k + 2 < indices.size(); ++k)
      tris.push_back(k % 2 == 0 ? uvec3(indices[k], indices[k + 1], indices[k + 2])
                                : uvec3(indices[k + 1], indices[k], indices[k + 2]));
  } else if (mode == TINYGLTF_MODE_TRIANGLE_FAN) {
    for (size_t k = 1; k + 1 < indices.size(); ++k)
      tris.emplace_back(indices[k], indices[k + 1], indices[0]);
  } else {
    return std::nullopt;
  }
  return tris;
}

std::vector<GltfViewlessIndices> rewriteGltfForTinyGltf(const nlohmann::json& doc,
                                                        std::vector<uint8_t>* bytes) {
  const bool glb = bytes->size() >= 20 && std::memcmp(bytes->data(), "glTF", 4) == 0;
  Json rewritten = doc;
  std::vector<GltfViewlessIndices> viewless;
  bool changed = false;
  const Json empty = Json::array();
  auto arrayOf = [&](const char* key) -> const Json& {
    auto it = doc.find(key);
    return it != doc.end() && it->is_array() ? *it : empty;
  };
  const Json &buffers = arrayOf("buffers"), &views = arrayOf("bufferViews"),
             &accessors = arrayOf("accessors"), &meshes = arrayOf("meshes");
  for (size_t m = 0; m < meshes.size(); ++m) {
    if (!meshes[m].is_object() || !meshes[m].contains("primitives")) continue;
    const Json& prims = meshes[m]["primitives"];
    for (size_t j = 0; prims.is_array() && j < prims.size(); ++j) {
      auto ix = prims[j].find("indices");
      if (ix == prims[j].end() || !ix->is_number_unsigned() || ix->get<size_t>() >= accessors.size())
        continue;
      if (accessors[ix->get<size_t>()].is_object() &&
          !accessors[ix->get<size_t>()].contains("bufferView")) {
        viewless.push_back({m, j, ix->get<int>()});
        rewritten["meshes"][m]["primitives"][j].erase("indices");
        changed = true;
      }
    }
  }
  // Data-less buffers (loadScene accepts them only as EXT_meshopt_compression fallbacks).
  for (size_t i = 0; i < buffers.size(); ++i)
    if (buffers[i].is_object() && !buffers[i].contains("uri") && !(glb && i == 0)) {
      rewritten["buffers"][i]["uri"] = "data:application/octet-stream;base64,AA==";
      rewritten["buffers"][i]["byteLength"] = 1;
      changed = true;
    }
  if (!changed) return viewless;
  for (size_t i = 0; i < views.size(); ++i) {
    auto ext = views[i].find("extensions");
    if (views[i].is_object() && ext != views[i].end() && ext->is_object() &&
        ext->contains("EXT_meshopt_compression")) {
      rewritten["bufferViews"][i]["byteOffset"] = 0;
      rewritten["bufferViews"][i]["byteLength"] = 1;
    }
  }
  std::string json = rewritten.dump();
  if (!glb) {
    bytes->assign(json.begin(), json.end());
    return viewless;
  }
  // A .glb: the same BIN chunk behind the new JSON chunk.
  while (json.size() % 4) json.push_back(' ');
  std::vector<uint8_t> bin;
  const uint64_t binHeader = 20 + uint64_t(readU32(bytes->data() + 12));
  if (binHeader + 8 <= bytes->size()) {
    const uint64_t end = std::min<uint64_t>(binHeader + 8 + readU32(bytes->data() + binHeader),
                                            bytes->size());
    bin.assign(bytes->begin() + long(binHeader), bytes->begin() + long(end));
  }
  std::vector<uint8_t> out(20);
  auto put32 = [&](size_t at, uint32_t v) {
    for (int k = 0; k < 4; ++k) out[at + size_t(k)] = uint8_t(v >> (8 * k));
  };
  std::memcpy(out.data(), "glTF", 4);
  put32(4, 2);
  put32(8, uint32_t(20 + json.size() + bin.size()));
  put32(12, uint32_t(json.size()));
  put32(16, 0x4E4F534Au);
  out.insert(out.end(), json.begin(), json.end());
  out.insert(out.end(), bin.begin(), bin.end());
  *bytes = std::move(out);
  return viewless;
}

double readGltfComponent(const uint8_t* p, int componentType, bool normalized) {
  return readComponent(p, componentType, normalized);
}

Result<Scene> loadScene(const std::string& path, const LoadOptions& options) {
  try {
    return Loader(path, options).load();
  } catch (const LoadFailure& f) {
    return Error{f.message};
  } catch (const std::bad_alloc&) {
    return Error{path + ": out of memory while loading"};
  } catch (const std::exception& e) {
    // tinygltf's JSON layer and the standard library may throw on input we did not foresee.
    return Error{path + ": " + e.what()};
  }
}

}  // namespace kiln
