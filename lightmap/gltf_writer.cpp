// gltf_writer.cpp: the output glTF of `kiln bake` (see gltf_writer.h). tinygltf reads the
// input's buffers (files, data: URIs, the .glb chunk); the document itself is edited as raw
// JSON so that everything kiln does not understand passes through unchanged.
#include "lightmap/gltf_writer.h"

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
#include <nlohmann/json.hpp>
#include <sstream>

#include "lightmap/atlas.h"
#include "src/gltf_loader.h"

namespace kiln {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr int kArrayBuffer = 34962;
constexpr int kElementArrayBuffer = 34963;
constexpr int kFloat = 5126;

uint32_t readU32(const uint8_t* p) {
  return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}

// The document's JSON, from a .gltf or the JSON chunk of a .glb (the loader has validated the
// file already; this only has to find the JSON again).
Result<Json> readDocumentJson(const std::string& path, bool* glb) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open the file"};
  std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  *glb = bytes.size() >= 20 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  const char* begin = reinterpret_cast<const char*>(bytes.data());
  size_t size = bytes.size();
  if (*glb) {
    const uint32_t chunk = readU32(bytes.data() + 12);
    if (uint64_t(chunk) + 20 > bytes.size()) return Error{path + ": GLB JSON chunk truncated"};
    begin += 20;
    size = chunk;
  }
  try {
    Json doc = Json::parse(begin, begin + size);
    if (!doc.is_object()) return Error{path + ": the JSON root is not an object"};
    return doc;
  } catch (const Json::exception& e) {
    return Error{path + ": malformed JSON: " + e.what()};
  }
}

bool skipImage(tinygltf::Image*, const int, std::string*, std::string*, int, int,
               const unsigned char*, int, void*) {
  return true;  // images are referenced, never decoded or rewritten
}

// Raw access to a non-sparse accessor's elements.
struct AccessorView {
  const uint8_t* data = nullptr;
  size_t stride = 0, elemSize = 0, count = 0;
  int componentType = 0, components = 0;
  bool normalized = false;
  std::string type;
  const uint8_t* element(size_t i) const { return data + i * stride; }
};

std::string accessorTypeName(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return "SCALAR";
    case TINYGLTF_TYPE_VEC2: return "VEC2";
    case TINYGLTF_TYPE_VEC3: return "VEC3";
    case TINYGLTF_TYPE_VEC4: return "VEC4";
    case TINYGLTF_TYPE_MAT2: return "MAT2";
    case TINYGLTF_TYPE_MAT3: return "MAT3";
    case TINYGLTF_TYPE_MAT4: return "MAT4";
  }
  return "SCALAR";
}

std::optional<AccessorView> viewAccessor(const tinygltf::Model& m, int index) {
  if (index < 0 || size_t(index) >= m.accessors.size()) return std::nullopt;
  const tinygltf::Accessor& a = m.accessors[size_t(index)];
  if (a.sparse.isSparse || a.bufferView < 0 || size_t(a.bufferView) >= m.bufferViews.size())
    return std::nullopt;
  const tinygltf::BufferView& bv = m.bufferViews[size_t(a.bufferView)];
  if (bv.buffer < 0 || size_t(bv.buffer) >= m.buffers.size()) return std::nullopt;
  const std::vector<unsigned char>& buf = m.buffers[size_t(bv.buffer)].data;
  AccessorView v;
  v.componentType = a.componentType;
  v.components = tinygltf::GetNumComponentsInType(uint32_t(a.type));
  const int compSize = tinygltf::GetComponentSizeInBytes(uint32_t(a.componentType));
  if (v.components <= 0 || compSize <= 0) return std::nullopt;
  v.elemSize = size_t(v.components) * size_t(compSize);
  v.stride = bv.byteStride ? bv.byteStride : v.elemSize;
  v.count = a.count;
  v.normalized = a.normalized;
  v.type = accessorTypeName(a.type);
  const size_t start = bv.byteOffset + a.byteOffset;
  if (a.count > 0 && start + (a.count - 1) * v.stride + v.elemSize > buf.size())
    return std::nullopt;
  v.data = buf.data() + start;
  return v;
}

