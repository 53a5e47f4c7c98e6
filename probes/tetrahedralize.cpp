// tetrahedralize.cpp: probe topology: duplicate merging, dimension detection, Delaunay via a
// backend, canonical ordering, neighbours, and Cupisz's outer cells (GDC 2012) on the hull
// with hull vertex normals (area-weighted averages of the adjacent hull face normals).
#include "probes/tetrahedralize.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>

#include "kiln/predicates.h"
#include "kiln/probe_runtime.h"
#include "probes/delaunay_backends.h"
#include "probes/huge_pages.h"
#include "probes/runtime/src/prefetch.h"
#include "probes/runtime/src/seed_grid.h"

namespace kiln {
namespace {

using runtime_detail::prefetch;
using detail::reserveOnHugePages;
using glm::dvec2;
using glm::dvec3;

struct Context {
  std::span<const glm::vec3> positions;
  std::vector<std::string>* warnings;
  void warn(std::string w) const {
    if (warnings) warnings->push_back(std::move(w));
  }
};

std::string fmt(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", v);
  return buf;
}

// Merges near-duplicates: returns, per input probe, its representative (the earliest probe
// within `tol` that is its own representative, or itself). A hash grid of cell size 2 tol
// holds the representatives: the ball of radius tol around a point then meets at most two
// cells per axis, its own and the one on the nearer side, so 8 cells are searched (open
// addressing, one chain per cell through `next`; no allocation per cell).
struct MergeStats {
  int exact = 0, near = 0;
  int32_t exactExample = -1, nearExample = -1;
};

std::vector<int32_t> mergeDuplicates(const Context& ctx, dvec3 lo, double tol, MergeStats& st) {
  const auto& P = ctx.positions;
  std::vector<int32_t> rep(P.size());
  if (!(tol > 0.0)) {  // zero extent: everything coincides
    for (size_t i = 0; i < P.size(); ++i) rep[i] = 0;
    st.exact = int(P.size()) - 1;
    if (P.size() > 1) st.exactExample = 1;
    return rep;
  }
  const double cell = 2.0 * tol;
  // Cells far apart may share a key (21 bits per axis); the distance test sorts them out.
  auto key = [](int64_t x, int64_t y, int64_t z) {
    return ((uint64_t(x + 1) & 0x1fffff) << 42) | ((uint64_t(y + 1) & 0x1fffff) << 21) |
           (uint64_t(z + 1) & 0x1fffff);
  };
  size_t capacity = 16;
  while (capacity < 2 * P.size()) capacity *= 2;
  constexpr uint64_t kEmpty = ~uint64_t(0);
  std::vector<uint64_t> keys(capacity, kEmpty);
  std::vector<int32_t> head(capacity, -1), next(P.size(), -1);
  // One bit per slot, set when the slot holds a key: almost every cell searched is empty (the
  // cells are far smaller than the probe spacing), and a clear bit at the home slot settles
  // that in a bitmap that stays in cache, where the keys (16 bytes a probe) would not.
  std::vector<uint64_t> occupied(capacity / 64 + 1, 0);
  auto slot = [&](uint64_t k) {
    uint64_t h = k * 0x9e3779b97f4a7c15ull;  // Fibonacci hashing, then linear probing
    size_t i = size_t(h >> 32) & (capacity - 1);
    if (!(occupied[i >> 6] >> (i & 63) & 1)) return i;
    while (keys[i] != kEmpty && keys[i] != k) i = (i + 1) & (capacity - 1);
    return i;
  };
  // The table is a quarter to half full, so `occupied` alone sends that share of the searches
  // (8 a probe) on to the keys, a cache miss each: a second bitmap of 64 bits a probe (a bit
  // set per cell that holds a representative, at the top bits of the same hash) turns away
  // all but at most 1 in 64 of the searches for empty cells, from 1 MB at 100k probes.
  int filterBits = 6;
  while ((size_t(1) << filterBits) < 64 * P.size()) ++filterBits;
  std::vector<uint64_t> filter((size_t(1) << filterBits) / 64, 0);
  auto filterBit = [&](uint64_t k) { return size_t((k * 0x9e3779b97f4a7c15ull) >> (64 - filterBits)); };
  for (size_t i = 0; i < P.size(); ++i) {
    const dvec3 p(P[i]);
    const dvec3 f = (p - lo) / cell;
    const dvec3 g = glm::floor(f);
    const int64_t gx = int64_t(g.x), gy = int64_t(g.y), gz = int64_t(g.z);
    const int sx = f.x - g.x < 0.5 ? -1 : 1, sy = f.y - g.y < 0.5 ? -1 : 1,
              sz = f.z - g.z < 0.5 ? -1 : 1;
    int32_t found = -1;
    for (int c = 0; c < 8; ++c) {
      const uint64_t k = key(gx + (c & 1 ? sx : 0), gy + (c & 2 ? sy : 0), gz + (c & 4 ? sz : 0));
      const size_t b = filterBit(k);
      if (!(filter[b >> 6] >> (b & 63) & 1)) continue;  // no representative in that cell
      const size_t at = slot(k);
      if (keys[at] != k) continue;
      for (int32_t j = head[at]; j >= 0; j = next[size_t(j)]) {
        if ((found < 0 || j < found) && glm::length(dvec3(P[j]) - p) <= tol) found = j;
      }
    }
    if (found >= 0) {
      rep[i] = found;
      if (P[found] == P[i]) {
        if (st.exact++ == 0) st.exactExample = int32_t(i);
      } else {
        if (st.near++ == 0) st.nearExample = int32_t(i);
      }
    } else {
      rep[i] = int32_t(i);
      const uint64_t k = key(gx, gy, gz);
      const size_t at = slot(k);
      keys[at] = k;
      occupied[at >> 6] |= uint64_t(1) << (at & 63);
      const size_t b = filterBit(k);
      filter[b >> 6] |= uint64_t(1) << (b & 63);
      next[i] = head[at];
      head[at] = int32_t(i);
    }
  }
  return rep;
}

// Sorted key of a face / edge / vertex, for matching cells across it: key[0] < key[1] <
// key[2], unused entries -1 (at the end).
struct FaceRef {
  std::array<int32_t, 3> key;
  int32_t cell;
  int32_t slot;
};

// Links cells that share a key; returns the refs seen only once (boundary), in key order.
// Error on a key shared by more than two cells. The refs are bucketed by key[0] (a counting
// sort: keys are probe indices) and each bucket, a few dozen faces around one probe, is
// sorted by the other two indices packed into one integer: no comparison sort over millions
// of array keys (a 100k-probe set has 2.6M tetrahedron faces).
Result<std::vector<FaceRef>> linkFaces(const std::vector<FaceRef>& refs, size_t probeCount,
                                       std::vector<glm::ivec4>& neighbours) {
  struct Packed {
    uint64_t rest;  // key[1] + 1 and key[2] + 1 (so -1 packs as 0)
    uint32_t ref;   // index into refs
  };
  std::vector<uint32_t> start(probeCount + 1, 0);
  for (const FaceRef& f : refs) ++start[size_t(f.key[0]) + 1];
  for (size_t i = 0; i < probeCount; ++i) start[i + 1] += start[i];
  std::vector<Packed> packed(refs.size());
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < refs.size(); ++i) {
      const FaceRef& f = refs[i];
      const uint64_t rest = (uint64_t(uint32_t(f.key[1] + 1)) << 32) | uint32_t(f.key[2] + 1);
      packed[fill[size_t(f.key[0])]++] = {rest, uint32_t(i)};
    }
  }
  std::vector<FaceRef> boundary;
  for (size_t v = 0; v < probeCount; ++v) {
    const auto first = packed.begin() + start[v], last = packed.begin() + start[v + 1];
    std::sort(first, last, [](const Packed& a, const Packed& b) {
      return a.rest != b.rest ? a.rest < b.rest : a.ref < b.ref;
    });
    for (auto i = first; i != last;) {
      auto j = i;
      while (j != last && j->rest == i->rest) ++j;
      if (j - i == 1) {
        boundary.push_back(refs[i->ref]);
      } else if (j - i == 2) {
        const FaceRef& a = refs[i->ref];
        const FaceRef& b = refs[(i + 1)->ref];
        neighbours[a.cell][a.slot] = b.cell;
        neighbours[b.cell][b.slot] = a.cell;
      } else {
        return Error{"tetrahedralization is not a manifold (a face is shared by " +
                     std::to_string(j - i) + " cells)"};
      }
      i = j;
    }
  }
  return boundary;
}

