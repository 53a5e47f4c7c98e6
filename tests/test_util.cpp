#include "tests/test_util.h"

#include <array>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include <sys/wait.h>
#include <unistd.h>

namespace kiln::test {

uint32_t addMaterial(Scene& scene, const Material& material) {
  scene.materials.push_back(material);
  return uint32_t(scene.materials.size() - 1);
}

Material lambert(vec3 albedo, vec3 emission, bool doubleSided) {
  Material m;
  m.name = "lambert";
  m.baseColorFactor = vec4(albedo, 1.0f);
  m.metallic = 0.0f;
  m.roughness = 1.0f;
  m.emissiveFactor = emission;
  m.doubleSided = doubleSided;
  return m;
}

static void appendQuad(Object& o, vec3 p0, vec3 p1, vec3 p2, vec3 p3, uint32_t material) {
  uint32_t base = uint32_t(o.positions.size());
  vec3 n = glm::normalize(glm::cross(p1 - p0, p2 - p0));
  const vec3 p[4] = {p0, p1, p2, p3};
  const vec2 uv[4] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int i = 0; i < 4; ++i) {
    o.positions.push_back(p[i]);
    o.normals.push_back(n);
    o.uv0.push_back(uv[i]);
    o.uv1.push_back(uv[i]);
  }
  o.triangles.push_back(uvec3(base, base + 1, base + 2));
  o.triangles.push_back(uvec3(base, base + 2, base + 3));
  o.triangleMaterial.push_back(material);
  o.triangleMaterial.push_back(material);
}

uint32_t addQuad(Scene& scene, const std::string& name, vec3 p0, vec3 p1, vec3 p2, vec3 p3,
                 uint32_t material) {
  Object o;
  o.name = name;
  o.nodeIndex = int(scene.objects.size());
  appendQuad(o, p0, p1, p2, p3, material);
  scene.objects.push_back(std::move(o));
  scene.updateBounds();
  return uint32_t(scene.objects.size() - 1);
}

uint32_t addBox(Scene& scene, const std::string& name, vec3 lo, vec3 hi, uint32_t material,
                bool inward) {
  Object o;
  o.name = name;
  o.nodeIndex = int(scene.objects.size());
  // The 8 corners; each face listed counter-clockwise seen from outside.
  auto c = [&](int i) { return vec3(i & 1 ? hi.x : lo.x, i & 2 ? hi.y : lo.y, i & 4 ? hi.z : lo.z); };
  const int faces[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& f : faces) {
    if (inward)
      appendQuad(o, c(f[3]), c(f[2]), c(f[1]), c(f[0]), material);
    else
      appendQuad(o, c(f[0]), c(f[1]), c(f[2]), c(f[3]), material);
  }
  scene.objects.push_back(std::move(o));
  scene.updateBounds();
  return uint32_t(scene.objects.size() - 1);
}

Light directionalLight(vec3 direction, float lux, vec3 color) {
  Light l;
  l.name = "sun";
  l.type = LightType::Directional;
  l.direction = glm::normalize(direction);
  l.intensity = lux;
  l.color = color;
  return l;
}

Light pointLight(vec3 position, float candela, vec3 color) {
  Light l;
  l.name = "point";
  l.type = LightType::Point;
  l.position = position;
  l.intensity = candela;
  l.color = color;
  return l;
}

std::string makeTempDir(const std::string& prefix) {
  static std::atomic<int> counter{0};
  auto dir = std::filesystem::temp_directory_path() /
             (prefix + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

void writeTextFile(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  if (!f) throw std::runtime_error("cannot write " + path);
  f << text;
}

std::string readTextFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

int runCommand(const std::string& command, std::string* output) {
  std::string cmd = command + " 2>&1";
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) return -1;
  std::array<char, 4096> buffer;
  std::string out;
  size_t n;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) out.append(buffer.data(), n);
  int status = ::pclose(pipe);
  if (output) *output = out;
  if (status == -1) return -1;
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

bool sharedAvailable() { return std::filesystem::exists(sharedDir() + "/scenes"); }

}  // namespace kiln::test