// The node's local matrix, as src/gltf_loader.cpp computes it (T x R x S or "matrix").
glm::dmat4 localMatrix(const tinygltf::Node& n) {
  if (n.matrix.size() == 16) return glm::make_mat4(n.matrix.data());
  glm::dmat4 m(1.0);
  if (n.translation.size() == 3)
    m = glm::translate(m, glm::dvec3(n.translation[0], n.translation[1], n.translation[2]));
  if (n.rotation.size() == 4) {
    glm::dquat q(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]);
    const double len = glm::length(q);
    if (len > 1e-12) m = m * glm::mat4_cast(q / len);
  }
  if (n.scale.size() == 3) m = glm::scale(m, glm::dvec3(n.scale[0], n.scale[1], n.scale[2]));
  return m;
}

// World matrices of every node, composed root first as the loader does.
std::vector<glm::dmat4> worldMatrices(const tinygltf::Model& m) {
  const size_t n = m.nodes.size();
  std::vector<int> parent(n, -1);
  for (size_t i = 0; i < n; ++i)
    for (int c : m.nodes[i].children)
      if (c >= 0 && size_t(c) < n) parent[size_t(c)] = int(i);
  std::vector<glm::dmat4> world(n, glm::dmat4(1.0));
  for (size_t i = 0; i < n; ++i) {
    std::vector<int> chain;
    for (int k = int(i); k >= 0 && chain.size() <= n; k = parent[size_t(k)]) chain.push_back(k);
    glm::dmat4 w(1.0);
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) w = w * localMatrix(m.nodes[size_t(*it)]);
    world[i] = w;
  }
  return world;
}

// Where each of an Object's vertices came from, recomputed exactly as the loader builds the
// Object: per primitive, triangles (lists, strips, fans), winding flipped under a mirroring
// transform, triangles with non-finite or zero-area world positions dropped, and only the
// vertices still referenced kept, in index order; primitives concatenated in order.
struct SourceVertex {
  uint32_t primitive, index;
};
struct SourceMap {
  std::vector<SourceVertex> vertices;
  std::vector<vec3> worldPositions;         // per vertex
  std::vector<size_t> primitiveTriangles;  // triangles each primitive kept
};

std::optional<SourceMap> traceSources(const tinygltf::Model& m, const tinygltf::Mesh& mesh,
                                      const glm::dmat4& world) {
  const mat4 positionMatrix(world);
  const bool flip = glm::determinant(mat3(world)) < 0.0f;
  SourceMap map;
  for (size_t j = 0; j < mesh.primitives.size(); ++j) {
    const tinygltf::Primitive& prim = mesh.primitives[j];
    auto pos = prim.attributes.find("POSITION");
    if (pos == prim.attributes.end()) return std::nullopt;
    std::optional<AccessorView> pv = viewAccessor(m, pos->second);
    if (!pv || pv->components != 3) return std::nullopt;
    const size_t vertexCount = pv->count;
    std::vector<uint32_t> indices;
    if (prim.indices >= 0) {
      std::optional<AccessorView> iv = viewAccessor(m, prim.indices);
      if (!iv) return std::nullopt;
      for (size_t k = 0; k < iv->count; ++k) {
        const double x = readGltfComponent(iv->element(k), iv->componentType, false);
        if (x >= double(vertexCount)) return std::nullopt;
        indices.push_back(uint32_t(x));
      }
    } else {
      for (size_t k = 0; k < vertexCount; ++k) indices.push_back(uint32_t(k));
    }
    const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
    std::optional<std::vector<uvec3>> assembled = gltfTriangles(indices, mode);
    if (!assembled) return std::nullopt;
    const std::vector<uvec3>& tris = *assembled;
    std::vector<vec3> positions(vertexCount);
    for (size_t v = 0; v < vertexCount; ++v) {
      const uint8_t* e = pv->element(v);
      const size_t cs = pv->elemSize / 3;
      vec3 p(float(readGltfComponent(e, pv->componentType, pv->normalized)),
             float(readGltfComponent(e + cs, pv->componentType, pv->normalized)),
             float(readGltfComponent(e + 2 * cs, pv->componentType, pv->normalized)));
      positions[v] = vec3(positionMatrix * vec4(p, 1.0f));
    }
    std::vector<bool> referenced(vertexCount, false);
    size_t kept = 0;
    for (uvec3 t : tris) {
      if (flip) std::swap(t.y, t.z);
      const vec3 a = positions[t.x], b = positions[t.y], c = positions[t.z];
      if (!isFinite(a) || !isFinite(b) || !isFinite(c)) continue;
      const float maxEdge2 =
          std::max({glm::dot(b - a, b - a), glm::dot(c - b, c - b), glm::dot(a - c, a - c)});
      const float cross = glm::length(glm::cross(b - a, c - a));
      if (!(cross > 1e-7f * maxEdge2) || !std::isfinite(cross)) continue;
      referenced[t.x] = referenced[t.y] = referenced[t.z] = true;
      ++kept;
    }
    map.primitiveTriangles.push_back(kept);
    for (size_t v = 0; v < vertexCount; ++v)
      if (referenced[v]) {
        map.vertices.push_back({uint32_t(j), uint32_t(v)});
        map.worldPositions.push_back(positions[v]);
      }
  }
  return map;
}

