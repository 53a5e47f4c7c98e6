/* minimal.c: the smallest complete use of kiln's probe runtime, in C99.
 *
 * Usage: kiln_runtime_minimal probes.kprobe [x y z]
 * Loads a probe file, finds the probes around a point, blends their SH and prints the
 * irradiance for an upward-facing surface. Every step is commented; error handling is the
 * same for every call: a status code, and kiln_last_error() for the message.
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
  printf("%u probes, %u cells\n", kiln_probes_count(probes), kiln_probes_cell_count(probes));

  /* 2. The point to light, in glTF world space (metres). */
  float position[3] = {0.0f, 1.0f, 0.0f};
  if (argc == 5) {
    position[0] = (float)atof(argv[2]);
    position[1] = (float)atof(argv[3]);
    position[2] = (float)atof(argv[4]);
  }

  /* 3. Find the cell around it. A game keeps `cell` per object and passes it back as the
   *    hint next frame, so the walk is only a step or two; -1 means "no hint". Points outside
   *    the probes' hull still get a cell (extrapolation), so this cannot fail on valid input. */
  int32_t hint = -1;
  kiln_probe_location location;
  kiln_probes_locate(probes, position, hint, &location);
  hint = location.cell;
  printf("cell %d: probes %d %d %d %d, weights %.4f %.4f %.4f %.4f\n", location.cell,
         location.probes[0], location.probes[1], location.probes[2], location.probes[3],
         location.weights[0], location.weights[1], location.weights[2], location.weights[3]);

  /* 4. Blend the probes' radiance SH with those weights: 27 floats, sh[3 * i + channel]. */
  float sh[27];
  kiln_probes_sample_sh(probes, &location, sh);

  /* 5. Irradiance E on a surface facing +Y (up in glTF). A shader would use albedo * E / pi. */
  const float up[3] = {0.0f, 1.0f, 0.0f};
  float irradiance[3];
  kiln_probes_irradiance(sh, up, irradiance);
  printf("irradiance (up): %g %g %g\n", irradiance[0], irradiance[1], irradiance[2]);

  /* 6. Release the handle (reference counted; the last release frees the data). */
  kiln_probes_release(probes);
  return 0;
}
