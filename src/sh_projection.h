// sh_projection.h: bake-time spherical-harmonics tools on top of sh.h: projection (from an
// equirectangular map, from a function, from weighted samples), conversion to irradiance SH,
// L1 reduction, windowing, deringing (a constrained least-squares fit, or the older window),
// and Unity's 7-vector packing.
//
// Which quantity each function takes and returns (basis and order: sh.h, MISSION.md):
//   - projectEquirect / projectFunction / ShL2Accumulator: RADIANCE SH, c_i = int L Y_i dw.
//   - ShL2Rgb::irradiance(n) (sh.h): irradiance E(n) in W/m^2 (lux in kiln's units), NOT E/pi.
//   - toIrradianceSh: SH of E(n) itself (bands scaled by A_l); its evaluate(n) is E(n).
//   - minIrradiance: per-channel minimum over the sphere of E(n) (not E/pi).
//   - windowSh / windowDeringSh / deringSh: RADIANCE SH in, RADIANCE SH out (see "Windowing"
//     and "Deringing" below).
//   - packUnitySh9 / evalUnitySh9: E(n) / pi, the outgoing radiance of a white Lambertian
//     surface, which is what Unity's ambient / probe SH constants evaluate to (and what a
//     kiln lightmap texel stores).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "src/image.h"
#include "src/math.h"
#include "kiln/sh.h"

namespace kiln {

// ---------------------------------------------------------------------------------------------
// Projection
// ---------------------------------------------------------------------------------------------

// Radiance-SH accumulator in double precision, for long sums (a map's pixels, a probe's rays):
// add(d, L, w) adds L(d) Y_i(d) w, with w the sample's quadrature weight (its solid angle, or
// 4 pi / N for N uniform sphere samples, or 1 / pdf / N for importance-sampled directions).
class ShL2Accumulator {
 public:
  void add(vec3 d, vec3 radiance, double weight);
  // Adds radiance constant over a region whose basis integrals int_region Y_i dw are given.
  void addIntegrals(vec3 radiance, const std::array<double, kShL2Count>& basisIntegrals);
  // Adds another accumulator's sums (parallel reductions).
  void merge(const ShL2Accumulator& other);
  ShL2Rgb result() const;

