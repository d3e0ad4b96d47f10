/* nnfmu fast build profile: the kernels that nnfmu/export/codegen.py inlines into model_casadi.c.
 *
 * Plain C99 that compilers vectorise (no intrinsics), so every target and compiler builds it; the
 * model functions that call these are cloned for x86-64-v3 (AVX2 + FMA) and x86-64-v4 (AVX-512) where
 * the toolchain dispatches at load time (see NNFMU_CLONES in the preamble), and the same code runs
 * portably elsewhere. casadi_real is double, or float when NNFMU_FLOAT32 is 1.
 *
 * - nnfmu_exp, nnfmu_tanh: range reduction x = k ln2 + r, |r| <= ln2/2, and the Taylor polynomial
 *   of expm1(r) (to r^13 in double, r^7 in float). Measured against glibc: exp within 1 ulp, tanh
 *   within 3 ulp; NaN and +-inf propagate as in libm; exp flushes results below 2^-1021 (double) or
 *   2^-125 (float) to zero. Branch-free, so a loop over them vectorises.
 * - nnfmu_fmax, nnfmu_fmin: C's fmax/fmin (a NaN argument yields the other one), branch-free.
 * - nnfmu_gemv_panel: z += W y for a constant W stored as row panels (layout written by
 *   nnfmu/export/panels.py): blocks of 32 rows in double (64 in float), the last one rounded up to
 *   whole vectors of 4 (8) rows, zero-padded, each block column after column. The weights
 *   stream through the cache in order, and one block's sums stay in registers. Every z element
 *   still adds its products for k = 0, 1, ... in CasADi's order; with FMA each product-add rounds
 *   once.
 */
#include <math.h>
#include <stdint.h>
#include <string.h>

#if defined(__GNUC__)
#define NNFMU_INLINE static inline __attribute__((always_inline))
#else
#define NNFMU_INLINE static
#endif

#if NNFMU_FLOAT32
typedef uint32_t nnfmu_bits;
#define NNFMU_EXP_HI 89.0f      /* exp overflows to inf above 88.72 */
#define NNFMU_EXP_LO (-86.0f)   /* below: results under 2^-124 flush to zero */
#define NNFMU_TANH_SAT 10.0f    /* |tanh| rounds to 1 above 9.01 */
#else
typedef uint64_t nnfmu_bits;
#define NNFMU_EXP_HI 710.0      /* exp overflows to inf above 709.78 */
#define NNFMU_EXP_LO (-707.5)   /* below: results under 2^-1020 flush to zero */
#define NNFMU_TANH_SAT 20.0     /* |tanh| rounds to 1 above 19.06 */
#endif

/* expm1(r) for |r| <= ln2/2 */
NNFMU_INLINE casadi_real nnfmu_expm1_small(casadi_real r) {
#if NNFMU_FLOAT32
  casadi_real p = 1.0f / 5040;
  p = p * r + 1.0f / 720; p = p * r + 1.0f / 120; p = p * r + 1.0f / 24; p = p * r + 1.0f / 6;
  p = p * r + 0.5f;
#else
  casadi_real p = 1.0 / 6227020800.0;
  p = p * r + 1.0 / 479001600.0; p = p * r + 1.0 / 39916800.0; p = p * r + 1.0 / 3628800.0;
  p = p * r + 1.0 / 362880.0; p = p * r + 1.0 / 40320.0; p = p * r + 1.0 / 5040.0; p = p * r + 1.0 / 720.0;
  p = p * r + 1.0 / 120.0; p = p * r + 1.0 / 24.0; p = p * r + 1.0 / 6.0; p = p * r + 0.5;
#endif
  return r + (r * r) * p;
}

/* r = x - k ln2 with k = round(x / ln2); *half_scale = 2^(k-1) (callers double it, so that k = 1024
   still has an exponent field). Valid for NNFMU_EXP_LO <= x <= NNFMU_EXP_HI. */
NNFMU_INLINE casadi_real nnfmu_reduce(casadi_real x, casadi_real *half_scale) {
#if NNFMU_FLOAT32
  const casadi_real shift = 12582912.0f; /* 1.5 * 2^23: adding it rounds to an integer in the low bits */
  const casadi_real t = x * 1.44269504f + shift, k = t - shift;
  nnfmu_bits bits;
  memcpy(&bits, &t, sizeof bits);
  bits = (bits + 126u) << 23;
  memcpy(half_scale, &bits, sizeof bits);
  return (x - k * 0.693145751953125f) - k * 1.42860677e-06f;
#else
  const casadi_real shift = 6755399441055744.0; /* 1.5 * 2^52 */
  const casadi_real t = x * 1.4426950408889634 + shift, k = t - shift;
  nnfmu_bits bits;
  memcpy(&bits, &t, sizeof bits);
  bits = (bits + 1022u) << 52;
  memcpy(half_scale, &bits, sizeof bits);
  return (x - k * 6.93147180369123816490e-01) - k * 1.90821492927058770002e-10;
#endif
}

NNFMU_INLINE casadi_real nnfmu_exp(casadi_real x) {
  casadi_real xc = x > NNFMU_EXP_HI ? NNFMU_EXP_HI : x, half, r, y; /* NaN fails every test: stays NaN */
  xc = xc < NNFMU_EXP_LO ? NNFMU_EXP_LO : xc;
  r = nnfmu_reduce(xc, &half);
  y = (half + half * nnfmu_expm1_small(r)) * 2;
  return x < NNFMU_EXP_LO ? 0 : y;
}