ProbeSet emptySet(const Context& ctx, int dimension) {
  ProbeSet s;
  s.dimension = dimension;
  s.positions.assign(ctx.positions.begin(), ctx.positions.end());
  s.sh.assign(s.positions.size(), ShL2Rgb{});
  s.validity.assign(s.positions.size(), 1.0f);
  return s;
}

// ---- dimension 3 -------------------------------------------------------------------------

// The bits of x (kCurveBits of them) spread to every third bit (Morton order), five at a time
// from a table (the canonical pass spreads three coordinates per tetrahedron).
constexpr int kCurveBits = 10;
constexpr std::array<uint32_t, 32> kSpread5 = [] {
  std::array<uint32_t, 32> t{};
  for (uint32_t x = 0; x < 32; ++x) {
    for (int b = 0; b < 5; ++b) t[x] |= ((x >> b) & 1u) << (3 * b);
  }
  return t;
}();
uint32_t spreadBits(uint32_t x) {
  static_assert(kCurveBits == 10);
  return kSpread5[x & 31] | kSpread5[(x >> 5) & 31] << 15;
}
uint32_t mortonIndex(uint32_t x, uint32_t y, uint32_t z) {
  return (spreadBits(x) << 2) | (spreadBits(y) << 1) | spreadBits(z);
}