// Appends accessors (one bufferView each) to the document and their bytes to a new buffer.
class BinaryBuilder {
 public:
  BinaryBuilder(Json& doc, int bufferIndex) : doc_(doc), buffer_(bufferIndex) {}

  // `elements` holds count x elemSize tightly packed bytes.
  int addAccessor(const std::vector<uint8_t>& elements, size_t elemSize, size_t count,
                  int componentType, const std::string& type, bool normalized, int target,
                  const Json& min = nullptr, const Json& max = nullptr) {
    while (bytes_.size() % 4) bytes_.push_back(0);
    // Vertex attribute elements must start on 4-byte boundaries (glTF 2.0, "Data alignment").
    const size_t stride = target == kArrayBuffer ? (elemSize + 3) / 4 * 4 : elemSize;
    const size_t offset = bytes_.size();
    for (size_t i = 0; i < count; ++i) {
      bytes_.insert(bytes_.end(), elements.begin() + long(i * elemSize),
                    elements.begin() + long((i + 1) * elemSize));
      bytes_.resize(bytes_.size() + (stride - elemSize), 0);
    }
    Json view = {{"buffer", buffer_}, {"byteOffset", offset}, {"byteLength", stride * count},
                 {"target", target}};
    if (stride != elemSize) view["byteStride"] = stride;
    doc_["bufferViews"].push_back(view);
    Json acc = {{"bufferView", doc_["bufferViews"].size() - 1},
                {"componentType", componentType},
                {"count", count},
                {"type", type}};
    if (normalized) acc["normalized"] = true;
    if (!min.is_null()) acc["min"] = min;
    if (!max.is_null()) acc["max"] = max;
    doc_["accessors"].push_back(acc);
    return int(doc_["accessors"].size() - 1);
  }

  int addFloats(const std::vector<float>& values, int components, const std::string& type,
                bool withBounds) {
    const size_t count = values.size() / size_t(components);
    std::vector<uint8_t> bytes(values.size() * 4);
    std::memcpy(bytes.data(), values.data(), bytes.size());
    Json mn = nullptr, mx = nullptr;
    if (withBounds && count > 0) {
      mn = Json::array();
      mx = Json::array();
      for (int c = 0; c < components; ++c) {
        float lo = values[size_t(c)], hi = lo;
        for (size_t i = 0; i < count; ++i) {
          lo = std::min(lo, values[i * size_t(components) + size_t(c)]);
          hi = std::max(hi, values[i * size_t(components) + size_t(c)]);
        }
        mn.push_back(lo);
        mx.push_back(hi);
      }
    }
    return addAccessor(bytes, size_t(components) * 4, count, kFloat, type, false, kArrayBuffer,
                       mn, mx);
  }

  int addIndices(const std::vector<uint32_t>& indices, size_t vertexCount) {
    if (vertexCount <= 65535) {
      std::vector<uint8_t> bytes(indices.size() * 2);
      for (size_t i = 0; i < indices.size(); ++i) {
        const uint16_t v = uint16_t(indices[i]);
        std::memcpy(&bytes[i * 2], &v, 2);
      }
      return addAccessor(bytes, 2, indices.size(), TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT,
                         "SCALAR", false, kElementArrayBuffer);
    }
    std::vector<uint8_t> bytes(indices.size() * 4);
    std::memcpy(bytes.data(), indices.data(), bytes.size());
    return addAccessor(bytes, 4, indices.size(), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, "SCALAR",
                       false, kElementArrayBuffer);
  }

