// gltf_test_scenes.h: glTF files written by tests from the shipped Cornell box, shared by the
// loader's coverage test and the output glTF test: byte helpers, the shipped box's JSON and
// .bin (Shipped), and its EXT_meshopt_compression copy (writeMeshoptCornell).
#pragma once

#include <gtest/gtest.h>
#include <meshoptimizer.h>

#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/test_util.h"

namespace kiln::test {

inline constexpr int kGltfI8 = 5120, kGltfU16 = 5123, kGltfU32 = 5125, kGltfF32 = 5126;

inline std::vector<uint8_t> readBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}
inline void writeBytes(const std::string& path, const std::vector<uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), std::streamsize(bytes.size()));
}
inline size_t append(std::vector<uint8_t>* bin, const void* data, size_t bytes) {
  while (bin->size() % 4) bin->push_back(0);
  size_t offset = bin->size();
  bin->insert(bin->end(), static_cast<const uint8_t*>(data),
              static_cast<const uint8_t*>(data) + bytes);
  return offset;
}

// The shipped Cornell box: its JSON and its one .bin (float attributes, tightly packed).
struct Shipped {
  nlohmann::json doc;
  std::vector<uint8_t> bin;
  Shipped() {
    std::string path = scenesDir() + "/cornell_box.gltf";
    doc = nlohmann::json::parse(readTextFile(path));
    bin = readBytes(scenesDir() + "/" + doc["buffers"][0]["uri"].get<std::string>());
  }
  // Accessor `a` as floats (FLOAT components, no stride), or as uint32 for indices.
  std::vector<float> floats(int a) const {
    const nlohmann::json& acc = doc["accessors"][size_t(a)];
    const nlohmann::json& view = doc["bufferViews"][acc["bufferView"].get<size_t>()];
    EXPECT_EQ(acc["componentType"], kGltfF32);
    EXPECT_FALSE(view.contains("byteStride"));
    size_t n = acc["count"].get<size_t>() * (acc["type"] == "VEC3" ? 3 : 2);
    std::vector<float> out(n);
    std::memcpy(out.data(),
                bin.data() + view.value("byteOffset", size_t(0)) + acc.value("byteOffset", size_t(0)),
                n * 4);
    return out;
  }
  std::vector<uint32_t> indices(int a) const {
    const nlohmann::json& acc = doc["accessors"][size_t(a)];
    const nlohmann::json& view = doc["bufferViews"][acc["bufferView"].get<size_t>()];
    const uint8_t* p = bin.data() + view.value("byteOffset", size_t(0)) +
                       acc.value("byteOffset", size_t(0));
    std::vector<uint32_t> out(acc["count"].get<size_t>());
    for (size_t i = 0; i < out.size(); ++i) {
      if (acc["componentType"] == kGltfU16) {
        uint16_t v;
        std::memcpy(&v, p + 2 * i, 2);
        out[i] = v;
      } else {
        EXPECT_EQ(acc["componentType"], kGltfU32);
        std::memcpy(&out[i], p + 4 * i, 4);
      }
    }
    return out;
  }
};

