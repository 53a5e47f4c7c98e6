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
#include <limits>
#include <map>
#include <numbers>
#include <set>
#include <nlohmann/json.hpp>
#include <sstream>

#include "lightmap/atlas.h"
#include "lightmap/ldr_encoding.h"
#include "src/gltf_loader.h"
#include "src/light_modes.h"

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
// file already; this only has to find the JSON again). *bytes: the whole file.
Result<Json> readDocumentJson(const std::string& path, bool* glb, std::vector<uint8_t>* bytesOut) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path + ": cannot open the file"};
  std::vector<uint8_t>& bytes = *bytesOut;
  bytes.assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
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
  return true;  // images are referenced or copied, never decoded or rewritten
}

// For a .glb output: keeps every image's encoded bytes, to embed them as they are.
bool keepEncodedImage(tinygltf::Image* image, const int, std::string*, std::string*, int, int,
                      const unsigned char* bytes, int size, void*) {
  image->image.assign(bytes, bytes + std::max(size, 0));
  return true;
}

// A bufferView whose bytes are EXT_meshopt_compression-compressed: through tinygltf they are
// not the values (rewriteGltfForTinyGltf even points them at a placeholder byte).
bool compressedView(const tinygltf::BufferView& bv) {
  return bv.extensions.count("EXT_meshopt_compression") != 0;
}

// Raw access to a non-sparse, uncompressed accessor's elements.
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
  if (compressedView(bv)) return std::nullopt;
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

// World matrices of every node, composed root first as the loader does: world = parent's
// world x local, each node's computed once (linear in the node count: a chain of 100,000
// nested nodes used to cost n x depth products). The products are formed in the same order
// as composing the whole chain from the root, so the results are the same bits. Nodes on a
// cycle (which the loader ignores) start from the identity.
std::vector<glm::dmat4> worldMatrices(const tinygltf::Model& m) {
  const size_t n = m.nodes.size();
  std::vector<int> parent(n, -1);
  for (size_t i = 0; i < n; ++i)
    for (int c : m.nodes[i].children)
      if (c >= 0 && size_t(c) < n) parent[size_t(c)] = int(i);
  std::vector<glm::dmat4> world(n, glm::dmat4(1.0));
  enum : uint8_t { kNotYet, kOnChain, kDone };
  std::vector<uint8_t> state(n, kNotYet);
  std::vector<int> chain;  // from node i up to the first node whose world is known
  for (size_t i = 0; i < n; ++i) {
    chain.clear();
    int k = int(i);
    for (; k >= 0 && state[size_t(k)] == kNotYet; k = parent[size_t(k)]) {
      state[size_t(k)] = kOnChain;
      chain.push_back(k);
    }
    glm::dmat4 w = k >= 0 && state[size_t(k)] == kDone ? world[size_t(k)] : glm::dmat4(1.0);
    for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
      w = w * localMatrix(m.nodes[size_t(*it)]);
      world[size_t(*it)] = w;
      state[size_t(*it)] = kDone;
    }
  }
  return world;
}