 private:
  std::array<std::array<double, 3>, kShL2Count> sum_{};
};

// The unit direction at equirectangular texture coordinates (u, v), the inverse of sky.h's
// mapping u = 0.5 + atan2(x, -z) / (2 pi), v = acos(y) / pi (row 0 = +Y, centre = -Z):
//   theta = pi v, phi = 2 pi (u - 0.5): d = (sin(theta) sin(phi), cos(theta),
//   -sin(theta) cos(phi)).
vec3 equirectDirection(float u, float v);

// Exact solid angle of pixel row y of a width x height equirectangular map: the pixel spans
// dphi = 2 pi / width and theta in [pi y / height, pi (y + 1) / height], so
//   dOmega = dphi (cos(theta0) - cos(theta1)),
// and the pixels of the whole map sum to exactly 4 pi.
double equirectPixelSolidAngle(int y, int width, int height);

// Radiance SH of an equirectangular map (times `scale`), sky.h's mapping. The map is taken
// as piecewise constant over its pixels (what Sky::radiance returns) and each pixel's basis
// integrals int_pixel Y_i dw are computed in closed form, so the projection is exact for
// that function: a constant map gives exactly c0 = 2 sqrt(pi) L and 0 elsewhere, up to
// rounding (a pixel-centre rule with exact solid angles, sum L Y_i(centre) dOmega, would be
// off by O(pixel size^2) in band 2).
ShL2Rgb projectEquirect(const Image& map, float scale = 1.0f);

// Radiance SH of a function of direction by `sampleCount` uniform sphere samples
// (Owen-scrambled Sobol points from sampling.h keyed by `seed`, so stratified for a power
// of two count), weight 4 pi / sampleCount each.
ShL2Rgb projectFunction(const std::function<vec3(vec3)>& radiance, uint32_t sampleCount,
                        uint64_t seed = 0);

// ---------------------------------------------------------------------------------------------
// Irradiance and L1
// ---------------------------------------------------------------------------------------------

// Irradiance SH: coefficient i multiplied by A_l(i) (Ramamoorthi & Hanrahan 2001, eq. 8:
// E_lm = A_l L_lm, with A0 = pi, A1 = 2 pi / 3, A2 = pi / 4). The result's evaluate(n) is the
// irradiance E(n) (equal to radiance.irradiance(n)); multiply by kInvPi for E / pi. Feed only
// radiance SH to windowSh / deringSh / packUnitySh9, never this.
ShL2Rgb toIrradianceSh(const ShL2Rgb& radiance);

// ShL1Rgb (sh.h) with bands 0-1 of `sh` (the first 4 coefficients, unchanged).
ShL1Rgb reduceToL1(const ShL2Rgb& sh);

// ---------------------------------------------------------------------------------------------
// Windowing / deringing
// ---------------------------------------------------------------------------------------------
//
// What is windowed: the RADIANCE coefficients, every coefficient of band l multiplied by the
// same factor w_l (w_0 = 1, so the mean radiance and total energy are kept). A per-band
// factor is a convolution with a zonal (rotation-symmetric) kernel, so windowing blurs the
// environment without favouring a direction, and it commutes with the cosine convolution:
// windowing radiance by w_l and then taking irradiance (A_l) is the same as windowing the
// irradiance SH. Why: a truncated SH series of a bright, small source rings (Gibbs), and L2
// irradiance can go negative on the side facing away from it (for a directional light of
// irradiance E0 along s, E(n) = E0 (1/4 + t/2 + 5/32 (3t^2 - 1)), t = n.s, has a minimum
// of -0.0396 E0 at t = -8/15). Tapering the higher bands removes the ringing at the cost of
// some blur (Sloan 2008 "Stupid SH Tricks"; Sloan 2017 "Deringing Spherical Harmonics").
// The bake's deringing (deringSh below) does not window: it moves bands 1-2 only as far as
// E >= 0 needs, which costs far less accuracy (docs/probes.md, "Deringing").

enum class ShWindowKind {
  // Filament cmgen's window: (sin(x) / x)^4, x = pi l / width (the sinc applied 4 times);
  // w_l = 0 for l >= width.
  kSinc4,
  // Lanczos sigma factors: sin(x) / x, x = pi l / width; w_l = 0 for l >= width.
  kLanczos,
  // Hanning: (1 + cos(pi l / width)) / 2; w_l = 0 for l >= width.
  kHanning,
};

// Window factors (w_0, w_1, w_2) for `width` in bands (> 0). Every kind goes to 1 for a
// large width and its factors shrink monotonically as the width decreases; width <= 1 keeps
// only band 0.
std::array<float, 3> shWindowFactors(ShWindowKind kind, float width);

// `sh` with band l multiplied by factors[l].
ShL2Rgb windowSh(const ShL2Rgb& sh, const std::array<float, 3>& factors);
inline ShL2Rgb windowSh(const ShL2Rgb& sh, ShWindowKind kind, float width) {
  return windowSh(sh, shWindowFactors(kind, width));
}

// Per-channel minimum over the unit sphere of the irradiance E(n) of radiance SH `sh`.
// Exact up to rounding: L2 irradiance is a quadratic polynomial n^T A n + b.n + c, and its
// minimum on |n| = 1 is a trust-region subproblem (Moré & Sorensen 1983): in A's eigenbasis
// the minimiser is n = -(A - lambda I)^-1 b / 2 with lambda <= the smallest eigenvalue and
// |n| = 1, a monotone 1D equation in lambda solved by bisection (the "hard case", b
// orthogonal to the smallest eigenvector, is handled). The value returned is attained at a
// point of the sphere, so it never overestimates the minimum by more than rounding. The
// minimising normals are written to *argmin when given.
vec3 minIrradiance(const ShL2Rgb& sh, std::array<vec3, 3>* argmin = nullptr);

// `n` unit vectors spread evenly over the sphere (Fibonacci lattice, golden-angle spiral):
// equal-area, so plain averages over them approximate averages over the sphere, and a dense
// set samples every region. Deterministic.
std::vector<vec3> fibonacciSphere(int n);

struct DeringResult {
  ShL2Rgb sh;            // radiance SH (== input when nothing was needed)
  bool changed = false;  // false: the input's irradiance was already >= 0 everywhere
  vec3 minIrradianceBefore{0.0f};
  vec3 minIrradianceAfter{0.0f};
  bool ok = true;  // false: even band 0 alone is negative (negative mean radiance)
  // deringSh only: the fit's cutting planes stopped short of E >= 0 and bands 1-2 of some
  // channel were scaled toward the mean to finish (see deringSh).
  bool fallback = false;
};

// Deringing by the nearest non-negative irradiance: per channel, the radiance SH whose
// irradiance is >= 0 for every normal and that is nearest to `sh` in irradiance, with c0 (the
// mean radiance, hence the energy) kept exactly. SH whose irradiance is already >= 0
// everywhere are returned bit-for-bit unchanged.
//
// Nearest in irradiance: the L2 distance over the sphere between the fitted and the raw
// irradiance E(n), in the orthonormal basis sum_i (A_l (c_i - raw_i))^2. The raw L2
// projection is the best band-limited approximation of the true irradiance, so by
// Pythagoras this also minimises the L2 distance to the TRUE irradiance among non-negative
// L2 irradiances. (The distance between radiance coefficients, sum_i (c_i - raw_i)^2, moves
// band 2 more since A2 = pi / 4 makes it cheap, and was measurably worse at the Cycles
// reference points: docs/probes.md, "Deringing".)
//
// Why not a window: a window scales a whole band by one factor, so the light on the bright
// side is blurred as much as the ringing on the dark side needs (at a Cornell box point near
// the lamp, normal +x, the window gave 1.9x the exact irradiance, raw L2 1.2x, the fit 1.2x:
// docs/probes.md). The fit moves the 8 coefficients of bands 1-2 freely, only as far as the
// constraint needs.
//
// Method: the irradiance E(n) = sum_i A_l c_i Y_i(n) is linear in the coefficients, so this is
// a least-distance problem with one linear constraint per normal (a semi-infinite quadratic
// program in 8 unknowns). It is solved by cutting planes: constraints at 256 Fibonacci
// normals, solved exactly as a least-distance program through NNLS (Lawson & Hanson 1974,
// "Solving Least Squares Problems", ch. 23); then the exact minimum of the fitted
// irradiance over the sphere (minIrradiance's trust-region solve) is added as a new
// constraint while it is negative. The constraints ask for E >= 1e-4 x the mean irradiance,
// so that float rounding cannot take the result below 0. The result is checked with the
// exact minimum; should the cuts not have converged (not seen in practice), the bands 1-2 are
// scaled toward the mean until E >= 0 (a window of equal factors, always feasible). Pure
// arithmetic on the input: deterministic (bit-identical on any thread), ~0.2 ms per SH that
// needs it (random SH, 3 channels, one core), about as long as windowDeringSh's bisection.
DeringResult deringSh(const ShL2Rgb& sh);

struct WindowDeringResult : DeringResult {
  float width = 0.0f;  // window width used (infinite when not windowed)
  std::array<float, 3> factors{1.0f, 1.0f, 1.0f};
};

// The weakest window of `kind` (largest width, one width for all three channels so the hue
// is kept) that makes the reconstructed irradiance >= 0 over the whole sphere in every
// channel, as Filament's cmgen does after Sloan 2017: the minimum of the irradiance (above)
// is tested while the width is bisected between 1 (band 0 only: irradiance = pi c0 Y00 >= 0)
// and the largest width that is still negative. An SH whose irradiance is already >= 0 is
// returned bit-for-bit unchanged. The search stops when the width is known within
// `relTolerance` (relative). kiln's bake used this before deringSh's fit; it is kept to
// compare against (docs/charts.md, chart 3).
WindowDeringResult windowDeringSh(const ShL2Rgb& sh, ShWindowKind kind = ShWindowKind::kSinc4,
                                  float relTolerance = 1e-4f);

// ---------------------------------------------------------------------------------------------
// Unity SH9 packing
// ---------------------------------------------------------------------------------------------
//
// Unity's built-in ShadeSH9 / URP SampleSH9 evaluates, for a unit normal n and N = (n, 1):
//   res.c  = dot(SHAc, N) + dot(SHBc, n.xyzz * n.yzzx)      for c in r, g, b
//   res   += SHC.rgb * (n.x^2 - n.y^2)
// i.e. a quadratic polynomial per channel with SHA = (x, y, z, constant) coefficients,
// SHB = (xy, yz, z^2, zx) coefficients and SHC = (x^2 - y^2) coefficient. Unity's constants
// evaluate to E(n) / pi (the cosine convolution and the Lambert 1/pi are folded in), so
// packUnitySh9 expands sum_i (A_l / pi) c_i Y_i(n) into that polynomial, folding Y20's
// constant -0.315392 into SHA.w (z^2 gets 3 x 0.315392).
//
// Axes: Unity is left-handed (+Y up, +Z forward); glTF importers (glTFast, UnityGLTF)
// negate X, so a glTF direction (x, y, z) is Unity's (-x, y, z). kGltf packs in kiln's own
// glTF axes (evaluate with a glTF-space normal); kUnity packs for Unity world-space normals
// (the x-odd terms x, xy and zx change sign; everything else is unchanged).
enum class ShAxes { kGltf, kUnity };

struct UnitySh9 {
  vec4 shAr, shAg, shAb;  // (x, y, z, constant) per channel
  vec4 shBr, shBg, shBb;  // (xy, yz, z^2, zx) per channel
  vec4 shC;               // (x^2 - y^2) per channel in rgb; w = 1 as Unity sets it
};

UnitySh9 packUnitySh9(const ShL2Rgb& radiance, ShAxes axes = ShAxes::kGltf);
// Unity's ShadeSH9 / SampleSH9 formula on packed constants, for a unit normal in the axes
// the constants were packed for: returns E(n) / pi (linear colour space).
vec3 evalUnitySh9(const UnitySh9& p, vec3 n);

}  // namespace kiln