// The cells' canonical order: along a space-filling curve (Morton's Z order, kCurveBits per
// axis over the probes' bounds) through their centroids, ties by probe indices. It depends on
// the triangulation alone (so both backends give the same ProbeSet), and cells near in space
// are near in memory, so a walk's steps, the neighbour links and the seed grid's cells stay in
// cache. A cell's key comes from CurveKeys::of in the pass that reads the backend's cells;
// curveOrder returns, for each position of the new order, the index into `tets`.
struct CurveKeys {
  glm::vec3 lo, scale;
  CurveKeys(dvec3 lo_, dvec3 hi_) : lo(lo_) {
    constexpr double kCells = double(1u << kCurveBits);
    scale = glm::vec3(kCells / glm::max(hi_ - lo_, dvec3(1e-30)));
  }
  uint32_t of(glm::vec3 a, glm::vec3 b, glm::vec3 c, glm::vec3 d) const {
    constexpr float kLast = float((1u << kCurveBits) - 1);
    const glm::vec3 f =
        glm::clamp((0.25f * (a + b + c + d) - lo) * scale, glm::vec3(0.0f), glm::vec3(kLast));
    return mortonIndex(uint32_t(f.x), uint32_t(f.y), uint32_t(f.z));
  }
};

// `words` holds key << 32 | index into `tets` per cell; sorted in place. Tetrahedra hold
// backend vertex numbers, probeOf maps them to probe indices.
std::vector<int32_t> curveOrder(std::vector<uint64_t>& words,
                                const std::vector<detail::BackendTet>& tets,
                                const std::vector<int32_t>& probeOf) {
  const size_t n = words.size();
  std::vector<uint64_t> swap;
  reserveOnHugePages(swap, n);
  swap.resize(n);
  // LSD radix sort on the 3 x kCurveBits key bits in three passes (stable): sorting the words
  // sorts by key, ties by the backend's index. 10-bit digits keep each pass's counters and
  // write positions in L1 (15-bit ones in two passes scatter over 32768 places).
  constexpr int kDigit = 10;
  constexpr int kPasses = 3;
  static_assert(kPasses * kDigit >= 3 * kCurveBits);
  std::vector<uint32_t> count((1u << kDigit) + 1);
  for (int pass = 0; pass < kPasses; ++pass) {
    const int shift = 32 + pass * kDigit;
    std::fill(count.begin(), count.end(), 0u);
    for (uint64_t w : words) ++count[((w >> shift) & ((1u << kDigit) - 1)) + 1];
    for (size_t i = 1; i < count.size(); ++i) count[i] += count[i - 1];
    for (uint64_t w : words) swap[count[(w >> shift) & ((1u << kDigit) - 1)]++] = w;
    words.swap(swap);
  }
  std::vector<int32_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = int32_t(uint32_t(words[i]));
  // Equal keys (cells sharing a curve cell) by probe indices, not by the backend's order.
  for (size_t i = 0; i < n;) {
    size_t j = i + 1;
    while (j < n && (words[j] >> 32) == (words[i] >> 32)) ++j;
    if (j - i > 1) {
      std::sort(order.begin() + long(i), order.begin() + long(j),
                [&](int32_t a, int32_t b) {
                  const std::array<int32_t, 4>&u = tets[size_t(a)].v, &v = tets[size_t(b)].v;
                  for (int k = 0; k < 4; ++k) {
                    const int32_t x = probeOf[size_t(u[size_t(k)])];
                    const int32_t y = probeOf[size_t(v[size_t(k)])];
                    if (x != y) return x < y;
                  }
                  return false;
                });
    }
    i = j;
  }
  return order;
}