// A KHR_draco_mesh_compression primitive: its accessors have no bufferView, or hold an
// uncompressed fallback that need not match the decoded vertices (their order, their count).
bool dracoCompressed(const tinygltf::Primitive& prim) {
  return prim.extensions.count("KHR_draco_mesh_compression") != 0;
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
    // The loader's vertices are Draco's decoded ones, whatever the fallback accessors hold.
    if (dracoCompressed(prim)) return std::nullopt;
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

// uv x (sx, sy) + (ox, oy): the atlas UV (identity (1, 1, 0, 0) leaves uv as it is).
vec2 applyUvTransform(vec2 uv, vec4 so) {
  return vec2(uv.x * so.x + so.z, uv.y * so.y + so.w);
}
const vec4 kIdentityUv(1.0f, 1.0f, 0.0f, 0.0f);

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
                                       const UnwrapResult& unwrap, bool flip, vec4 uvTransform,
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
      const vec2 uv = applyUvTransform(unwrap.uv1[newVertices[i]], uvTransform);
      uv1.push_back(uv.x);
      uv1.push_back(uv.y);
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
                       vec4 uvTransform, BinaryBuilder& bin) {
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
      const vec2 uv = applyUvTransform(o.uv1[v], uvTransform);
      uv1.insert(uv1.end(), {uv.x, uv.y});
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

std::string lowerCase(std::string s) {
  for (char& c : s) c = char(std::tolower(uint8_t(c)));
  return s;
}

// An embedded image's mimeType: the data: URI's, else the JSON's, else from the bytes'
// signature (PNG, JPEG, WebP, KTX2); empty when unknown.
std::string imageMimeType(const std::string& uri, const Json& image,
                          const std::vector<unsigned char>& bytes) {
  if (uri.rfind("data:", 0) == 0) {
    const size_t end = uri.find_first_of(";,", 5);
    if (end != std::string::npos && end > 5) return uri.substr(5, end - 5);
  }
  if (image.contains("mimeType") && image["mimeType"].is_string())
    return image["mimeType"].get<std::string>();
  auto startsWith = [&](const char* sig, size_t n, size_t at = 0) {
    return bytes.size() >= at + n && std::memcmp(bytes.data() + at, sig, n) == 0;
  };
  if (startsWith("\x89PNG", 4)) return "image/png";
  if (startsWith("\xFF\xD8\xFF", 3)) return "image/jpeg";
  if (startsWith("RIFF", 4) && startsWith("WEBP", 4, 8)) return "image/webp";
  if (startsWith("\xABKTX 20\xBB", 8)) return "image/ktx2";
  return {};
}

// Names of the files copied into the output directory: a relative path inside the input's
// folder is kept, anything else (../, absolute) goes by its file name; a name already taken
// (by a file kiln writes, by another source, or an input file of the document that is not
// this source) gets "_2", "_3", ... before its extension. Compared case-insensitively, for
// case-insensitive file systems.
class ResourcePlacer {
 public:
  ResourcePlacer(fs::path outputDir, const std::vector<std::string>& reserved,
                 std::set<fs::path> sources)
      : outputDir_(std::move(outputDir)), sources_(std::move(sources)) {
    for (const std::string& name : reserved) taken_[lowerCase(name)] = fs::path();
  }

  // The output name of `source` (canonical), referenced as the relative path `wanted`.
  // *inPlace: the source is already that file of the output directory.
  std::string place(const fs::path& source, const fs::path& wanted, bool* inPlace) {
    if (auto it = bySource_.find(source); it != bySource_.end()) {
      *inPlace = inPlace_[source];
      return it->second;
    }
    fs::path rel = wanted.lexically_normal();
    if (rel.is_absolute() || rel.empty() || *rel.begin() == ".." || !rel.has_filename())
      rel = wanted.filename();
    const std::string stem = rel.stem().string(), ext = rel.extension().string();
    std::string name = rel.generic_string();
    for (int n = 2;; ++n) {
      const fs::path dest = outputDir_ / name;
      std::error_code ec;
      const fs::path canonical = fs::weakly_canonical(dest, ec);
      const bool self = !ec && canonical == source;
      const bool otherInput = !ec && !self && sources_.count(canonical);
      auto taken = taken_.find(lowerCase(name));
      if (!otherInput && (taken == taken_.end() || taken->second == source)) {
        taken_[lowerCase(name)] = source;
        bySource_[source] = name;
        inPlace_[source] = self;
        *inPlace = self;
        return name;
      }
      name = (rel.parent_path() / (stem + "_" + std::to_string(n) + ext)).generic_string();
    }
  }

 private:
  fs::path outputDir_;
  std::set<fs::path> sources_;  // every input file of the document, canonical
  std::map<std::string, fs::path> taken_;
  std::map<fs::path, std::string> bySource_;
  std::map<fs::path, bool> inPlace_;
};

// True when a material (or anything in it: extensions' texture infos too) has a texture info
// with "texCoord": 1.
bool readsTexcoord1(const Json& j) {
  if (j.is_object()) {
    if (j.contains("index") && j.contains("texCoord") && j["texCoord"] == 1) return true;
    for (const auto& [key, value] : j.items())
      if (key != "extras" && readsTexcoord1(value)) return true;
  } else if (j.is_array()) {
    for (const Json& v : j)
      if (readsTexcoord1(v)) return true;
  }
  return false;
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

// Builds the output glTF of one bake; buildOutputGltf runs it. The stages run in the order of
// run(), which is part of the output: it fixes the indices of everything appended (images,
// textures, samplers, accessors, bufferViews, meshes, lights) and the order of the warnings.
class OutputGltfBuilder {
 public:
  OutputGltfBuilder(const std::string& scenePath, const LightmapBakeResult& result,
                    const Json& lightmaps, const OutputGltfOptions& options)
      : scenePath_(scenePath),
        result_(result),
        lightmaps_(lightmaps),
        options_(options),
        rgbm_(options.ldr == LdrEncoding::Rgbm) {}

  Result<OutputGltf> run() {
    if (Status s = readInput(); !s) return Error{s.error()};
    if (Status s = planOutputNames(); !s) return Error{s.error()};
    makeSelfContained();
    addRootLightmaps();
    prepareAppendedArrays();
    addLightmapTextures();
    countMeshUsers();
    for (size_t i = 0; i < result_.scene.objects.size(); ++i)
      if (Status s = editObject(i); !s) return Error{s.error()};
    listLightmapExtension();
    markBakedLights();
    addUvBuffer();
    if (options_.glb) {
      if (Status s = mergeBuffersIntoChunk(); !s) return Error{s.error()};
      embedImages();
      if (Status s = writeGlbContainer(); !s) return Error{s.error()};
    } else {
      writeGltfText();
    }
    return std::move(out_);
  }

 private:
  // A buffer or image of the document that references a file (copied or embedded).
  struct FileRef {
    Json* element;
    std::string where;
    fs::path source;   // canonical
    fs::path wanted;   // the URI, decoded
  };

  // One baked Object's node and how its lightmap UVs are written.
  struct ObjectEdit {
    size_t index;  // in result.scene.objects (and result.layout.objects, result.unwraps)
    const Object& object;
    Json& node;
    std::string where;  // "nodes[i] 'name'", for messages
    bool lightmapped;
    vec4 uvTransform;  // applied to the TEXCOORD_1 written
    vec4 nodeSo;       // the node's scale/offset
  };

  // How far the accessors, bufferViews and new bytes reach: a partial rebuild is dropped back
  // to it.
  struct Checkpoint {
    size_t bytes, accessors, views;
  };

  // Checks the options and reads the input twice: its JSON (edited and written out) and,
  // through tinygltf, its buffers (the mesh data to rebuild from; the images' encoded bytes
  // too for a .glb output).
  Status readInput() {
    if (options_.ldr == LdrEncoding::None)
      return Error{"the output glTF needs the LDR pages (its lightmap textures)"};
    if (options_.ldrPages.size() != result_.layout.pages.size() ||
        (options_.glb && options_.ldrPngs.size() != result_.layout.pages.size()))
      return Error{"the output glTF needs one LDR page per lightmap page"};
    std::vector<uint8_t> bytes;
    Result<Json> parsed = readDocumentJson(scenePath_, &inputIsGlb_, &bytes);
    if (!parsed) return Error{parsed.error()};
    doc_ = std::move(parsed).value();
    if (bytes.size() > std::numeric_limits<unsigned int>::max())
      return Error{scenePath_ + ": file too large for tinygltf (4 GiB)"};

    // The document as the loader gives it to tinygltf (compressed glTF: placeholders where
    // tinygltf insists on data kiln does not read from it).
    const std::vector<GltfViewlessIndices> viewless = rewriteGltfForTinyGltf(doc_, &bytes);
    tinygltf::TinyGLTF loader;
    loader.SetImageLoader(options_.glb ? keepEncodedImage : skipImage, nullptr);
    std::string err, warn;
    const std::string baseDir = fs::absolute(fs::path(scenePath_)).parent_path().string();
    const bool ok =
        inputIsGlb_
            ? loader.LoadBinaryFromMemory(&model_, &err, &warn, bytes.data(),
                                          static_cast<unsigned int>(bytes.size()), baseDir)
            : loader.LoadASCIIFromString(&model_, &err, &warn,
                                         reinterpret_cast<const char*>(bytes.data()),
                                         static_cast<unsigned int>(bytes.size()), baseDir);
    if (!ok) return Error{scenePath_ + ": " + (err.empty() ? "cannot be read" : err)};
    for (const GltfViewlessIndices& v : viewless)
      model_.meshes[v.mesh].primitives[v.primitive].indices = v.accessor;
    // Buffers the document gives no data (meshopt fallbacks): tinygltf holds a placeholder.
    const Json& buffers = doc_.contains("buffers") && doc_["buffers"].is_array()
                              ? doc_["buffers"] : Json::array();
    for (size_t i = 0; i < buffers.size(); ++i)
      if (buffers[i].is_object() && !buffers[i].contains("uri") && !(inputIsGlb_ && i == 0))
        dataLessBuffers_.insert(i);
    // The output shows the scene kiln baked (--scene).
    if (result_.scene.gltfScene >= 0) doc_["scene"] = result_.scene.gltfScene;
    return Status::success();
  }

  // The output's file names, and the input and output folders the copied files are placed
  // between. The output must not replace the input scene.
  Status planOutputNames() {
    const fs::path input(scenePath_);
    const std::string stem = input.stem().string();
    out_.fileName = stem + (options_.glb ? ".glb" : ".gltf");
    std::error_code ec;
    inputDir_ = fs::weakly_canonical(fs::absolute(input).parent_path(), ec);
    outputDir_ = fs::weakly_canonical(fs::absolute(fs::path(options_.outDir)), ec);
    inputFile_ = fs::weakly_canonical(fs::absolute(input), ec);
    if (inputFile_ == outputDir_ / out_.fileName)
      return Error{scenePath_ + ": the output glTF " + (outputDir_ / out_.fileName).string() +
                   " would overwrite the input scene; choose another output directory"};
    glbChunkName_ = stem + ".bin";
    uvBufferName_ = stem + "_lightmap_uv.bin";
    return Status::success();
  }

  // Self-contained output: every file the document references is copied into the output
  // directory (a .glb output embeds them later); data: URIs stay.
  void makeSelfContained() {
    if (!doc_.contains("buffers") || !doc_["buffers"].is_array()) doc_["buffers"] = Json::array();
    if (!doc_.contains("images") || !doc_["images"].is_array()) doc_["images"] = Json::array();
    for (size_t i = 0; i < doc_["buffers"].size(); ++i)
      collectFileRef(doc_["buffers"][i], "buffers[" + std::to_string(i) + "]");
    for (size_t i = 0; i < doc_["images"].size(); ++i)
      collectFileRef(doc_["images"][i], "images[" + std::to_string(i) + "]");
    if (!options_.glb) placeFiles();
  }

  // Records `element`'s URI when it names an existing file; warns about other URIs (kept).
  void collectFileRef(Json& element, const std::string& where) {
    if (!element.is_object() || !element.contains("uri") || !element["uri"].is_string()) return;
    const std::string uri = element["uri"].get<std::string>();
    if (uri.rfind("data:", 0) == 0) return;
    if (uri.find("://") != std::string::npos) {
      out_.warnings.push_back(scenePath_ + ": " + where + ": '" + uri +
                              "' is not a file; the output references it as it is");
      return;
    }
    const fs::path decoded = fs::path(percentDecode(uri));
    std::error_code e;
    const fs::path source = fs::weakly_canonical(inputDir_ / decoded, e);
    if (e || !fs::is_regular_file(source, e)) {
      out_.warnings.push_back(scenePath_ + ": " + where + ": file '" + uri +
                              "' not found; its URI is kept as it was");
      return;
    }
    fileRefs_.push_back({&element, where, source, decoded});
  }

  // A .gltf output: names every referenced file in the output directory (ResourcePlacer),
  // rewrites the URIs and lists the copies; a .glb input's binary chunk becomes a file.
  void placeFiles() {
    std::set<fs::path> sources = {inputFile_};
    for (const FileRef& r : fileRefs_) sources.insert(r.source);
    std::vector<std::string> reserved = options_.reservedNames;
    reserved.insert(reserved.end(), {out_.fileName, uvBufferName_});
    if (inputIsGlb_) reserved.push_back(glbChunkName_);
    reserved.insert(reserved.end(), options_.ldrPages.begin(), options_.ldrPages.end());
    ResourcePlacer placer(outputDir_, reserved, sources);
    std::set<std::string> copied;
    for (FileRef& r : fileRefs_) {
      bool inPlace = false;
      const std::string name = placer.place(r.source, r.wanted, &inPlace);
      (*r.element)["uri"] = encodeUriPath(name);
      if (!inPlace && copied.insert(name).second) out_.copies.push_back({name, r.source.string()});
    }
    // A .glb input's binary chunk becomes a file.
    if (inputIsGlb_ && !doc_["buffers"].empty() && doc_["buffers"][0].is_object() &&
        !doc_["buffers"][0].contains("uri") && !model_.buffers.empty()) {
      out_.binaries.push_back({glbChunkName_, std::vector<uint8_t>(model_.buffers[0].data.begin(),
                                                                   model_.buffers[0].data.end())});
      doc_["buffers"][0]["uri"] = encodeUriPath(glbChunkName_);
    }
  }

  // Lightmaps on the root (the manifest's "lightmaps" array: EXR pages and mixed-lighting
  // data stay there); the lightmapped nodes get theirs in markLightmappedNode.
  void addRootLightmaps() {
    if (Json* k = kilnExtras(doc_)) {
      (*k)["lightmaps"] = lightmaps_;
    } else {
      out_.warnings.push_back(scenePath_ +
                              ": extras is not an object; the output glTF does not "
                              "list the lightmaps (see manifest.json)");
    }
  }

  // The arrays the next stages append to, and the new buffer (after every input buffer) that
  // receives the rebuilt meshes' data.
  void prepareAppendedArrays() {
    if (!doc_.contains("nodes") || !doc_["nodes"].is_array()) doc_["nodes"] = Json::array();
    if (!doc_.contains("accessors")) doc_["accessors"] = Json::array();
    if (!doc_.contains("bufferViews")) doc_["bufferViews"] = Json::array();
    if (!doc_.contains("meshes")) doc_["meshes"] = Json::array();
    if (!doc_.contains("textures") || !doc_["textures"].is_array())
      doc_["textures"] = Json::array();
    if (!doc_.contains("samplers") || !doc_["samplers"].is_array())
      doc_["samplers"] = Json::array();
    const int newBuffer = int(doc_["buffers"].size());
    bin_.emplace(doc_, newBuffer);
    world_ = worldMatrices(model_);
  }

  // The lightmap textures: one image (the LDR PNG) and texture per page, one sampler.
  void addLightmapTextures() {
    firstLightmapImage_ = doc_["images"].size();
    if (!options_.ldrPages.empty())
      doc_["samplers"].push_back({{"magFilter", 9729},  // LINEAR
                                  {"minFilter", 9729},  // LINEAR, no mipmaps
                                  {"wrapS", 33071},     // CLAMP_TO_EDGE
                                  {"wrapT", 33071},
                                  {"name", "kiln lightmap"}});
    const size_t sampler = doc_["samplers"].size() - 1;
    for (size_t p = 0; p < options_.ldrPages.size(); ++p) {
      doc_["images"].push_back({{"uri", encodeUriPath(options_.ldrPages[p])},
                                {"mimeType", "image/png"},
                                {"name", "lightmap-" + std::to_string(p)}});
      doc_["textures"].push_back({{"sampler", sampler},
                                  {"source", doc_["images"].size() - 1},
                                  {"name", "lightmap-" + std::to_string(p)}});
      pageTexture_.push_back(doc_["textures"].size() - 1);
    }
  }

  // How many nodes use each mesh: a node's TEXCOORD_1 can only change in place when it is the
  // mesh's only user.
  void countMeshUsers() {
    meshUsers_.assign(doc_["meshes"].size(), 0);
    for (const Json& node : doc_["nodes"])
      if (node.is_object() && node.contains("mesh") && node["mesh"].is_number_integer()) {
        const int64_t m = node["mesh"].get<int64_t>();
        if (m >= 0 && size_t(m) < meshUsers_.size()) ++meshUsers_[size_t(m)];
      }
  }

  // One baked Object: its node's lightmap, then its node's mesh when kiln writes its
  // TEXCOORD_1 (generated lightmap UVs, or --atlas-uv).
  Status editObject(size_t i) {
    const Object& o = result_.scene.objects[i];
    if (o.nodeIndex < 0 || size_t(o.nodeIndex) >= doc_["nodes"].size() ||
        size_t(o.nodeIndex) >= model_.nodes.size())
      return Error{scenePath_ + ": object '" + o.name + "' has no node " +
                   std::to_string(o.nodeIndex)};
    const bool lightmapped =
        i < result_.layout.objects.size() && result_.layout.objects[i].lightmapIndex >= 0;
    const vec4 so = lightmapped ? result_.layout.objects[i].scaleOffset : kIdentityUv;
    // With atlasUv the transform moves into TEXCOORD_1 and the glTF's is identity.
    const ObjectEdit e{i,
                       o,
                       doc_["nodes"][size_t(o.nodeIndex)],
                       "nodes[" + std::to_string(o.nodeIndex) + "] '" + o.name + "'",
                       lightmapped,
                       lightmapped && options_.atlasUv ? so : kIdentityUv,
                       lightmapped && options_.atlasUv ? kIdentityUv : so};
    if (Status s = markLightmappedNode(e); !s) return s;
    markProbeLitNode(e);
    const bool generated = i < result_.unwraps.size() && result_.unwraps[i].has_value();
    if (!generated && !(lightmapped && options_.atlasUv)) return Status::success();
    return rebuildNodeMesh(e, generated);
  }

  // A lightmapped node's extras.kiln.lightmap and its MX_lightmap extension (the shared
  // contract, gltf_writer.h); an extras or extensions that is not an object is left alone
  // with a warning.
  Status markLightmappedNode(const ObjectEdit& e) {
    if (!e.lightmapped) return Status::success();
    Json& node = e.node;
    const vec4 nodeSo = e.nodeSo;
    const AtlasObject& a = result_.layout.objects[e.index];
    if (size_t(a.lightmapIndex) >= pageTexture_.size())
      return Error{e.where + ": lightmap " + std::to_string(a.lightmapIndex) + " has no page"};
    if (Json* k = kilnExtras(node)) {
      (*k)["lightmap"] = {{"index", a.lightmapIndex},
                          {"scaleOffset", {nodeSo.x, nodeSo.y, nodeSo.z, nodeSo.w}}};
    } else {
      out_.warnings.push_back(scenePath_ + ": " + e.where +
                              ": extras is not an object; its lightmap is only in manifest.json");
    }
    if (!node.contains("extensions")) node["extensions"] = Json::object();
    if (!node["extensions"].is_object()) {
      out_.warnings.push_back(scenePath_ + ": " + e.where + ": extensions is not an object; no " +
                              kLightmapExtension);
    } else {
      node["extensions"][kLightmapExtension] = {
          {"lightMapTexture", {{"index", pageTexture_[size_t(a.lightmapIndex)]}, {"texCoord", 1}}},
          {"scale", {nodeSo.x, nodeSo.y}},
          {"offset", {nodeSo.z, nodeSo.w}},
          {"intensity", lightmapIntensity(options_.ldr)},
          {"extras",
           {{"kiln",
             {{"page", a.lightmapIndex},
              {"encoding", rgbm_ ? "rgbm" : "dldr"},
              {"range", rgbm_ ? int(kRgbmRange) : int(kDldrRange)}}}}}};
      lightmapUsed_ = true;
    }
    return Status::success();
  }

  // A probe-lit node's own light (lightmap/probe_lit.h): extras.kiln.probeSH (27 numbers, the
  // manifest's "probeSH") and, when some light has a shadowmask channel, .probeOcclusion.
  // An input that is itself a bake's output loses the earlier bake's values.
  void markProbeLitNode(const ObjectEdit& e) {
    if (e.node.contains("extras") && e.node["extras"].is_object() &&
        e.node["extras"].contains("kiln") && e.node["extras"]["kiln"].is_object()) {
      e.node["extras"]["kiln"].erase("probeSH");
      e.node["extras"]["kiln"].erase("probeOcclusion");
    }
    if (e.index >= result_.objectProbes.size() || !result_.objectProbes[e.index]) return;
    const ObjectProbe& probe = *result_.objectProbes[e.index];
    Json* k = kilnExtras(e.node);
    if (!k) {
      out_.warnings.push_back(scenePath_ + ": " + e.where +
                              ": extras is not an object; its probe light is only in "
                              "manifest.json");
      return;
    }
    Json sh = Json::array();
    for (const vec3& c : probe.sh.c) sh.insert(sh.end(), {c.x, c.y, c.z});
    (*k)["probeSH"] = std::move(sh);
    bool withShadowmask = false;
    for (int c : result_.lightModes.shadowmaskChannel) withShadowmask |= c >= 0;
    if (withShadowmask)
      (*k)["probeOcclusion"] = {probe.occlusion.x, probe.occlusion.y, probe.occlusion.z,
                                probe.occlusion.w};
  }

  // The node's new TEXCOORD_1: --atlas-uv on its own TEXCOORD_1 changes the mesh in place
  // when the node is its only user; otherwise the node gets a new mesh of its own (generated
  // UVs: rebuilt from the original attributes, else from the baked Object).
  Status rebuildNodeMesh(const ObjectEdit& e, bool generated) {
    const Object& o = e.object;
    const int meshIndex = model_.nodes[size_t(o.nodeIndex)].mesh;
    if (meshIndex < 0 || size_t(meshIndex) >= model_.meshes.size())
      return Error{scenePath_ + ": " + e.where + " has no mesh"};
    const tinygltf::Mesh& mesh = model_.meshes[size_t(meshIndex)];
    const glm::dmat4& w = world_[size_t(o.nodeIndex)];
    const Json& meshJson = doc_["meshes"][size_t(meshIndex)];
    std::optional<Json> primitives;
    if (!generated) {
      primitives = atlasUvPrimitives(e, mesh, meshJson);
      if (primitives && meshUsers_[size_t(meshIndex)] == 1) {
        doc_["meshes"][size_t(meshIndex)]["primitives"] = *primitives;  // its only user
        return Status::success();
      }
    } else {
      primitives = generatedUvPrimitives(e, mesh, meshJson, w);
    }
    if (!primitives) {
      out_.warnings.push_back(scenePath_ + ": " + e.where +
                              ": the mesh's own vertex attributes could not be traced (sparse or "
                              "compressed accessors); its lightmapped mesh was rebuilt from "
                              "positions, normals and UVs only");
      primitives = rebuildFromObject(o, w, model_.materials.size(), e.uvTransform, *bin_);
    }
    Json newMesh = meshJson;
    newMesh["primitives"] = *primitives;
    newMesh["name"] = (meshJson.contains("name") && meshJson["name"].is_string()
                           ? meshJson["name"].get<std::string>()
                           : "meshes[" + std::to_string(meshIndex) + "]") +
                      " (lightmap UVs of " + o.name + ")";
    doc_["meshes"].push_back(newMesh);
    e.node["mesh"] = doc_["meshes"].size() - 1;
    return Status::success();
  }

  // atlasUv on the node's own TEXCOORD_1: a new accessor per primitive, everything else
  // shared with the original mesh. nullopt (nothing appended) when a TEXCOORD_1 cannot be
  // read.
  std::optional<Json> atlasUvPrimitives(const ObjectEdit& e, const tinygltf::Mesh& mesh,
                                        const Json& meshJson) {
    const Checkpoint mark = checkpoint();
    std::optional<Json> primitives = meshJson["primitives"];
    for (size_t j = 0; j < mesh.primitives.size() && primitives; ++j) {
      // A Draco primitive's TEXCOORD_1 is the decoder's (a new accessor would not replace it).
      if (dracoCompressed(mesh.primitives[j])) {
        primitives.reset();
        break;
      }
      auto uv = mesh.primitives[j].attributes.find("TEXCOORD_1");
      if (uv == mesh.primitives[j].attributes.end()) continue;
      const int material = mesh.primitives[j].material;
      if (material >= 0 && size_t(material) < model_.materials.size() &&
          doc_.contains("materials") && doc_["materials"].is_array() &&
          size_t(material) < doc_["materials"].size() &&
          readsTexcoord1(doc_["materials"][size_t(material)]) &&
          warnedMaterials_.insert(material).second)
        out_.warnings.push_back(scenePath_ + ": materials[" + std::to_string(material) +
                                "] samples a texture with TEXCOORD_1, which --atlas-uv turns "
                                "into atlas UVs");
      std::optional<AccessorView> v = viewAccessor(model_, uv->second);
      if (!v || v->components != 2) {
        primitives.reset();
        break;
      }
      std::vector<float> values;
      values.reserve(v->count * 2);
      const size_t cs = v->elemSize / 2;
      for (size_t k = 0; k < v->count; ++k) {
        const vec2 t(float(readGltfComponent(v->element(k), v->componentType, v->normalized)),
                     float(readGltfComponent(v->element(k) + cs, v->componentType, v->normalized)));
        const vec2 a = applyUvTransform(t, e.uvTransform);
        values.insert(values.end(), {a.x, a.y});
      }
      (*primitives)[j]["attributes"]["TEXCOORD_1"] = bin_->addFloats(values, 2, "VEC2", false);
    }
    if (!primitives) rollback(mark);
    return primitives;
  }

  // Generated UVs: a new mesh for this node alone, rebuilt from the original primitives'
  // attributes. nullopt (nothing appended) when the loader's vertices cannot be traced back
  // to them.
  std::optional<Json> generatedUvPrimitives(const ObjectEdit& e, const tinygltf::Mesh& mesh,
                                            const Json& meshJson, const glm::dmat4& w) {
    const Checkpoint mark = checkpoint();
    const UnwrapResult& unwrap = *result_.unwraps[e.index];
    std::optional<SourceMap> src = traceSources(model_, mesh, w);
    if (!src || !reproducesLoaderVertices(*src, unwrap, e.object)) return std::nullopt;
    std::optional<Json> primitives =
        rebuildFromSources(model_, meshJson, mesh, *src, unwrap,
                           glm::determinant(glm::dmat3(w)) < 0.0, e.uvTransform, *bin_);
    if (!primitives) rollback(mark);
    return primitives;
  }

  // The trace must reproduce the loader's vertices: same triangle count, every new vertex
  // at its source's world position (float rounding aside).
  static bool reproducesLoaderVertices(const SourceMap& src, const UnwrapResult& unwrap,
                                       const Object& o) {
    size_t triangles = 0;
    for (size_t t : src.primitiveTriangles) triangles += t;
    bool traced =
        triangles == unwrap.triangles.size() && unwrap.vertexRemap.size() == o.positions.size();
    for (size_t v = 0; traced && v < unwrap.vertexRemap.size(); ++v) {
      const uint32_t s = unwrap.vertexRemap[v];
      if (s >= src.worldPositions.size()) return false;
      const vec3 d = src.worldPositions[s] - o.positions[v];
      const float scale = 1.0f + maxComponent(glm::abs(o.positions[v]));
      traced = maxComponent(glm::abs(d)) <= 1e-4f * scale;
    }
    return traced;
  }

  Checkpoint checkpoint() {
    return {bin_->bytes().size(), doc_["accessors"].size(), doc_["bufferViews"].size()};
  }

  // Drops a partial rebuild.
  void rollback(const Checkpoint& mark) {
    doc_["accessors"].erase(doc_["accessors"].begin() + long(mark.accessors),
                            doc_["accessors"].end());
    doc_["bufferViews"].erase(doc_["bufferViews"].begin() + long(mark.views),
                              doc_["bufferViews"].end());
    bin_->bytes().resize(mark.bytes);
  }

  void listLightmapExtension() {
    if (!lightmapUsed_) return;
    if (!doc_.contains("extensionsUsed") || !doc_["extensionsUsed"].is_array())
      doc_["extensionsUsed"] = Json::array();
    Json& used = doc_["extensionsUsed"];
    if (std::find(used.begin(), used.end(), Json(kLightmapExtension)) == used.end())
      used.push_back(kLightmapExtension);
  }

  // Baked lights: a viewer must not add them again. Instances of one light that differ (a
  // Shadowmask light without a channel is baked fully) get a copy of the light each.
  void markBakedLights() {
    if (result_.scene.lights.empty() || !doc_.contains("extensions") ||
        !doc_["extensions"].is_object() || !doc_["extensions"].contains("KHR_lights_punctual") ||
        !doc_["extensions"]["KHR_lights_punctual"].is_object() ||
        !doc_["extensions"]["KHR_lights_punctual"].contains("lights") ||
        !doc_["extensions"]["KHR_lights_punctual"]["lights"].is_array())
      return;
    Json& lights = doc_["extensions"]["KHR_lights_punctual"]["lights"];
    const LightModePlan& plan = result_.lightModes;
    std::map<std::pair<int, bool>, size_t> definition;  // (light, baked) -> lights[] index
    std::set<int> marked;
    for (size_t l = 0; l < result_.scene.lights.size(); ++l) {
      const Light& light = result_.scene.lights[l];
      if (light.lightIndex < 0 || size_t(light.lightIndex) >= lights.size() ||
          light.nodeIndex < 0 || size_t(light.nodeIndex) >= doc_["nodes"].size())
        continue;
      const bool baked =
          l < plan.bakeDirect.size() ? bool(plan.bakeDirect[l]) : light.mode == LightMode::Baked;
      const std::pair<int, bool> key{light.lightIndex, baked};
      if (definition.count(key)) {
        if (definition[key] != size_t(light.lightIndex))
          doc_["nodes"][size_t(light.nodeIndex)]["extensions"]["KHR_lights_punctual"]["light"] =
              definition[key];
        continue;
      }
      if (marked.insert(light.lightIndex).second) {
        markLight(lights[size_t(light.lightIndex)], light, baked);
        definition[key] = size_t(light.lightIndex);
        continue;
      }
      Json copy = lights[size_t(light.lightIndex)];
      markLight(copy, light, baked);
      lights.push_back(copy);
      definition[key] = lights.size() - 1;
      doc_["nodes"][size_t(light.nodeIndex)]["extensions"]["KHR_lights_punctual"]["light"] =
          lights.size() - 1;
    }
  }

  // extras.kiln.baked and .mode of one light definition.
  void markLight(Json& element, const Light& light, bool baked) {
    if (Json* k = kilnExtras(element)) {
      (*k)["baked"] = baked;
      (*k)["mode"] = lightModeName(light.mode);
    } else {
      out_.warnings.push_back(scenePath_ + ": extensions.KHR_lights_punctual.lights[" +
                              std::to_string(light.lightIndex) +
                              "]: extras is not an object; not marked baked or not");
    }
  }

  // The rebuilt meshes' data: the new buffer (a file beside a .gltf; merged into a .glb).
  void addUvBuffer() {
    if (bin_->bytes().empty()) return;
    doc_["buffers"].push_back(
        {{"uri", encodeUriPath(uvBufferName_)}, {"byteLength", bin_->bytes().size()}});
    if (!options_.glb) out_.binaries.push_back({uvBufferName_, bin_->bytes()});
  }

  // .glb: one file: every buffer into the BIN chunk (each starting on 8 bytes, so that every
  // accessor keeps its alignment), every bufferView (and EXT_meshopt_compression's compressed
  // range) moved onto buffer 0. Buffers without data stay so, after it (buffers 1, 2, ...).
  Status mergeBuffersIntoChunk() {
    constexpr size_t kKept = std::numeric_limits<size_t>::max();
    std::vector<size_t> base, keptIndex;
    for (size_t b = 0; b < doc_["buffers"].size(); ++b) {
      const Json& buffer = doc_["buffers"][b];
      keptIndex.push_back(0);
      if (dataLessBuffers_.count(b)) {
        keptBuffers_.push_back(buffer);
        keptIndex.back() = keptBuffers_.size();
        base.push_back(kKept);
        continue;
      }
      const size_t length = buffer.is_object() && buffer.contains("byteLength") &&
                                    buffer["byteLength"].is_number_integer() &&
                                    buffer["byteLength"].get<int64_t>() > 0
                                ? buffer["byteLength"].get<size_t>()
                                : 0;
      const std::vector<unsigned char>& data =
          b < model_.buffers.size() ? model_.buffers[b].data : bin_->bytes();
      if (data.size() < length)
        return Error{scenePath_ + ": buffers[" + std::to_string(b) + "] holds " +
                     std::to_string(data.size()) + " bytes, less than its byteLength " +
                     std::to_string(length)};
      while (chunk_.size() % 8) chunk_.push_back(0);
      base.push_back(chunk_.size());
      chunk_.insert(chunk_.end(), data.begin(), data.begin() + long(length));
    }
    // (kiln's own views hold signed integers, the parsed ones unsigned: both are integers)
    auto move = [&](Json& range) {
      if (!range.is_object() || !range.contains("buffer") || !range["buffer"].is_number_integer())
        return;
      const int64_t b = range["buffer"].get<int64_t>();
      if (b < 0 || size_t(b) >= base.size()) return;  // the loader rejects it; left as it was
      if (base[size_t(b)] == kKept) {
        range["buffer"] = keptIndex[size_t(b)];
        return;
      }
      range["buffer"] = 0;
      range["byteOffset"] = base[size_t(b)] + range.value("byteOffset", size_t(0));
    };
    for (Json& view : doc_["bufferViews"]) {
      move(view);
      if (view.is_object() && view.contains("extensions") && view["extensions"].is_object() &&
          view["extensions"].contains("EXT_meshopt_compression"))
        move(view["extensions"]["EXT_meshopt_compression"]);
    }
    // Buffer 0 must exist for the kept ones to be 1, 2, ...
    if (!keptBuffers_.empty() && chunk_.empty()) chunk_ = std::vector<uint8_t>(4, 0);
    return Status::success();
  }

  // .glb: every image with a URI (the lightmap PNGs too) into a bufferView of its own, with
  // its mimeType.
  void embedImages() {
    for (size_t i = 0; i < doc_["images"].size(); ++i) {
      Json& image = doc_["images"][i];
      if (!image.is_object() || !image.contains("uri") || !image["uri"].is_string()) continue;
      const std::string uri = image["uri"].get<std::string>();
      const bool page = i >= firstLightmapImage_;
      const std::vector<unsigned char>& bytes =
          page ? options_.ldrPngs[i - firstLightmapImage_] : model_.images[i].image;
      if (bytes.empty()) continue;  // not found: warned above, the URI kept
      const std::string mime = page ? "image/png" : imageMimeType(uri, image, bytes);
      if (mime.empty()) {
        out_.warnings.push_back(scenePath_ + ": images[" + std::to_string(i) +
                                "]: unknown image type; left as the URI '" + uri + "'");
        continue;
      }
      while (chunk_.size() % 4) chunk_.push_back(0);
      doc_["bufferViews"].push_back(
          {{"buffer", 0}, {"byteOffset", chunk_.size()}, {"byteLength", bytes.size()}});
      chunk_.insert(chunk_.end(), bytes.begin(), bytes.end());
      image.erase("uri");
      image["bufferView"] = doc_["bufferViews"].size() - 1;
      image["mimeType"] = mime;
    }
  }

  // .glb: the container (header, JSON chunk, BIN chunk), within the format's 4 GiB.
  Status writeGlbContainer() {
    while (chunk_.size() % 4) chunk_.push_back(0);
    doc_["buffers"] = Json::array();
    if (!chunk_.empty()) doc_["buffers"].push_back({{"byteLength", chunk_.size()}});
    for (const Json& kept : keptBuffers_) doc_["buffers"].push_back(kept);
    dropEmptyArrays();
    std::string json = doc_.dump();
    while (json.size() % 4) json.push_back(' ');  // the JSON chunk is padded with spaces
    auto u32 = [&](uint32_t v) {
      for (int k = 0; k < 4; ++k) out_.contents.push_back(uint8_t(v >> (8 * k)));
    };
    const uint64_t total = 12 + 8 + json.size() + (chunk_.empty() ? 0 : 8 + chunk_.size());
    if (total > 0xFFFFFFFFull)
      return Error{scenePath_ + ": the output .glb would be " + std::to_string(total) +
                   " bytes, more than a .glb can hold (4 GiB); write a .gltf instead"};
    out_.contents.reserve(size_t(total));
    out_.contents.insert(out_.contents.end(), {'g', 'l', 'T', 'F'});
    u32(2);
    u32(uint32_t(total));
    u32(uint32_t(json.size()));
    out_.contents.insert(out_.contents.end(), {'J', 'S', 'O', 'N'});
    out_.contents.insert(out_.contents.end(), json.begin(), json.end());
    if (!chunk_.empty()) {
      u32(uint32_t(chunk_.size()));
      out_.contents.insert(out_.contents.end(), {'B', 'I', 'N', 0});
      out_.contents.insert(out_.contents.end(), chunk_.begin(), chunk_.end());
    }
    return Status::success();
  }

  // .gltf: the JSON text, indented by one space.
  void writeGltfText() {
    dropEmptyArrays();
    const std::string text = doc_.dump(1) + "\n";
    out_.contents.assign(text.begin(), text.end());
  }

  // Arrays kiln created (or found) empty are left out of the output.
  void dropEmptyArrays() {
    for (const char* key :
         {"accessors", "bufferViews", "meshes", "buffers", "textures", "samplers", "images"})
      if (doc_[key].empty()) doc_.erase(key);
  }

  const std::string& scenePath_;
  const LightmapBakeResult& result_;
  const Json& lightmaps_;  // the manifest's "lightmaps" array
  const OutputGltfOptions& options_;
  const bool rgbm_;  // the LDR pages are RGBM (else dLDR)

  OutputGltf out_;
  Json doc_;  // the input document, edited into the output
  bool inputIsGlb_ = false;
  tinygltf::Model model_;  // the input's buffers (and, for a .glb output, images' bytes)
  fs::path inputDir_, outputDir_, inputFile_;  // canonical
  std::string glbChunkName_, uvBufferName_;
  std::vector<FileRef> fileRefs_;
  std::optional<BinaryBuilder> bin_;  // the rebuilt meshes' accessors, into a new buffer
  std::vector<glm::dmat4> world_;     // every node's world matrix
  size_t firstLightmapImage_ = 0;     // images[] index of page 0's PNG
  std::vector<size_t> pageTexture_;   // per page: its textures[] index
  std::vector<int> meshUsers_;        // per mesh: how many nodes use it
  bool lightmapUsed_ = false;         // some node got MX_lightmap
  std::set<int> warnedMaterials_;     // --atlas-uv and a material that reads TEXCOORD_1
  std::vector<uint8_t> chunk_;        // .glb: the BIN chunk
  std::set<size_t> dataLessBuffers_;  // input buffers without data (meshopt fallbacks)
  Json keptBuffers_ = Json::array();  // .glb: those buffers, after the BIN chunk's
};

}  // namespace

double lightmapIntensity(LdrEncoding encoding) {
  return encoding == LdrEncoding::Rgbm ? std::numbers::pi : 2.0 * std::numbers::pi;
}

Result<OutputGltf> buildOutputGltf(const std::string& scenePath, const LightmapBakeResult& result,
                                   const Json& lightmaps, const OutputGltfOptions& options) {
  return OutputGltfBuilder(scenePath, result, lightmaps, options).run();
}

}  // namespace kiln