/* tanh(x) = -m / (m + 2) with m = expm1(-2|x|), sign of x: no cancellation near 0. */
NNFMU_INLINE casadi_real nnfmu_tanh(casadi_real x) {
  casadi_real a = fabs(x), half, em, m;
  a = a > NNFMU_TANH_SAT ? NNFMU_TANH_SAT : a;
  em = nnfmu_expm1_small(nnfmu_reduce(-2 * a, &half));
  m = 2 * (half * em + (half - (casadi_real)0.5)); /* 2^k em + 2^k - 1 */
  return copysign(-m / (m + 2), x);
}

NNFMU_INLINE casadi_real nnfmu_fmax(casadi_real a, casadi_real b) {
  casadi_real r = a > b ? a : b;
  return b != b ? a : r;
}

NNFMU_INLINE casadi_real nnfmu_fmin(casadi_real a, casadi_real b) {
  casadi_real r = a < b ? a : b;
  return b != b ? a : r;
}

/* A panel block is up to 8 vectors of 32 bytes (NNFMU_VL rows each: 4 double or 8 float), so 32 rows in
   double and 64 in float, whose sums stay in 8 registers while the block's weights stream past. */
#define NNFMU_VL ((casadi_int)(32 / sizeof(casadi_real)))
#define NNFMU_BLOCK (8 * NNFMU_VL)

#if defined(__GNUC__)
/* GCC/Clang vector extension: one AVX2 register (two SSE2 ones on the baseline). */
typedef casadi_real nnfmu_vec __attribute__((vector_size(32)));
/* the same, for loads and stores at any casadi_real address */
typedef casadi_real nnfmu_vec_at __attribute__((vector_size(32), aligned(sizeof(casadi_real)), may_alias));
#define nnfmu_load(p) (*(const nnfmu_vec_at *)(p))

#define NNFMU_SUMS(F) F(0) F(1) F(2) F(3) F(4) F(5) F(6) F(7)

/* One block of nv vectors of rows (nv = 1..8, a constant after inlining): z[0..valid) += P y, P stored
   column after column (nv * NNFMU_VL values each, zero-padded below `valid`). The sums start at zero
   and are added to z at the end: the same operations as CasADi's, whose products always start from a
   cleared z. (Starting them from z would let GCC 12 keep them in memory.) */
NNFMU_INLINE void nnfmu_panel_block(const casadi_real *NNFMU_RESTRICT p, casadi_int ncol,
                                    const casadi_real *NNFMU_RESTRICT y, casadi_real *NNFMU_RESTRICT z,
                                    const int nv, casadi_int valid) {
  casadi_real sums[8 * 8];
  const nnfmu_vec zero = {0};
  nnfmu_vec a0 = zero, a1 = zero, a2 = zero, a3 = zero, a4 = zero, a5 = zero, a6 = zero, a7 = zero;
  casadi_int j, k;
  for (k = 0; k < ncol; ++k, p += nv * NNFMU_VL) {
    const casadi_real yk = y[k];
#define NNFMU_FMA(i) if (nv > i) a##i += nnfmu_load(p + i * NNFMU_VL) * yk;
    NNFMU_SUMS(NNFMU_FMA)
  }
#define NNFMU_PUT(i) if (nv > i) *(nnfmu_vec_at *)(sums + i * NNFMU_VL) = a##i;
  NNFMU_SUMS(NNFMU_PUT)
  for (j = 0; j < valid; ++j) z[j] += sums[j];
}
#else
NNFMU_INLINE void nnfmu_panel_block(const casadi_real *NNFMU_RESTRICT p, casadi_int ncol,
                                    const casadi_real *NNFMU_RESTRICT y, casadi_real *NNFMU_RESTRICT z,
                                    const int nv, casadi_int valid) {
  casadi_int j, k;
  for (k = 0; k < ncol; ++k, p += nv * NNFMU_VL)
    for (j = 0; j < valid; ++j) z[j] += p[j] * y[k];
}
#endif

/* z += W y for each of the ncol_y columns of y (ncol values each) and z (nrow values each). W is stored
   as panels (nnfmu/export/panels.py): blocks of NNFMU_BLOCK rows, then one block of the remaining rows
   rounded up to whole vectors, zero-padded. */
NNFMU_INLINE void nnfmu_gemv_panel(const casadi_real *NNFMU_RESTRICT p, casadi_int nrow, casadi_int ncol,
                                   const casadi_real *NNFMU_RESTRICT y, casadi_int ncol_y,
                                   casadi_real *NNFMU_RESTRICT z) {
  casadi_int c, b, rest;
  for (c = 0; c < ncol_y; ++c, y += ncol, z += nrow) {
    const casadi_real *pb = p;
    for (b = 0; b + NNFMU_BLOCK <= nrow; b += NNFMU_BLOCK, pb += NNFMU_BLOCK * ncol)
      nnfmu_panel_block(pb, ncol, y, z + b, 8, NNFMU_BLOCK);
    rest = nrow - b;
    switch ((rest + NNFMU_VL - 1) / NNFMU_VL) { /* vectors of rows left: a constant for each call below */
      case 8: nnfmu_panel_block(pb, ncol, y, z + b, 8, rest); break;
      case 7: nnfmu_panel_block(pb, ncol, y, z + b, 7, rest); break;
      case 6: nnfmu_panel_block(pb, ncol, y, z + b, 6, rest); break;
      case 5: nnfmu_panel_block(pb, ncol, y, z + b, 5, rest); break;
      case 4: nnfmu_panel_block(pb, ncol, y, z + b, 4, rest); break;
      case 3: nnfmu_panel_block(pb, ncol, y, z + b, 3, rest); break;
      case 2: nnfmu_panel_block(pb, ncol, y, z + b, 2, rest); break;
      case 1: nnfmu_panel_block(pb, ncol, y, z + b, 1, rest); break;
      default: break;
    }
  }
}
