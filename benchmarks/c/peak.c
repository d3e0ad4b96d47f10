/* The machine's ceilings for benchmarks/step_speed.py, in process CPU time on the calling core.
 *
 * usage: peak fma256 | muladd256 | fma512     ->  gflops=<x>       (or "unsupported" on this CPU)
 *        peak read BYTES                      ->  gbps=<x>
 *
 * fma256     10 independent chains of 256-bit FMA (a = a * m + c): 16 double FLOPs per instruction pair
 *            per cycle and port; the ceiling of an AVX2 + FMA matrix-vector kernel.
 * muladd256  6 independent chains of 256-bit a = a + x * m as a multiply and a separate add (what a
 *            build without FMA executes for the product-adds of a matrix-vector product): the ceiling
 *            of the same kernel compiled with -ffp-contract=off.
 * fma512     as fma256 with 512-bit AVX-512 registers.
 * read       streams a buffer of BYTES bytes (doubles, 8 independent sums) again and again: the bandwidth
 *            from the cache level that holds BYTES, which bounds a matrix-vector product whose weights
 *            take BYTES (each weight is used once per step: 4 bytes per FLOP in double, 2 in float).
 * Only for x86-64 with GCC or Clang; elsewhere every mode prints "unsupported".
 */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static double cpu_seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

#define CHAINS 10
#define ITERS 4000000L

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>

__attribute__((target("avx2,fma"))) static double fma256(void) {
  __m256d a[CHAINS], m = _mm256_set1_pd(0.999999), c = _mm256_set1_pd(1e-6);
  double out[4], t;
  long k;
  int i;
  for (i = 0; i < CHAINS; ++i) a[i] = _mm256_set1_pd(i);
  t = cpu_seconds();
  for (k = 0; k < ITERS; ++k) {
#pragma GCC unroll 10
    for (i = 0; i < CHAINS; ++i) a[i] = _mm256_fmadd_pd(a[i], m, c);
  }
  t = cpu_seconds() - t;
  for (i = 1; i < CHAINS; ++i) a[0] = _mm256_add_pd(a[0], a[i]);
  _mm256_storeu_pd(out, a[0]);
  if (out[0] == 42.0) printf("#");
  return 2.0 * 4 * CHAINS * ITERS / t * 1e-9;
}

__attribute__((target("avx2"))) static double muladd256(void) {
  __m256d a[6], x[6], m = _mm256_set1_pd(1e-6);
  double out[4], t;
  long k;
  int i;
  for (i = 0; i < 6; ++i) {
    a[i] = _mm256_set1_pd(i);
    x[i] = _mm256_set1_pd(1.0 + 0.1 * i);
    __asm__("" : "+x"(x[i])); /* opaque values: no products folded at compile time */
  }
  t = cpu_seconds();
  for (k = 0; k < ITERS; ++k) {
    __asm__("" : "+x"(m)); /* m is "new" every iteration: the products cannot be hoisted */
#pragma GCC unroll 6
    for (i = 0; i < 6; ++i) a[i] = _mm256_add_pd(a[i], _mm256_mul_pd(x[i], m));
  }
  t = cpu_seconds() - t;
  for (i = 1; i < 6; ++i) a[0] = _mm256_add_pd(a[0], a[i]);
  _mm256_storeu_pd(out, a[0]);
  if (out[0] == 42.0) printf("#");
  return 2.0 * 4 * 6 * ITERS / t * 1e-9;
}

__attribute__((target("avx512f"))) static double fma512(void) {
  __m512d a[CHAINS], m = _mm512_set1_pd(0.999999), c = _mm512_set1_pd(1e-6);
  double out[8], t;
  long k;
  int i;
  for (i = 0; i < CHAINS; ++i) a[i] = _mm512_set1_pd(i);
  t = cpu_seconds();
  for (k = 0; k < ITERS; ++k) {
#pragma GCC unroll 10
    for (i = 0; i < CHAINS; ++i) a[i] = _mm512_fmadd_pd(a[i], m, c);
  }
  t = cpu_seconds() - t;
  for (i = 1; i < CHAINS; ++i) a[0] = _mm512_add_pd(a[0], a[i]);
  _mm512_storeu_pd(out, a[0]);
  if (out[0] == 42.0) printf("#");
  return 2.0 * 8 * CHAINS * ITERS / t * 1e-9;
}

static int supported(const char *mode) {
  __builtin_cpu_init();
  if (!strcmp(mode, "fma256")) return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  if (!strcmp(mode, "muladd256")) return __builtin_cpu_supports("avx2");
  if (!strcmp(mode, "fma512")) return __builtin_cpu_supports("avx512f");
  return 0;
}
#endif

/* GB/s of reading `bytes` bytes again and again (8 independent sums of 4 doubles; a dependency between
   passes keeps the compiler from skipping any). Compiled for AVX2 where the CPU has it. */
#define READ_BODY                                                                            \
  size_t n = bytes / sizeof(double) / 32 * 32, i, passes = 1 + (size_t)(2e9 / (double)bytes), p; \
  double *buffer = (double *)calloc(n ? n : 1, sizeof(double)), s[32] = {0}, t = 0, total = 0; \
  int j;                                                                                     \
  if (!buffer || !n) return 0.0;                                                             \
  for (p = 0; p < passes + 2; ++p) {                                                         \
    if (p == 2) t = cpu_seconds(); /* two passes warm the caches */                          \
    for (i = 0; i < n; i += 32)                                                              \
      for (j = 0; j < 32; ++j) s[j] += buffer[i + j];                                        \
    buffer[p % n] = s[p % 32] * 1e-300;                                                      \
  }                                                                                          \
  t = cpu_seconds() - t;                                                                     \
  for (j = 0; j < 32; ++j) total += s[j];                                                    \
  if (total == 42.0) printf("#");                                                            \
  free(buffer);                                                                              \
  return (double)passes * (double)n * sizeof(double) / t * 1e-9;

static double read_portable(size_t bytes) { READ_BODY }
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("avx2"))) static double read_avx2(size_t bytes) { READ_BODY }
#endif

static double read_bandwidth(size_t bytes) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx2")) return read_avx2(bytes);
#endif
  return read_portable(bytes);
}

int main(int argc, char **argv) {
  if (argc == 3 && !strcmp(argv[1], "read")) {
    printf("gbps=%.2f\n", read_bandwidth((size_t)atof(argv[2])));
    return 0;
  }
  if (argc != 2) {
    fprintf(stderr, "usage: %s fma256|muladd256|fma512 | read BYTES\n", argv[0]);
    return 2;
  }
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  if (supported(argv[1])) {
    double g = !strcmp(argv[1], "fma256") ? fma256() : !strcmp(argv[1], "muladd256") ? muladd256() : fma512();
    printf("gflops=%.2f\n", g);
    return 0;
  }
#endif
  printf("unsupported\n");
  return 0;
}
