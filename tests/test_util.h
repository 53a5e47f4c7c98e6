// test_util.h: building small scenes in code, temporary files and running the CLI, for tests.
#pragma once

#include <string>

#include "src/scene.h"

namespace kiln::test {

// Adds a material and returns its index.
uint32_t addMaterial(Scene& scene, const Material& material);
// A Lambertian material of albedo `albedo` (metallic 0, roughness 1), optionally emissive.
Material lambert(vec3 albedo, vec3 emission = vec3(0.0f), bool doubleSided = false);

// Adds a quad object p0 p1 p2 p3 (counter-clockwise seen from its front side) as two
// triangles, with UV0 = UV1 = the unit square (p0 -> (0,0), p1 -> (1,0), p2 -> (1,1)).
// Returns the object index.
uint32_t addQuad(Scene& scene, const std::string& name, vec3 p0, vec3 p1, vec3 p2, vec3 p3,
                 uint32_t material);
// Adds an axis-aligned box as six quads in one object, faces pointing inward (a room) or
// outward (a solid block). Returns the object index.
uint32_t addBox(Scene& scene, const std::string& name, vec3 min, vec3 max, uint32_t material,
                bool inward);

Light directionalLight(vec3 direction, float lux, vec3 color = vec3(1.0f));
Light pointLight(vec3 position, float candela, vec3 color = vec3(1.0f));

// A fresh empty directory under the system's temporary directory, unique per call.
std::string makeTempDir(const std::string& prefix = "kiln_test");
void writeTextFile(const std::string& path, const std::string& text);
std::string readTextFile(const std::string& path);

// Runs a shell command, capturing stdout and stderr together in *output. Returns the exit
// code (or -1 when it could not run).
int runCommand(const std::string& command, std::string* output);

// The kiln executable, the project's generated scenes, and ../shared (may be absent).
inline const char* kilnExe() { return KILN_EXE; }
inline std::string scenesDir() { return KILN_SCENES_DIR; }
inline std::string sharedDir() { return KILN_SHARED_DIR; }
bool sharedAvailable();  // ../shared/scenes exists

}  // namespace kiln::test
