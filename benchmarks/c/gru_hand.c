/* A plain hand-written C step of the benchmark's GRU network: the yardstick for the FMU's step time.
 *
 * Same maths as the exported network (nnfmu.models GRU with output feedback, PyTorch gate order r, z, n):
 *   inputs normalised, in = [y_k, u_k];  gi = W_ih in + b_ih;  gh = W_hh h + b_hh
 *   r = sigmoid(gi_r + gh_r);  z = sigmoid(gi_z + gh_z);  n = tanh(gi_n + r * gh_n);  h' = (1 - z) n + z h
 *   y_{k+1} = y_k + SKIP_SCALE * (W_o h' + b_o)   (normalised; de-normalised for the output)
 * Weights come from gru_weights.h (written by benchmarks/step_speed.py), column-major, as static
 * constants like CasADi's. Loops are column-wise axpys (contiguous inner loop), no fast-math.
 *
 * usage: gru_hand N_STEPS  ->  us_per_step=<t> y_final=<y1>,<y2>,...
 * The inputs are the same sinusoids as in fmu_step_driver.c, computed before the timed loop, and
 * y0 = 0 (physical units). One run warms the caches, the least of three timed ones (process CPU
 * time) is printed, as in fmu_step_driver.c.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gru_weights.h" /* NY, NU, H, W_ih, W_hh, b_ih, b_hh, W_o, b_o, u/y mean/std, SKIP_SCALE */

#define NI (NY + NU)

static double cpu_seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* z[0..n) = b + sum_k A[:, k] x[k], A column-major n x m. */
static void affine(int n, int m, const double *restrict A, const double *restrict x, const double *restrict b,
                   double *restrict z) {
  int j, k;
  for (j = 0; j < n; ++j) z[j] = b[j];
  for (k = 0; k < m; ++k) {
    const double *restrict col = A + (size_t)k * n;
    const double xk = x[k];
    for (j = 0; j < n; ++j) z[j] += col[j] * xk;
  }
}

static void gru_step(const double *restrict yn, const double *restrict un, const double *restrict h,
                     double *restrict yn_next, double *restrict h_next) {
  double in[NI], gi[3 * H], gh[3 * H], out[NY];
  int j;
  memcpy(in, yn, NY * sizeof(double));
  memcpy(in + NY, un, NU * sizeof(double));
  affine(3 * H, NI, W_ih, in, b_ih, gi);
  affine(3 * H, H, W_hh, h, b_hh, gh);
  for (j = 0; j < H; ++j) {
    const double r = 1.0 / (1.0 + exp(-(gi[j] + gh[j])));
    const double z = 1.0 / (1.0 + exp(-(gi[H + j] + gh[H + j])));
    const double n = tanh(gi[2 * H + j] + r * gh[2 * H + j]);
    h_next[j] = (1.0 - z) * n + z * h[j];
  }
  affine(NY, H, W_o, h_next, b_o, out);
  for (j = 0; j < NY; ++j) yn_next[j] = yn[j] + SKIP_SCALE * out[j];
}

int main(int argc, char **argv) {
  double yn[NY], yn_next[NY], h[H], h_next[H], un[NU], t0 = 0.0, best = 1e300, *inputs;
  long n_steps, k;
  int i, pass;
  if (argc != 2) {
    fprintf(stderr, "usage: %s N_STEPS\n", argv[0]);
    return 2;
  }
  n_steps = atol(argv[1]);
  inputs = (double *)malloc(sizeof(double) * (size_t)(n_steps * NU));
  if (!inputs) return 2;
  for (k = 0; k < n_steps; ++k)
    for (i = 0; i < NU; ++i) inputs[k * NU + i] = sin(0.01 * (double)k * (i + 1)) * (1.0 + 0.5 * i);
  for (pass = 0; pass < 4; ++pass) { /* pass 0 warms the caches */
    for (i = 0; i < NY; ++i) yn[i] = (0.0 - y_mean[i]) / y_std[i];
    memset(h, 0, sizeof h);
    t0 = cpu_seconds();
    for (k = 0; k < n_steps; ++k) {
      for (i = 0; i < NU; ++i) un[i] = (inputs[k * NU + i] - u_mean[i]) / u_std[i];
      gru_step(yn, un, h, yn_next, h_next);
      memcpy(yn, yn_next, sizeof yn);
      memcpy(h, h_next, sizeof h);
    }
    t0 = cpu_seconds() - t0;
    if (pass && t0 < best) best = t0;
  }
  printf("us_per_step=%.4f y_final=", best / (double)n_steps * 1e6);
  for (i = 0; i < NY; ++i) printf("%s%.17g", i ? "," : "", yn[i] * y_std[i] + y_mean[i]);
  printf("\n");
  free(inputs);
  return 0;
}
