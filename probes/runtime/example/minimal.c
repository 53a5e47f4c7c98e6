/* minimal.c: the smallest complete use of kiln's probe runtime, in C99.
 *
 * Usage: kiln_runtime_minimal probes.kprobe [x y z]
 * Loads a probe file, finds the probes around a point, blends their SH and prints the
 * irradiance for an upward-facing surface (visibility-weighted when the file has visibility,
 * and then also with the plain blend for comparison). Every step is commented; error handling is
 * the same for every call: a status code, and kiln_last_error() for the message.
 */
#include <stdio.h>
#include <stdlib.h>

#include "kiln_runtime.h"

int main(int argc, char** argv) {
  if (argc != 2 && argc != 5) {
    fprintf(stderr, "usage: %s probes.kprobe [x y z]\n", argv[0]);
    return 2;
  }

  /* 1. Load the file. It is validated (sizes, indices, NaNs, checksum); a bad file gives
   *    KILN_ERROR_INVALID_FILE and a message naming the file and the field at fault. */
  kiln_probes* probes = NULL;
  if (kiln_probes_load(argv[1], &probes) != KILN_OK) {
    fprintf(stderr, "%s\n", kiln_last_error());
    return 1;
  }
  printf("%u probes, %u cells, %s\n", kiln_probes_count(probes), kiln_probes_cell_count(probes),
         kiln_probes_has_visibility(probes) ? "with visibility (leak-free blending)"
                                            : "no visibility (plain blending)");

  /* 2. The point to light, in glTF world space (metres). */
  float position[3] = {0.0f, 1.0f, 0.0f};
  if (argc == 5) {
    position[0] = (float)atof(argv[2]);
    position[1] = (float)atof(argv[3]);
    position[2] = (float)atof(argv[4]);
  }

  /* 3. Choose how the probes are blended. The defaults weight each probe by whether it can
   *    see the point (when the file has visibility), so light does not leak through walls.
   *    For a point on a surface, pass its normal: the test then starts a little off the
   *    surface (normal_bias), and the wall the point lies on does not hide it. Setting
   *    visibility = 0 gives the plain barycentric blend. */
  const float up[3] = {0.0f, 1.0f, 0.0f};
  kiln_probe_blend blend;
  kiln_probe_blend_defaults(&blend);
  blend.normal[0] = up[0];
  blend.normal[1] = up[1];
  blend.normal[2] = up[2];

  /* 4. Find the cell around it. A game keeps `cell` per object and passes it back as the
   *    hint next frame, so the walk is only a step or two; -1 means "no hint". Points outside
   *    the probes' hull still get a cell (extrapolation), so this cannot fail on valid input
   *    (kiln_probes_locate does the same with the default blend and no normal). */
  int32_t hint = -1;
  kiln_probe_location location;
  if (kiln_probes_locate_blend(probes, position, hint, &blend, &location) != KILN_OK) {
    fprintf(stderr, "%s\n", kiln_last_error());
    kiln_probes_release(probes);
    return 1;
  }
  hint = location.cell;
  printf("cell %d: probes %d %d %d %d\n", location.cell, location.probes[0], location.probes[1],
         location.probes[2], location.probes[3]);
  printf("  weights      %.4f %.4f %.4f %.4f\n", location.weights[0], location.weights[1],
         location.weights[2], location.weights[3]);
  /* The cell's own weights, before visibility (equal to `weights` without visibility). */
  printf("  barycentric  %.4f %.4f %.4f %.4f\n", location.barycentric[0], location.barycentric[1],
         location.barycentric[2], location.barycentric[3]);

  /* 5. Blend the probes' radiance SH with those weights: 27 floats, sh[3 * i + channel]. */
  float sh[27];
  kiln_probes_sample_sh(probes, &location, sh);

  /* 6. Irradiance E on a surface facing +Y (up in glTF). A shader would use albedo * E / pi. */
  float irradiance[3];
  kiln_probes_irradiance(sh, up, irradiance);
  printf("irradiance (up): %g %g %g\n", irradiance[0], irradiance[1], irradiance[2]);

  /* 7. For comparison, the plain barycentric blend (what a file without visibility gives):
   *    behind a wall it mixes in probes on the wall's other side. `hint` (the cell just
   *    found) makes this walk zero steps. */
  if (kiln_probes_has_visibility(probes)) {
    blend.visibility = 0;
    kiln_probes_locate_blend(probes, position, hint, &blend, &location);
    kiln_probes_sample_sh(probes, &location, sh);
    kiln_probes_irradiance(sh, up, irradiance);
    printf("irradiance (up), plain blend: %g %g %g\n", irradiance[0], irradiance[1], irradiance[2]);
  }

  /* 8. Release the handle (reference counted; the last release frees the data). */
  kiln_probes_release(probes);
  return 0;
}