Result<ProbeSet> build3(const Context& ctx, const std::vector<int32_t>& reps, dvec3 lo,
                        dvec3 hi, const ProbeTopologySettings& settings) {
  const auto& P = ctx.positions;
  if (P.size() >= (size_t(1) << 30)) return Error{"too many probes (2^30 or more)"};
  std::vector<dvec3> pts(reps.size());
  for (size_t i = 0; i < reps.size(); ++i) pts[i] = dvec3(P[reps[i]]);
  Result<detail::Tetrahedralization> raw = settings.backend == DelaunayBackend::TetGen
                                               ? detail::tetgenDelaunay3(pts)
                                               : detail::cgalDelaunay3(pts);
  if (!raw) return Error{raw.error()};
  ProbeSet s = emptySet(ctx, 3);
  // The backend's vertices, in its order: their probes and positions (read per tetrahedron
  // below; in the backend's spatial order they stay in cache, in the caller's they would not).
  const size_t vertexCount = raw->vertices.empty() ? pts.size() : raw->vertices.size();
  std::vector<int32_t> probeOf(vertexCount);
  std::vector<glm::vec3> Q(vertexCount);
  for (size_t j = 0; j < vertexCount; ++j) {
    probeOf[j] = reps[raw->vertices.empty() ? j : size_t(raw->vertices[j])];
    Q[j] = P[size_t(probeOf[j])];
  }
  // Pass 1, in the backend's order and in place: each tetrahedron's vertices sorted by probe
  // index, then the last two swapped if that makes the orientation positive, its backend
  // neighbours following their vertices to the new slots; its curve key; flat ones marked
  // (vertex -1) and left out. The records keep backend vertex numbers.
  std::vector<detail::BackendTet>& tets = raw->tets;
  std::vector<uint64_t> words;
  reserveOnHugePages(words, tets.size());
  const CurveKeys curve(lo, hi);
  int flat = 0;
  size_t hullFaces = 0;
  for (size_t r = 0; r < tets.size(); ++r) {
    detail::BackendTet& t = tets[r];
    // Probe index and slot in one word (indices < 2^30, checked by the caller), sorted by a
    // network of five compare-exchanges (min / max, no branches on the data).
    uint32_t w[4];
    for (int k = 0; k < 4; ++k) w[k] = uint32_t(probeOf[size_t(t.v[size_t(k)])]) << 2 | uint32_t(k);
    auto exchange = [&](int i, int j) {
      const uint32_t a = std::min(w[i], w[j]), b = std::max(w[i], w[j]);
      w[i] = a;
      w[j] = b;
    };
    exchange(0, 1);
    exchange(2, 3);
    exchange(0, 2);
    exchange(1, 3);
    exchange(1, 2);
    int32_t v[4];  // backend vertex numbers, in probe order
    int slot[4];
    for (int k = 0; k < 4; ++k) {
      slot[k] = int(w[k] & 3);
      v[k] = t.v[size_t(slot[k])];
    }
    const glm::vec3 a = Q[size_t(v[0])], b = Q[size_t(v[1])], c = Q[size_t(v[2])],
                    d = Q[size_t(v[3])];
    bool negative;
    if (raw->positive) {
      // The sorted order is the backend's permuted by `slot`: an odd permutation of a
      // positive tetrahedron is negative (as orient3d would say, without its arithmetic).
      const int inversions = int(slot[0] > slot[1]) + int(slot[0] > slot[2]) +
                             int(slot[0] > slot[3]) + int(slot[1] > slot[2]) +
                             int(slot[1] > slot[3]) + int(slot[2] > slot[3]);
      negative = (inversions & 1) != 0;
    } else {
      const double o = orient3d(a, b, c, d);
      if (o == 0.0) {
        ++flat;
        t.v[0] = -1;
        continue;
      }
      negative = o < 0.0;
    }
    if (negative) {  // an odd permutation makes it positive
      std::swap(v[2], v[3]);
      std::swap(slot[2], slot[3]);
    }
    t.v = {v[0], v[1], v[2], v[3]};
    std::array<int32_t, 4>& n = t.n;
    n = {n[size_t(slot[0])], n[size_t(slot[1])], n[size_t(slot[2])], n[size_t(slot[3])]};
    hullFaces += size_t(n[0] < 0) + size_t(n[1] < 0) + size_t(n[2] < 0) + size_t(n[3] < 0);
    words.push_back((uint64_t(curve.of(a, b, c, d)) << 32) | r);
  }
  if (flat > 0) ctx.warn(std::to_string(flat) + " flat tetrahedra from the backend dropped");
  if (words.empty()) return Error{"tetrahedralization produced no tetrahedra"};
  const std::vector<int32_t> order = curveOrder(words, tets, probeOf);
  std::vector<uint64_t>().swap(words);
  const int32_t inner = int32_t(order.size());

  // Pass 2, in the new order: the cells, the backend's neighbours renumbered (when every
  // tetrahedron was kept: dropping a flat one leaves its neighbours pointing at nothing, and
  // then faces are matched instead), the hull faces (no tetrahedron beyond) and the seed
  // grid's candidates (each cell offered as buildProbeSeedGrid would, in the same order); then
  // the walk records over the finished cells, four at a time (makeProbeWalkCells), and the
  // cells' backend vertex numbers replaced by their probes.
  auto faceOf = [](glm::ivec4 cell, int32_t c, int k) {
    std::array<int32_t, 3> f{};
    for (int j = 0, m = 0; j < 4; ++j) {
      if (j != k) f[size_t(m++)] = cell[j];
    }
    std::sort(f.begin(), f.end());
    return FaceRef{f, c, k};
  };
  auto face = [&](int32_t c, int k) { return faceOf(s.cells[size_t(c)], c, k); };
  // Per backend vertex, 1 once a tetrahedron has it; not kept when the backend says every
  // vertex has one (CGAL), which spares pass 2 four scattered stores per tetrahedron.
  const bool markUsed = !raw->everyVertexUsed;
  std::vector<int32_t> used(markUsed ? vertexCount : 0, 0);
  std::vector<FaceRef> hull;
  reserveOnHugePages(s.cells, size_t(inner) + hullFaces);
  reserveOnHugePages(s.neighbours, size_t(inner) + hullFaces);
  if (flat == 0) {
    std::vector<int32_t> newIndex(tets.size());
    for (int32_t i = 0; i < inner; ++i) newIndex[size_t(order[size_t(i)])] = i;
    hull.reserve(hullFaces);
    runtime_detail::SeedGridBuilder grid(s.positions, 3, inner, settings.cellsPerSeed);
    // The seed grid's offers are prepared kOfferAhead cells ahead (their record has arrived
    // by then) and committed in order.
    constexpr int32_t kOfferAhead = 8;
    runtime_detail::SeedGridBuilder::Offer offers[kOfferAhead];
    auto prepareOffer = [&](int32_t c) {
      const detail::BackendTet& t = tets[size_t(order[size_t(c)])];
      offers[c % kOfferAhead] = grid.prepare(
          c, ((Q[size_t(t.v[0])] + Q[size_t(t.v[1])]) + Q[size_t(t.v[2])]) + Q[size_t(t.v[3])]);
    };
    for (int32_t i = 0; i < std::min(kOfferAhead, inner); ++i) prepareOffer(i);
    for (int32_t i = 0; i < inner; ++i) {
      // The backend's records are read in the new order, scattered over 20 MB: fetch the
      // record kAhead cells ahead, and the renumbering entries of its neighbours half as far
      // ahead (by then that record has arrived), so that the misses overlap.
      constexpr int32_t kAhead = 16;
      static_assert(kOfferAhead <= kAhead / 2);
      if (i + kAhead < inner) prefetch(&tets[size_t(order[size_t(i + kAhead)])]);
      if (i + kAhead / 2 < inner) {
        for (int32_t n : tets[size_t(order[size_t(i + kAhead / 2)])].n) {
          if (n >= 0) prefetch(&newIndex[size_t(n)]);
        }
      }
      const runtime_detail::SeedGridBuilder::Offer offer = offers[i % kOfferAhead];
      if (i + kOfferAhead < inner) prepareOffer(i + kOfferAhead);
      const detail::BackendTet& t = tets[size_t(order[size_t(i)])];
      glm::ivec4 links(-1);
      // The backend's vertex numbers for now: the walk records below read positions through
      // them (Q, in the backend's vertex order, which follows its spatial sort: fewer misses
      // than the probes' order); replaced by the probes after.
      s.cells.push_back(glm::ivec4(t.v[0], t.v[1], t.v[2], t.v[3]));
      for (int k = 0; k < 4; ++k) {
        if (markUsed) used[size_t(t.v[size_t(k)])] = 1;
        if (t.n[size_t(k)] >= 0) {
          links[k] = newIndex[size_t(t.n[size_t(k)])];
        } else {
          const glm::ivec4 cell(probeOf[size_t(t.v[0])], probeOf[size_t(t.v[1])],
                                probeOf[size_t(t.v[2])], probeOf[size_t(t.v[3])]);
          hull.push_back(faceOf(cell, i, k));
        }
      }
      s.neighbours.push_back(links);
      grid.commit(offer);
    }
    // The walk records (each a function of its four positions alone, so the same through Q),
    // made in batches that stay in L1 and appended: no zero-fill of the 43 MB array (at 100k
    // probes) before they are written.
    reserveOnHugePages(s.walk, size_t(inner));
    {
      constexpr size_t kBatch = 64;
      ProbeWalkCell batch[kBatch];
      const std::span<const glm::ivec4> local(s.cells);
      for (size_t c = 0; c < size_t(inner); c += kBatch) {
        const size_t m = std::min(kBatch, size_t(inner) - c);
        makeProbeWalkCells(Q, local.subspan(c, m), batch);
        s.walk.insert(s.walk.end(), batch, batch + m);
      }
    }
    for (glm::ivec4& cell : s.cells) {
      cell = glm::ivec4(probeOf[size_t(cell[0])], probeOf[size_t(cell[1])],
                        probeOf[size_t(cell[2])], probeOf[size_t(cell[3])]);
    }
    s.grid = grid.finish();
  } else {
    for (int32_t i = 0; i < inner; ++i) {
      const detail::BackendTet& t = tets[size_t(order[size_t(i)])];
      s.cells.push_back(glm::ivec4(probeOf[size_t(t.v[0])], probeOf[size_t(t.v[1])],
                                   probeOf[size_t(t.v[2])], probeOf[size_t(t.v[3])]));
      for (int k = 0; k < 4; ++k) {
        if (markUsed) used[size_t(t.v[size_t(k)])] = 1;
      }
    }
    s.neighbours.assign(size_t(inner), glm::ivec4(-1));
    std::vector<FaceRef> refs;
    refs.reserve(size_t(inner) * 4);
    for (int32_t c = 0; c < inner; ++c) {
      for (int k = 0; k < 4; ++k) refs.push_back(face(c, k));
    }
    Result<std::vector<FaceRef>> open = linkFaces(refs, P.size(), s.neighbours);
    if (!open) return Error{open.error()};
    hull = std::move(open).value();
  }
  std::vector<detail::BackendTet>().swap(tets);  // the backend's records are no longer needed
  // Every backend vertex is a distinct representative probe, so the unused ones are the
  // representatives minus the vertices some tetrahedron has.
  int unused = int(reps.size());
  if (markUsed) {
    for (int32_t u : used) unused -= u;
  } else {
    unused -= int(vertexCount);
  }
  if (unused > 0) {
    ctx.warn(std::to_string(unused) + " probes are in no tetrahedron (dropped by the backend)");
  }

  // Outer cells: hull triangles wound outwards, smallest index first, sorted.
  struct Outer {
    std::array<int32_t, 3> v;
    int32_t tet, slot;
  };
  std::vector<Outer> outers;
  for (const FaceRef& f : hull) {
    const glm::ivec4 t = s.cells[size_t(f.cell)];
    std::array<int32_t, 3> v = f.key;
    if (orient3d(P[v[0]], P[v[1]], P[v[2]], P[t[f.slot]]) > 0.0) std::swap(v[1], v[2]);
    std::rotate(v.begin(), std::min_element(v.begin(), v.end()), v.end());
    outers.push_back({v, f.cell, f.slot});
  }
  std::sort(outers.begin(), outers.end(),
            [](const Outer& a, const Outer& b) { return a.v < b.v; });

  s.innerCellCount = inner;
  std::vector<FaceRef> edges;
  for (size_t i = 0; i < outers.size(); ++i) {
    const int32_t c = inner + int32_t(i);
    const Outer& o = outers[i];
    s.cells.push_back(glm::ivec4(o.v[0], o.v[1], o.v[2], -1));
    s.neighbours.push_back(glm::ivec4(-1, -1, -1, o.tet));
    s.neighbours[size_t(o.tet)][o.slot] = c;
    for (int k = 0; k < 3; ++k) {
      int32_t a = o.v[(k + 1) % 3], b = o.v[(k + 2) % 3];
      if (a > b) std::swap(a, b);
      edges.push_back({{a, b, -1}, c, k});
    }
  }
  Result<std::vector<FaceRef>> open = linkFaces(edges, P.size(), s.neighbours);
  if (!open) return Error{open.error()};
  if (!open->empty()) return Error{"convex hull is not closed"};

  // Hull vertex normals: the sum of cross products = the area-weighted average of the
  // adjacent hull face normals. Cupisz's sweep needs each vertex normal to point out of every
  // adjacent face; on thin sets (a slab's rim) big faces on both sides can tip the weighted
  // sum inwards, so such vertices take the better of the unweighted average of unit face
  // normals and the direction from the probes' centroid (strictly inside the hull, hence on
  // the inner side of every hull plane: that direction always points out of every face).
  dvec3 centroid(0.0);
  for (int32_t r : reps) centroid += dvec3(P[r]);
  centroid /= double(reps.size());
  std::vector<dvec3> normals(P.size(), dvec3(0.0)), unitSums(P.size(), dvec3(0.0));
  std::vector<dvec3> radial(P.size());
  for (size_t v = 0; v < P.size(); ++v) radial[v] = dvec3(P[v]) - centroid;
  std::vector<dvec3> faceNormals;
  for (const Outer& o : outers) {
    const dvec3 a(P[o.v[0]]), b(P[o.v[1]]), c(P[o.v[2]]);
    const dvec3 n = glm::cross(b - a, c - a);
    faceNormals.push_back(glm::normalize(n));
    for (int k = 0; k < 3; ++k) {
      normals[o.v[k]] += n;
      unitSums[o.v[k]] += faceNormals.back();
    }
  }
  auto minDot = [&](std::vector<double>& out, const std::vector<dvec3>& sums) {
    out.assign(P.size(), 2.0);
    for (size_t i = 0; i < outers.size(); ++i) {
      for (int k = 0; k < 3; ++k) {
        const int32_t v = outers[i].v[k];
        const double len = glm::length(sums[v]);
        const double d = len > 0.0 ? glm::dot(sums[v], faceNormals[i]) / len : -1.0;
        out[v] = std::min(out[v], d);
      }
    }
  };
  std::vector<double> weightedDot, unitDot, radialDot;
  minDot(weightedDot, normals);
  minDot(unitDot, unitSums);
  minDot(radialDot, radial);
  int inward = 0;
  for (size_t v = 0; v < P.size(); ++v) {
    // 0.1: well inside the cone, so the sweep of each face moves outwards.
    if (weightedDot[v] == 2.0 || weightedDot[v] > 0.1) continue;
    double best = weightedDot[v];
    if (unitDot[v] > best) {
      best = unitDot[v];
      normals[v] = unitSums[v];
    }
    if (radialDot[v] > best) {
      best = radialDot[v];
      normals[v] = radial[v];
    }
    if (best <= 0.0) ++inward;
  }
  if (inward > 0) {
    ctx.warn(std::to_string(inward) + " hull vertices have no normal pointing out of all their "
             "faces (very thin probe set); extrapolation near them may be uneven");
  }
  s.outerCells.resize(outers.size());
  for (size_t i = 0; i < outers.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const dvec3 n = normals[outers[i].v[k]];
      const double len = glm::length(n);
      s.outerCells[i].normals[k] = len > 0.0 ? glm::vec3(n / len) : glm::vec3(0.0f);
    }
  }
  computeOuterCellCubics(s);
  return s;
}