// The Cornell box with every bufferView meshopt-compressed into buffers[0]; buffers[1] is the
// fallback buffer, without data. `filters`: normals through the OCTAHEDRAL filter (8-bit, a
// 4-byte stride) and positions through EXPONENTIAL (24-bit mantissa); otherwise bit-exact.
inline std::string writeMeshoptCornell(const std::string& dir, bool filters, bool glb) {
  Shipped s;
  nlohmann::json doc = s.doc;
  std::vector<uint8_t> compressed;
  size_t fallbackLength = 0;
  doc["bufferViews"] = nlohmann::json::array();
  doc["accessors"] = nlohmann::json::array();
  auto addCompressed = [&](const std::vector<uint8_t>& data, size_t count, size_t stride,
                           const char* mode, const char* filter) {
    std::vector<uint8_t> enc;
    if (std::string(mode) == "ATTRIBUTES") {
      enc.resize(meshopt_encodeVertexBufferBound(count, stride));
      enc.resize(meshopt_encodeVertexBuffer(enc.data(), enc.size(), data.data(), count, stride));
    } else {
      std::vector<uint32_t> idx(count);
      for (size_t i = 0; i < count; ++i) std::memcpy(&idx[i], data.data() + 4 * i, 4);
      enc.resize(meshopt_encodeIndexBufferBound(count, count));
      enc.resize(meshopt_encodeIndexBuffer(enc.data(), enc.size(), idx.data(), count));
    }
    EXPECT_GT(enc.size(), 0u);
    nlohmann::json ext = {{"buffer", 0},
                {"byteOffset", append(&compressed, enc.data(), enc.size())},
                {"byteLength", enc.size()},
                {"byteStride", stride},
                {"count", count},
                {"mode", mode}};
    if (filter) ext["filter"] = filter;
    nlohmann::json v = {{"buffer", 1},
              {"byteOffset", fallbackLength},
              {"byteLength", count * stride},
              {"extensions", {{"EXT_meshopt_compression", ext}}}};
    if (std::string(mode) == "ATTRIBUTES") v["byteStride"] = stride;
    fallbackLength += (count * stride + 3) / 4 * 4;
    doc["bufferViews"].push_back(v);
    return doc["bufferViews"].size() - 1;
  };
  auto accessor = [&](size_t view, int type, size_t count, const char* t, bool normalized) {
    nlohmann::json a = {{"bufferView", view}, {"componentType", type}, {"count", count}, {"type", t}};
    if (normalized) a["normalized"] = true;
    doc["accessors"].push_back(a);
    return int(doc["accessors"].size() - 1);
  };
  auto bytesOf = [](const auto& v) {
    std::vector<uint8_t> b(v.size() * sizeof(v[0]));
    std::memcpy(b.data(), v.data(), b.size());
    return b;
  };
  for (nlohmann::json& mesh : doc["meshes"])
    for (nlohmann::json& p : mesh["primitives"]) {
      nlohmann::json& attrs = p["attributes"];
      std::vector<float> pos = s.floats(attrs["POSITION"]);
      size_t n = pos.size() / 3;
      if (filters) {
        std::vector<uint8_t> enc(n * 12);
        meshopt_encodeFilterExp(enc.data(), n, 12, 24, pos.data());
        attrs["POSITION"] =
            accessor(addCompressed(enc, n, 12, "ATTRIBUTES", "EXPONENTIAL"), kGltfF32, n, "VEC3", false);
        std::vector<float> nrm = s.floats(attrs["NORMAL"]), n4(4 * n, 1.0f);
        for (size_t v = 0; v < n; ++v)
          for (int c = 0; c < 3; ++c) n4[4 * v + size_t(c)] = nrm[3 * v + size_t(c)];
        std::vector<uint8_t> encN(n * 4);
        meshopt_encodeFilterOct(encN.data(), n, 4, 8, n4.data());
        attrs["NORMAL"] =
            accessor(addCompressed(encN, n, 4, "ATTRIBUTES", "OCTAHEDRAL"), kGltfI8, n, "VEC3", true);
      } else {
        attrs["POSITION"] =
            accessor(addCompressed(bytesOf(pos), n, 12, "ATTRIBUTES", nullptr), kGltfF32, n, "VEC3", false);
        attrs["NORMAL"] = accessor(addCompressed(bytesOf(s.floats(attrs["NORMAL"])), n, 12,
                                                 "ATTRIBUTES", nullptr),
                                   kGltfF32, n, "VEC3", false);
      }
      for (const char* set : {"TEXCOORD_0", "TEXCOORD_1"})
        if (attrs.contains(set))
          attrs[set] = accessor(
              addCompressed(bytesOf(s.floats(attrs[set])), n, 8, "ATTRIBUTES", nullptr), kGltfF32, n,
              "VEC2", false);
      std::vector<uint32_t> idx = s.indices(p["indices"]);
      p["indices"] = accessor(addCompressed(bytesOf(idx), idx.size(), 4, "TRIANGLES", nullptr),
                              kGltfU32, idx.size(), "SCALAR", false);
    }
  doc["extensionsUsed"].push_back("EXT_meshopt_compression");
  doc["extensionsRequired"] = {"EXT_meshopt_compression"};
  nlohmann::json fallback = {{"byteLength", fallbackLength},
                   {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}};
  std::string name = filters ? "meshopt_filtered" : "meshopt";
  if (!glb) {
    doc["buffers"] = {{{"uri", name + ".bin"}, {"byteLength", compressed.size()}}, fallback};
    writeBytes(dir + "/" + name + ".bin", compressed);
    writeTextFile(dir + "/" + name + ".gltf", doc.dump(1));
    return dir + "/" + name + ".gltf";
  }
  while (compressed.size() % 4) compressed.push_back(0);
  doc["buffers"] = {{{"byteLength", compressed.size()}}, fallback};
  std::string json = doc.dump();
  while (json.size() % 4) json += ' ';
  std::vector<uint8_t> out;
  auto u32 = [&](uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(uint8_t(v >> (8 * i)));
  };
  out.insert(out.end(), {'g', 'l', 'T', 'F'});
  u32(2);
  u32(uint32_t(28 + json.size() + compressed.size()));
  u32(uint32_t(json.size()));
  u32(0x4E4F534A);
  out.insert(out.end(), json.begin(), json.end());
  u32(uint32_t(compressed.size()));
  u32(0x004E4942);
  out.insert(out.end(), compressed.begin(), compressed.end());
  writeBytes(dir + "/" + name + ".glb", out);
  return dir + "/" + name + ".glb";
}

}  // namespace kiln::test
