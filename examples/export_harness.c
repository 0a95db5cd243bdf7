/* The closed loop from mrpctl's exported C code alone (design/export.md): at sample k,
 * m_k = rule(x_k, m_{k-d}), u_k = K m_{k-d}, x_{k+1} = step(m_k, u_k); m_{-d..-1} = x0.
 * Build: gcc -O2 -I EXPORT export_harness.c EXPORT/mrpctl_model.c -lm -o harness
 * Run:   ./harness d memory0 x0[0..5]  (d >= 1, memory0: manifest.json) -> m_1000, %.17g */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "mrpctl_model.h"
#define N 1000 /* samples: 1 s at 1 kHz */
typedef int (*fn)(const casadi_real**, casadi_real**, casadi_int*, casadi_real*, int);
/* Work arrays large enough for any of the three Functions (sizes from the header). */
static const casadi_real* arg[mrpctl_rule_SZ_ARG + mrpctl_controller_SZ_ARG + mrpctl_step_SZ_ARG];
static casadi_real* res[mrpctl_rule_SZ_RES + mrpctl_controller_SZ_RES + mrpctl_step_SZ_RES];
static casadi_int iw[1 + mrpctl_rule_SZ_IW + mrpctl_controller_SZ_IW + mrpctl_step_SZ_IW];
static casadi_real w[mrpctl_rule_SZ_W + mrpctl_controller_SZ_W + mrpctl_step_SZ_W];
static void call(fn f, const casadi_real* a0, const casadi_real* a1, const casadi_real* a2,
                 casadi_real* r0, casadi_real* r1, casadi_real* r2) {
  arg[0] = a0; arg[1] = a1; arg[2] = a2; res[0] = r0; res[1] = r1; res[2] = r2;
  if (f(arg, res, iw, w, 0)) { fprintf(stderr, "evaluation failed\n"); exit(1); }
}
int main(int argc, char** argv) {
  int d = argc == 9 ? atoi(argv[1]) : 0;
  if (d < 1) { fprintf(stderr, "usage: %s d memory0 x0[0..5] (d >= 1)\n", argv[0]); return 2; }
  casadi_real x[6], m[6], u[3], memory = strtod(argv[2], NULL), memory_next, switched;
  casadi_real (*buffer)[6] = malloc(sizeof(casadi_real[6]) * d); /* ring of m_{k-d..k-1} */
  for (int i = 0; i < 6; i++) x[i] = strtod(argv[3 + i], NULL);
  for (int j = 0; j < d; j++) memcpy(buffer[j], x, sizeof x);  /* constant history */
  for (int k = 0;; k++) {
    casadi_real* delayed = buffer[k % d];                                 /* m_{k-d} */
    call(mrpctl_rule, x, delayed, &memory, m, &memory_next, &switched); /* m_k */
    if (k == N) break;
    call(mrpctl_controller, delayed, NULL, NULL, u, NULL, NULL);        /* u_k */
    memcpy(delayed, m, sizeof m); memory = memory_next;                   /* record m_k */
    call(mrpctl_step, m, u, NULL, x, NULL, NULL);                         /* x_{k+1} */
  }
  for (int i = 0; i < 6; i++) printf("%.17g\n", m[i]);
  free(buffer); return 0;
}