// ---- dimension 2 -------------------------------------------------------------------------

Result<ProbeSet> build2(const Context& ctx, const std::vector<int32_t>& reps, dvec3 origin,
                        dvec3 u, dvec3 n) {
  const auto& P = ctx.positions;
  const dvec3 v = glm::cross(n, u);
  std::vector<dvec2> pts(reps.size());
  for (size_t i = 0; i < reps.size(); ++i) {
    const dvec3 d = dvec3(P[reps[i]]) - origin;
    pts[i] = dvec2(glm::dot(d, u), glm::dot(d, v));
  }
  Result<detail::Triangles> raw = detail::cgalDelaunay2(pts);
  if (!raw) return Error{raw.error()};
  std::vector<int32_t> local(P.size(), -1);
  for (size_t i = 0; i < reps.size(); ++i) local[reps[i]] = int32_t(i);

  ProbeSet s = emptySet(ctx, 2);
  std::vector<glm::ivec4> tris;
  for (const auto& t : *raw) {
    glm::ivec4 c(reps[t[0]], reps[t[1]], reps[t[2]], -1);
    std::sort(&c[0], &c[0] + 3);
    const dvec2 a = pts[local[c[0]]], b = pts[local[c[1]]], d = pts[local[c[2]]];
    const double o = (b.x - a.x) * (d.y - a.y) - (b.y - a.y) * (d.x - a.x);
    if (o == 0.0) continue;
    if (o < 0.0) std::swap(c[1], c[2]);  // counter-clockwise about n
    tris.push_back(c);
  }
  if (tris.empty()) return Error{"2D triangulation produced no triangles"};
  std::sort(tris.begin(), tris.end(), [](const glm::ivec4& a, const glm::ivec4& b) {
    return std::lexicographical_compare(&a[0], &a[0] + 3, &b[0], &b[0] + 3);
  });
  const int32_t inner = int32_t(tris.size());
  std::vector<glm::ivec4> nb(tris.size(), glm::ivec4(-1));
  std::vector<FaceRef> refs;
  for (int32_t c = 0; c < inner; ++c) {
    for (int k = 0; k < 3; ++k) {
      int32_t a = tris[c][(k + 1) % 3], b = tris[c][(k + 2) % 3];
      if (a > b) std::swap(a, b);
      refs.push_back({{a, b, -1}, c, k});
    }
  }
  Result<std::vector<FaceRef>> hull = linkFaces(refs, P.size(), nb);
  if (!hull) return Error{hull.error()};
  std::vector<FaceRef> edges = *hull;  // key = sorted hull edge
  std::sort(edges.begin(), edges.end(),
            [](const FaceRef& a, const FaceRef& b) { return a.key < b.key; });
  s.innerCellCount = inner;
  s.cells = tris;
  s.neighbours = nb;
  std::vector<FaceRef> ends;
  for (size_t i = 0; i < edges.size(); ++i) {
    const int32_t c = inner + int32_t(i);
    s.cells.push_back(glm::ivec4(edges[i].key[0], edges[i].key[1], -1, -1));
    s.neighbours.push_back(glm::ivec4(-1, -1, edges[i].cell, -1));
    s.neighbours[edges[i].cell][edges[i].slot] = c;
    // Slot k links across the end opposite vertex k (vertex 1 - k).
    ends.push_back({{edges[i].key[1], -1, -1}, c, 0});
    ends.push_back({{edges[i].key[0], -1, -1}, c, 1});
  }
  Result<std::vector<FaceRef>> open = linkFaces(ends, P.size(), s.neighbours);
  if (!open) return Error{open.error()};
  s.outerCells.resize(edges.size());
  for (size_t i = 0; i < edges.size(); ++i) {
    // Plane normal (for the runtime's projection) and the edge's outward in-plane normal.
    const glm::ivec4 tri = s.cells[edges[i].cell];
    const dvec3 a(P[edges[i].key[0]]), b(P[edges[i].key[1]]), apex(P[tri[edges[i].slot]]);
    dvec3 out = glm::normalize(glm::cross(b - a, n));
    if (glm::dot(out, apex - a) > 0.0) out = -out;
    s.outerCells[i].normals[0] = glm::vec3(n);
    s.outerCells[i].normals[1] = glm::vec3(out);
  }
  return s;
}

