/* The closed loop from mrpctl's exported C code alone (design/export.md), for every kind of export
 * (plain rule, flight loop, predictor): the exported `sample` Function once per sample, with the
 * caller's delay line of the d past entries (x_meas, or the flown loop's `measurement` / the
 * predictor's `ring`: its last output), constant history x0 (x0; x0 for the predictor), zero noise.
 * Build: gcc -O2 -Wall -Wextra -Werror -c -I EXPORT export_harness.c
 *        gcc -O2 -c EXPORT/mrpctl_model.c && gcc export_harness.o mrpctl_model.o -lm -o harness
 * Run:   ./harness d n x0[0..5] memory0[...]  (memory0: manifest.json) -> x_meas at sample n, %.17g */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "mrpctl_model.h"
static const casadi_real* arg[mrpctl_sample_SZ_ARG + 4]; /* room for every kind's inputs and outputs */
static casadi_real* res[mrpctl_sample_SZ_RES + 6];
static casadi_int iw[1 + mrpctl_sample_SZ_IW];
static casadi_real w[mrpctl_sample_SZ_W], x[6], x_next[6], memory[64], memory_next[64], x_meas[6], u[3], switched,
    noise[6], entry[12];
int main(int argc, char** argv) {
  casadi_int ins = mrpctl_sample_n_in(), outs = mrpctl_sample_n_out();
  int m = (int)mrpctl_sample_sparsity_in(1)[0], r = (int)mrpctl_sample_sparsity_in(2)[0];
  int d = argc > 2 ? atoi(argv[1]) : 0, n = argc > 2 ? atoi(argv[2]) : -1;
  if (argc != 9 + m || d < 1 || n < 0 || ins > 4 || m > 64 || r > 12) {
    fprintf(stderr, "usage: %s d n x0[0..5] memory0[0..%d] (d >= 1; sample takes %d inputs)\n", argv[0], m - 1, (int)ins);
    return 2;
  }
  for (int i = 0; i < 6; i++) x[i] = strtod(argv[3 + i], NULL);
  for (int i = 0; i < m; i++) memory[i] = strtod(argv[9 + i], NULL);
  casadi_real* ring = malloc(sizeof(casadi_real) * (size_t)(r * d)); /* entries k-d..k-1, k % d */
  for (int j = 0; j < d * r; j++) ring[j] = x[j % 6];                 /* constant history */
  for (int k = 0; k <= n; k++) {
    casadi_real* delayed = ring + (k % d) * r;
    arg[0] = x; arg[1] = memory; arg[2] = delayed; arg[3] = noise;
    res[0] = x_next; res[1] = memory_next; res[2] = x_meas; res[3] = u; res[4] = &switched; res[5] = entry;
    if (mrpctl_sample(arg, res, iw, w, 0)) { fprintf(stderr, "evaluation failed\n"); return 1; }
    memcpy(delayed, outs > 5 ? entry : x_meas, sizeof(casadi_real) * (size_t)r);             /* record */
    memcpy(x, x_next, sizeof x); memcpy(memory, memory_next, sizeof(casadi_real) * (size_t)m);
  }
  for (int i = 0; i < 6; i++) printf("%.17g\n", x_meas[i]);
  free(ring); return 0;
}