  std::vector<uint8_t>& bytes() { return bytes_; }

 private:
  Json& doc_;
  int buffer_;
  std::vector<uint8_t> bytes_;
};

// An accessor's elements gathered at `indices` (tightly packed), with min/max for positions.
int gatherAccessor(BinaryBuilder& bin, const AccessorView& v, const std::vector<uint32_t>& indices,
                   bool bounds) {
  std::vector<uint8_t> bytes(indices.size() * v.elemSize);
  for (size_t i = 0; i < indices.size(); ++i)
    std::memcpy(&bytes[i * v.elemSize], v.element(indices[i]), v.elemSize);
  Json mn = nullptr, mx = nullptr;
  if (bounds && !indices.empty()) {
    const size_t cs = v.elemSize / size_t(v.components);
    mn = Json::array();
    mx = Json::array();
    for (int c = 0; c < v.components; ++c) {
      double lo = INFINITY, hi = -INFINITY;
      for (uint32_t k : indices) {
        const double x = readGltfComponent(v.element(k) + size_t(c) * cs, v.componentType, false);
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
      mn.push_back(lo);
      mx.push_back(hi);
    }
  }
  return bin.addAccessor(bytes, v.elemSize, indices.size(), v.componentType, v.type, v.normalized,
                         kArrayBuffer, mn, mx);
}

// The new primitives of a node whose UVs kiln generated, from the original attributes.
std::optional<Json> rebuildFromSources(const tinygltf::Model& m, const Json& meshJson,
                                       const tinygltf::Mesh& mesh, const SourceMap& src,
                                       const UnwrapResult& unwrap, bool flip,
                                       BinaryBuilder& bin) {
  Json primitives = Json::array();
  size_t triangle = 0;
  for (size_t j = 0; j < mesh.primitives.size(); ++j) {
    const tinygltf::Primitive& prim = mesh.primitives[j];
    const size_t end = triangle + src.primitiveTriangles[j];
    if (end == triangle) continue;
    // New vertices used by this primitive's triangles, in order of first use.
    std::map<uint32_t, uint32_t> local;
    std::vector<uint32_t> newVertices, indices;
    for (size_t t = triangle; t < end; ++t) {
      uvec3 tri = unwrap.triangles[t];
      if (flip) std::swap(tri.y, tri.z);  // back to the mesh's own winding
      for (int k = 0; k < 3; ++k) {
        auto [it, added] = local.emplace(tri[k], uint32_t(newVertices.size()));
        if (added) newVertices.push_back(tri[k]);
        indices.push_back(it->second);
      }
    }
    triangle = end;
    std::vector<uint32_t> sourceIndex(newVertices.size());
    std::vector<float> uv1;
    for (size_t i = 0; i < newVertices.size(); ++i) {
      const SourceVertex s = src.vertices[unwrap.vertexRemap[newVertices[i]]];
      if (s.primitive != j) return std::nullopt;  // a vertex shared across primitives
      sourceIndex[i] = s.index;
      uv1.push_back(unwrap.uv1[newVertices[i]].x);
      uv1.push_back(unwrap.uv1[newVertices[i]].y);
    }
    Json p = meshJson["primitives"][j];
    p.erase("targets");
    p["mode"] = TINYGLTF_MODE_TRIANGLES;
    if (p.contains("extensions") && p["extensions"].is_object())
      p["extensions"].erase("KHR_draco_mesh_compression");
    Json attributes = Json::object();
    for (const auto& [name, accessor] : prim.attributes) {
      if (name == "TEXCOORD_1") continue;
      std::optional<AccessorView> v = viewAccessor(m, accessor);
      if (!v) return std::nullopt;
      attributes[name] = gatherAccessor(bin, *v, sourceIndex, name == "POSITION");
    }
    attributes["TEXCOORD_1"] = bin.addFloats(uv1, 2, "VEC2", false);
    p["attributes"] = attributes;
    if (!prim.targets.empty()) {
      Json targets = Json::array();
      for (const auto& target : prim.targets) {
        Json t = Json::object();
        for (const auto& [name, accessor] : target) {
          std::optional<AccessorView> v = viewAccessor(m, accessor);
          if (!v) return std::nullopt;
          t[name] = gatherAccessor(bin, *v, sourceIndex, name == "POSITION");
        }
        targets.push_back(t);
      }
      p["targets"] = targets;
    }
    p["indices"] = bin.addIndices(indices, newVertices.size());
    primitives.push_back(p);
  }
  return primitives;
}

// The fallback when the original attributes cannot be traced (sparse or compressed
// accessors): the baked Object taken back to the node's local space (positions, normals,
// TEXCOORD_0, TEXCOORD_1), one primitive per material.
Json rebuildFromObject(const Object& o, const glm::dmat4& world, size_t gltfMaterials,
                       BinaryBuilder& bin) {
  const glm::dmat4 localFromWorld = glm::inverse(world);
  const glm::dmat3 normalToLocal = glm::transpose(glm::dmat3(world));
  const bool flip = glm::determinant(glm::dmat3(world)) < 0.0;
  std::vector<uint32_t> materials;
  for (uint32_t mat : o.triangleMaterial)
    if (std::find(materials.begin(), materials.end(), mat) == materials.end())
      materials.push_back(mat);
  Json primitives = Json::array();
  for (uint32_t mat : materials) {
    std::map<uint32_t, uint32_t> local;
    std::vector<uint32_t> vertices, indices;
    for (size_t t = 0; t < o.triangles.size(); ++t) {
      if (o.triangleMaterial[t] != mat) continue;
      uvec3 tri = o.triangles[t];
      if (flip) std::swap(tri.y, tri.z);
      for (int k = 0; k < 3; ++k) {
        auto [it, added] = local.emplace(tri[k], uint32_t(vertices.size()));
        if (added) vertices.push_back(tri[k]);
        indices.push_back(it->second);
      }
    }
    std::vector<float> pos, nrm, uv0, uv1;
    for (uint32_t v : vertices) {
      const glm::dvec3 p = glm::dvec3(localFromWorld * glm::dvec4(glm::dvec3(o.positions[v]), 1.0));
      glm::dvec3 n = normalToLocal * glm::dvec3(o.normals[v]);
      n = glm::length(n) > 0.0 ? glm::normalize(n) : glm::dvec3(0, 1, 0);
      pos.insert(pos.end(), {float(p.x), float(p.y), float(p.z)});
      nrm.insert(nrm.end(), {float(n.x), float(n.y), float(n.z)});
      if (!o.uv0.empty()) uv0.insert(uv0.end(), {o.uv0[v].x, o.uv0[v].y});
      uv1.insert(uv1.end(), {o.uv1[v].x, o.uv1[v].y});
    }
    Json p = {{"mode", TINYGLTF_MODE_TRIANGLES}};
    Json attributes;
    attributes["POSITION"] = bin.addFloats(pos, 3, "VEC3", true);
    attributes["NORMAL"] = bin.addFloats(nrm, 3, "VEC3", false);
    if (!uv0.empty()) attributes["TEXCOORD_0"] = bin.addFloats(uv0, 2, "VEC2", false);
    attributes["TEXCOORD_1"] = bin.addFloats(uv1, 2, "VEC2", false);
    p["attributes"] = attributes;
    p["indices"] = bin.addIndices(indices, vertices.size());
    if (mat < gltfMaterials) p["material"] = mat;  // else glTF's default material
    primitives.push_back(p);
  }
  return primitives;
}

// Percent-encodes a relative path for a URI, keeping '/' (RFC 3986 unreserved characters).
std::string encodeUriPath(const std::string& path) {
  static const char* kHex = "0123456789ABCDEF";
  std::string out;
  for (unsigned char c : path) {
    if (std::isalnum(c) || c == '-' || c == '.' || c == '_' || c == '~' || c == '/') {
      out += char(c);
    } else {
      out += '%';
      out += kHex[c >> 4];
      out += kHex[c & 15];
    }
  }
  return out;
}

// extras.kiln of a JSON element, created when absent. Returns nullptr when extras or
// extras.kiln exist but are not objects (left alone).
Json* kilnExtras(Json& element) {
  if (!element.contains("extras")) element["extras"] = Json::object();
  Json& extras = element["extras"];
  if (!extras.is_object()) return nullptr;
  if (!extras.contains("kiln")) extras["kiln"] = Json::object();
  if (!extras["kiln"].is_object()) return nullptr;
  return &extras["kiln"];
}

}  // namespace