// ---- dimensions 1 and 0 ------------------------------------------------------------------

ProbeSet build1(const Context& ctx, std::vector<int32_t> reps, dvec3 origin, dvec3 dir) {
  const auto& P = ctx.positions;
  std::stable_sort(reps.begin(), reps.end(), [&](int32_t a, int32_t b) {
    return glm::dot(dvec3(P[a]) - origin, dir) < glm::dot(dvec3(P[b]) - origin, dir);
  });
  ProbeSet s = emptySet(ctx, 1);
  const int32_t n = int32_t(reps.size()) - 1;
  for (int32_t i = 0; i < n; ++i) {
    s.cells.push_back(glm::ivec4(reps[i], reps[i + 1], -1, -1));
    s.neighbours.push_back(glm::ivec4(i + 1 < n ? i + 1 : -1, i - 1, -1, -1));
  }
  s.innerCellCount = n;
  return s;
}

ProbeSet build0(const Context& ctx, int32_t probe) {
  ProbeSet s = emptySet(ctx, 0);
  s.cells.push_back(glm::ivec4(probe, -1, -1, -1));
  s.neighbours.push_back(glm::ivec4(-1));
  s.innerCellCount = 1;
  return s;
}

}  // namespace

Result<ProbeSet> buildProbeTopology(std::span<const glm::vec3> positions,
                                    const ProbeTopologySettings& settings,
                                    std::vector<std::string>* warnings) {
  const Context ctx{positions, warnings};
  if (positions.empty()) return Error{"buildProbeTopology: positions: no probes"};
  dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  double maxAbs = 0.0;
  for (size_t i = 0; i < positions.size(); ++i) {
    const glm::vec3 p = positions[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      return Error{"buildProbeTopology: positions[" + std::to_string(i) + "]: not finite"};
    }
    lo = glm::min(lo, dvec3(p));
    hi = glm::max(hi, dvec3(p));
    maxAbs = std::max({maxAbs, double(std::fabs(p.x)), double(std::fabs(p.y)),
                       double(std::fabs(p.z))});
  }
  const double diag = glm::length(hi - lo);
  if (positions.size() < 4) {
    ctx.warn("fewer than 4 probes (" + std::to_string(positions.size()) +
             "): no tetrahedron is possible; using a lower-dimensional fallback");
  }
  // Float spacing at the largest coordinate vs the set's extent.
  if (diag > 0.0 && maxAbs * 1.2e-7 > 1e-4 * diag) {
    ctx.warn("large coordinates: probes up to " + fmt(maxAbs) + " from the origin span only " +
             fmt(diag) + "; float precision limits interpolation (move the origin closer)");
  }

  const double tol = settings.mergeTolerance * diag;
  MergeStats merged;
  const std::vector<int32_t> rep = mergeDuplicates(ctx, lo, tol, merged);
  if (merged.exact > 0) {
    const int32_t e = merged.exactExample;
    ctx.warn(std::to_string(merged.exact) + " duplicate probe positions merged (e.g. positions[" +
             std::to_string(e) + "] into positions[" + std::to_string(rep[e]) + "])");
  }
  if (merged.near > 0) {
    const int32_t e = merged.nearExample;
    ctx.warn(std::to_string(merged.near) + " near-duplicate probes (within " + fmt(tol) +
             ") merged (e.g. positions[" + std::to_string(e) + "] into positions[" +
             std::to_string(rep[e]) + "])");
  }
  std::vector<int32_t> reps;
  for (size_t i = 0; i < rep.size(); ++i) {
    if (rep[i] == int32_t(i)) reps.push_back(int32_t(i));
  }

  ProbeSet set;
  if (reps.size() == 1) {
    ctx.warn("a single distinct probe position: every query returns that probe (constant)");
    set = build0(ctx, reps[0]);
  } else {
    // Extreme points: p1 farthest from p0, p2 farthest from their line, p3 from their plane.
    auto P = [&](int32_t i) { return dvec3(positions[i]); };
    const dvec3 p0 = P(reps[0]);
    int32_t i1 = reps[0];
    for (int32_t r : reps) {
      if (glm::length(P(r) - p0) > glm::length(P(i1) - p0)) i1 = r;
    }
    const dvec3 dir = glm::normalize(P(i1) - p0);
    int32_t i2 = reps[0];
    double d2 = 0.0;
    for (int32_t r : reps) {
      const double d = glm::length(glm::cross(P(r) - p0, dir));
      if (d > d2) {
        d2 = d;
        i2 = r;
      }
    }
    const double flat = settings.flatTolerance * diag;
    if (d2 <= flat) {
      ctx.warn("colinear probes: all " + std::to_string(reps.size()) +
               " lie on one line; interpolating along segments, constant across the line");
      set = build1(ctx, reps, p0, dir);
    } else {
      const dvec3 n = glm::normalize(glm::cross(P(i1) - p0, P(i2) - p0));
      double d3 = 0.0;
      for (int32_t r : reps) d3 = std::max(d3, std::fabs(glm::dot(P(r) - p0, n)));
      if (d3 <= flat) {
        ctx.warn("coplanar probes: all " + std::to_string(reps.size()) +
                 " lie in one plane; using a 2D Delaunay triangulation in the plane, constant "
                 "along its normal");
        Result<ProbeSet> r = build2(ctx, reps, p0, dir, n);
        if (!r) return Error{"buildProbeTopology: " + r.error()};
        set = std::move(r).value();
      } else {
        Result<ProbeSet> r = build3(ctx, reps, lo, hi, settings);
        if (!r) return Error{"buildProbeTopology: " + r.error()};
        set = std::move(r).value();
      }
    }
  }
  if (set.outerCells.size() != set.cells.size() - size_t(set.innerCellCount)) {
    set.outerCells.resize(set.cells.size() - size_t(set.innerCellCount));
  }
  // build3 makes the walk records after its pass over the cells (unless it had to match faces).
  if (set.dimension != 3 || set.walk.size() != size_t(set.innerCellCount)) {
    prepareProbeLookup(set);
  }
  // build3 offers its cells to the seed grid in its pass over them (unless it matched faces).
  if (set.grid.seeds.empty()) buildProbeSeedGrid(set, settings.cellsPerSeed);
  Status st = validateProbeSet(set, "buildProbeTopology");
  if (!st) return Error{st.error()};
  return set;
}

}  // namespace kiln
