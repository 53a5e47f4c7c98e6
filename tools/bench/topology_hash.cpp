// topology_hash.cpp: kiln_topology_hash, hashes of buildProbeTopology's output on fixed point
// sets with both Delaunay backends, for showing that a change to the build path leaves its
// output byte for byte the same (run before and after, diff the lines).
//
// Per set and backend one line: the FNV-1a 64 hash of the serialized ProbeSet (cells, links,
// outer cells, seed grid, positions, ...), of the walk records (derived, not in the file), of
// the warnings, and the cell count; or the error message. The sets: random 1k / 10k / 100k /
// 5k, a cospherical grid, a jittered grid, points on a sphere, huge coordinates, a thin slab,
// corners whose exponents differ by 40, duplicates and near-duplicates, clusters, and five
// points.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "kiln/probe_set.h"
#include "probes/tetrahedralize.h"

namespace {

using kiln::DelaunayBackend;

std::vector<glm::vec3> randomPoints(size_t n, uint32_t seed, float lo, float hi) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(lo, hi);
  std::vector<glm::vec3> p(n);
  for (auto& v : p) v = glm::vec3(u(rng), u(rng), u(rng));
  return p;
}

std::vector<glm::vec3> grid(int n, float jitter, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-jitter, jitter);
  std::vector<glm::vec3> p;
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x) {
        glm::vec3 q = glm::vec3(float(x), float(y), float(z));
        if (jitter > 0.0f) q += glm::vec3(u(rng), u(rng), u(rng));
        p.push_back(q);
      }
    }
  }
  return p;
}

struct Set {
  std::string name;
  std::vector<glm::vec3> points;
};

std::vector<Set> sets() {
  std::vector<Set> s;
  s.push_back({"random_1k", randomPoints(1000, 1, 0.0f, 10.0f)});
  s.push_back({"random_10k", randomPoints(10000, 1, 0.0f, 10.0f)});
  s.push_back({"random_100k", randomPoints(100000, 1, 0.0f, 10.0f)});
  s.push_back({"random_5k_seed2", randomPoints(5000, 2, -3.0f, 7.0f)});
  s.push_back({"grid_12", grid(12, 0.0f, 0)});
  s.push_back({"grid_12_jitter", grid(12, 0.01f, 3)});
  {
    std::mt19937 rng(4);
    std::normal_distribution<float> g(0.0f, 1.0f);
    std::vector<glm::vec3> p;
    for (int i = 0; i < 2000; ++i) {
      glm::vec3 v(g(rng), g(rng), g(rng));
      p.push_back(5.0f * glm::normalize(v));
    }
    p.push_back(glm::vec3(0.0f));
    s.push_back({"sphere_2k", p});
  }
  {
    std::vector<glm::vec3> p = randomPoints(3000, 5, 0.0f, 100.0f);
    for (auto& v : p) v += glm::vec3(1.0e6f, -2.0e6f, 5.0e5f);
    s.push_back({"huge_3k", p});
  }
  {
    std::vector<glm::vec3> p = randomPoints(4000, 6, 0.0f, 10.0f);
    for (auto& v : p) v.z *= 1e-3f;
    s.push_back({"slab_4k", p});
  }
  {
    std::vector<glm::vec3> p;
    for (int i = 0; i < 8; ++i) {
      const float a = (i & 1) ? 0x1p20f : 0x1p-20f, b = (i & 2) ? 0x1p20f : 0x1p-20f,
                  c = (i & 4) ? 0x1p20f : 0x1p-20f;
      p.push_back(glm::vec3(a, b, c));
    }
    std::vector<glm::vec3> q = randomPoints(200, 7, 0.0f, 0x1p20f);
    p.insert(p.end(), q.begin(), q.end());
    s.push_back({"exponents_40", p});
  }
  {
    std::vector<glm::vec3> p = randomPoints(3000, 8, 0.0f, 10.0f);
    const size_t n = p.size();
    for (size_t i = 0; i < n; i += 7) p.push_back(p[i]);
    for (size_t i = 3; i < n; i += 11) p.push_back(p[i] + glm::vec3(1e-7f, 0.0f, 0.0f));
    s.push_back({"duplicates_3k", p});
  }
  {
    std::mt19937 rng(9);
    std::normal_distribution<float> g(0.0f, 0.05f);
    std::vector<glm::vec3> centres = randomPoints(20, 10, 0.0f, 10.0f);
    std::vector<glm::vec3> p;
    for (int i = 0; i < 6000; ++i) p.push_back(centres[size_t(i) % 20] + glm::vec3(g(rng), g(rng), g(rng)));
    s.push_back({"clusters_6k", p});
  }
  s.push_back({"five", {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {1, 1, 1}}});
  return s;
}

uint64_t hashBytes(const void* data, size_t size) {
  return kiln::fnv1a64(std::span<const uint8_t>(static_cast<const uint8_t*>(data), size));
}

}  // namespace

int main() {
  for (const Set& set : sets()) {
    for (DelaunayBackend backend : {DelaunayBackend::TetGen, DelaunayBackend::Cgal}) {
      kiln::ProbeTopologySettings settings;
      settings.backend = backend;
      std::vector<std::string> warnings;
      kiln::Result<kiln::ProbeSet> r = kiln::buildProbeTopology(set.points, settings, &warnings);
      const char* b = backend == DelaunayBackend::TetGen ? "tetgen" : "cgal";
      if (!r) {
        std::printf("%-16s %-6s error: %s\n", set.name.c_str(), b, r.error().c_str());
        continue;
      }
      // Version 3 (the format before the sun layer, which a topology never has), so that the
      // hashes stay comparable with those recorded before version 4 (docs/probes.md).
      const std::vector<uint8_t> bytes = kiln::serializeProbeSet(*r, 3);
      std::string w;
      for (const std::string& s : warnings) w += s + "\n";
      std::printf("%-16s %-6s cells %7d file %016llx walk %016llx warnings %016llx\n",
                  set.name.c_str(), b, r->cellCount(),
                  (unsigned long long)hashBytes(bytes.data(), bytes.size()),
                  (unsigned long long)hashBytes(r->walk.data(),
                                                r->walk.size() * sizeof(kiln::ProbeWalkCell)),
                  (unsigned long long)hashBytes(w.data(), w.size()));
    }
  }
  return 0;
}