Result<OutputGltf> buildOutputGltf(const std::string& scenePath, const LightmapBakeResult& result,
                                   const Json& lightmaps, const std::string& outDir) {
  bool glb = false;
  Result<Json> parsed = readDocumentJson(scenePath, &glb);
  if (!parsed) return Error{parsed.error()};
  Json doc = std::move(parsed).value();

  tinygltf::Model model;
  {
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(skipImage, nullptr);
    std::string err, warn;
    const bool ok = glb ? loader.LoadBinaryFromFile(&model, &err, &warn, scenePath)
                        : loader.LoadASCIIFromFile(&model, &err, &warn, scenePath);
    if (!ok) return Error{scenePath + ": " + (err.empty() ? "cannot be read" : err)};
  }

  OutputGltf out;
  const fs::path input(scenePath);
  const std::string stem = input.stem().string();
  out.fileName = stem + ".gltf";
  std::error_code ec;
  const fs::path inputDir = fs::weakly_canonical(fs::absolute(input).parent_path(), ec);
  const fs::path outputDir = fs::weakly_canonical(fs::absolute(fs::path(outDir)), ec);
  if (fs::weakly_canonical(fs::absolute(input), ec) == outputDir / out.fileName)
    return Error{scenePath + ": the output glTF " + (outputDir / out.fileName).string() +
                 " would overwrite the input scene; choose another output directory"};

  // Buffers and images stay where they are: relative URIs get the path from the output
  // directory to the input's; a .glb's binary chunk becomes a file.
  fs::path relative = fs::relative(inputDir, outputDir, ec);
  std::string prefix;
  if (ec || relative.empty()) {
    prefix = encodeUriPath(inputDir.generic_string()) + "/";
  } else if (relative != ".") {
    prefix = encodeUriPath(relative.generic_string()) + "/";
  }
  auto rewrite = [&](Json& element) {
    if (!element.is_object() || !element.contains("uri") || !element["uri"].is_string()) return;
    const std::string uri = element["uri"].get<std::string>();
    if (uri.rfind("data:", 0) == 0 || uri.find("://") != std::string::npos) return;
    if (!uri.empty() && uri[0] == '/') return;  // absolute
    element["uri"] = prefix + uri;
  };
  if (doc.contains("buffers") && doc["buffers"].is_array()) {
    for (size_t i = 0; i < doc["buffers"].size(); ++i) {
      Json& b = doc["buffers"][i];
      if (glb && i == 0 && b.is_object() && !b.contains("uri") && !model.buffers.empty()) {
        const std::string name = stem + ".bin";
        out.binaries.push_back({name, std::vector<uint8_t>(model.buffers[0].data.begin(),
                                                           model.buffers[0].data.end())});
        b["uri"] = encodeUriPath(name);
        continue;
      }
      rewrite(b);
    }
  }
  if (doc.contains("images") && doc["images"].is_array())
    for (Json& image : doc["images"]) rewrite(image);

  // Lightmaps on the root and on every lightmapped node.
  if (Json* k = kilnExtras(doc)) {
    (*k)["lightmaps"] = lightmaps;
  } else {
    out.warnings.push_back(scenePath + ": extras is not an object; the output glTF does not "
                                       "list the lightmaps (see manifest.json)");
  }
  if (!doc.contains("nodes") || !doc["nodes"].is_array()) doc["nodes"] = Json::array();
  if (!doc.contains("accessors")) doc["accessors"] = Json::array();
  if (!doc.contains("bufferViews")) doc["bufferViews"] = Json::array();
  if (!doc.contains("meshes")) doc["meshes"] = Json::array();
  if (!doc.contains("buffers")) doc["buffers"] = Json::array();
  const int newBuffer = int(doc["buffers"].size());
  BinaryBuilder bin(doc, newBuffer);
  const std::vector<glm::dmat4> world = worldMatrices(model);

  for (size_t i = 0; i < result.scene.objects.size(); ++i) {
    const Object& o = result.scene.objects[i];
    if (o.nodeIndex < 0 || size_t(o.nodeIndex) >= doc["nodes"].size() ||
        size_t(o.nodeIndex) >= model.nodes.size())
      return Error{scenePath + ": object '" + o.name + "' has no node " +
                   std::to_string(o.nodeIndex)};
    Json& node = doc["nodes"][size_t(o.nodeIndex)];
    const std::string where = "nodes[" + std::to_string(o.nodeIndex) + "] '" + o.name + "'";
    if (i < result.layout.objects.size() && result.layout.objects[i].lightmapIndex >= 0) {
      const AtlasObject& a = result.layout.objects[i];
      if (Json* k = kilnExtras(node)) {
        (*k)["lightmap"] = {
            {"index", a.lightmapIndex},
            {"scaleOffset", {a.scaleOffset.x, a.scaleOffset.y, a.scaleOffset.z, a.scaleOffset.w}}};
      } else {
        out.warnings.push_back(scenePath + ": " + where +
                               ": extras is not an object; its lightmap is only in manifest.json");
      }
    }
    if (i >= result.unwraps.size() || !result.unwraps[i]) continue;

    // Generated UVs: a new mesh for this node alone.
    const UnwrapResult& unwrap = *result.unwraps[i];
    const int meshIndex = model.nodes[size_t(o.nodeIndex)].mesh;
    if (meshIndex < 0 || size_t(meshIndex) >= model.meshes.size())
      return Error{scenePath + ": " + where + " has no mesh"};
    const tinygltf::Mesh& mesh = model.meshes[size_t(meshIndex)];
    const glm::dmat4& w = world[size_t(o.nodeIndex)];
    std::optional<SourceMap> src = traceSources(model, mesh, w);
    // The trace must reproduce the loader's vertices: same triangle count, every new vertex at
    // its source's world position (float rounding aside).
    bool traced = src.has_value();
    if (traced) {
      size_t triangles = 0;
      for (size_t t : src->primitiveTriangles) triangles += t;
      traced = triangles == unwrap.triangles.size() && unwrap.vertexRemap.size() == o.positions.size();
      for (size_t v = 0; traced && v < unwrap.vertexRemap.size(); ++v) {
        const uint32_t s = unwrap.vertexRemap[v];
        if (s >= src->worldPositions.size()) {
          traced = false;
          break;
        }
        const vec3 d = src->worldPositions[s] - o.positions[v];
        const float scale = 1.0f + maxComponent(glm::abs(o.positions[v]));
        traced = maxComponent(glm::abs(d)) <= 1e-4f * scale;
      }
    }
    const Json& meshJson = doc["meshes"][size_t(meshIndex)];
    std::optional<Json> primitives;
    const size_t mark = bin.bytes().size();
    if (traced) {
      const size_t accessors = doc["accessors"].size(), views = doc["bufferViews"].size();
      primitives = rebuildFromSources(model, meshJson, mesh, *src, unwrap,
                                      glm::determinant(glm::dmat3(w)) < 0.0, bin);
      if (!primitives) {  // undo the partial rebuild
        doc["accessors"].erase(doc["accessors"].begin() + long(accessors), doc["accessors"].end());
        doc["bufferViews"].erase(doc["bufferViews"].begin() + long(views),
                                 doc["bufferViews"].end());
        bin.bytes().resize(mark);
      }
    }
    if (!primitives) {
      out.warnings.push_back(scenePath + ": " + where +
                             ": the mesh's own vertex attributes could not be traced (sparse or "
                             "compressed accessors); its lightmapped mesh was rebuilt from "
                             "positions, normals and UVs only");
      primitives = rebuildFromObject(o, w, model.materials.size(), bin);
    }
    Json newMesh = meshJson;
    newMesh["primitives"] = *primitives;
    newMesh["name"] = (meshJson.contains("name") && meshJson["name"].is_string()
                           ? meshJson["name"].get<std::string>()
                           : "meshes[" + std::to_string(meshIndex) + "]") +
                      " (lightmap UVs of " + o.name + ")";
    doc["meshes"].push_back(newMesh);
    node["mesh"] = doc["meshes"].size() - 1;
  }

  if (!bin.bytes().empty()) {
    const std::string name = stem + "_lightmap_uv.bin";
    doc["buffers"].push_back({{"uri", encodeUriPath(name)}, {"byteLength", bin.bytes().size()}});
    out.binaries.push_back({name, std::move(bin.bytes())});
  }
  for (const char* key : {"accessors", "bufferViews", "meshes", "buffers"})
    if (doc[key].empty()) doc.erase(key);
  out.text = doc.dump(1) + "\n";
  return out;
}

}  // namespace kiln
