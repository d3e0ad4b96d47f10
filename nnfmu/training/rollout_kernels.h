/* What the compiled free runs share (rollout.c: the recurrent networks; window_rollout.c: the TCN and the MLP;
 * nnfmu/ss/state_loop.c: the ss network's state): the real type, vector exp/tanh, the matrix kernels, the
 * activations, and the linear path's step forwards and backwards.
 *
 * nnfmu/training/compiled_rollout.py pastes this file in place of its #include line before compiling, so that the
 * cached library is keyed by everything it was compiled from.
 */
#ifndef NNFMU_ROLLOUT_KERNELS_H
#define NNFMU_ROLLOUT_KERNELS_H
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef NNFMU_REAL
#define NNFMU_REAL double
#endif
typedef NNFMU_REAL real;

/* Vector variants from glibc's libmvec where available (the loops below call them on whole rows). */
#if defined(__GLIBC__) && defined(__x86_64__)
#define NNFMU_SIMD __attribute__((simd("notinbranch")))
#else
#define NNFMU_SIMD
#endif
NNFMU_SIMD double exp(double);
NNFMU_SIMD double tanh(double);
NNFMU_SIMD float expf(float);
NNFMU_SIMD float tanhf(float);
#define EXP(v) (sizeof(real) == sizeof(float) ? (real)expf((float)(v)) : (real)exp((double)(v)))
#define TANH(v) (sizeof(real) == sizeof(float) ? (real)tanhf((float)(v)) : (real)tanh((double)(v)))

static void transpose(int rows, int cols, const real *a, real *at) {
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) at[(long)c * rows + r] = a[(long)r * cols + c];
}

/* Vectors of 32 bytes (8 floats or 4 doubles; GCC/Clang vector extensions), two of them per block of
 * outputs that the matrix kernels keep in registers across a whole sum. */
typedef real vec_t __attribute__((vector_size(32)));
#define VL ((int)(sizeof(vec_t) / sizeof(real)))
#define BLOCK (2 * VL)

static inline vec_t load(const real *p) {
  vec_t v;
  memcpy(&v, p, sizeof v);
  return v;
}

static inline void store(real *p, vec_t v) { memcpy(p, &v, sizeof v); }

static inline real dot(int n, const real *restrict a, const real *restrict b) {
  real acc = 0;
#pragma omp simd reduction(+ : acc)
  for (int i = 0; i < n; ++i) acc += a[i] * b[i];
  return acc;
}

/* out[j] (+)= b[j] + sum_i x[i] M[i, j] for M (n, m) row-major; b may be NULL, add: accumulate into out.
 * Blocks of BLOCK outputs stay in registers over the whole sum (no load and store of out per term);
 * Mt = M^T (m, n), used for the outputs left over as dot products, may be NULL when BLOCK divides m. */
static inline void vecmat(int n, int m, const real *restrict x, const real *restrict M, const real *restrict Mt,
                          const real *restrict b, int add, real *restrict out) {
  int j0 = 0;
  for (; j0 + 4 * VL <= m; j0 += 4 * VL) {
    vec_t a0 = add ? load(out + j0) : (vec_t){0}, a1 = add ? load(out + j0 + VL) : (vec_t){0};
    vec_t a2 = add ? load(out + j0 + 2 * VL) : (vec_t){0}, a3 = add ? load(out + j0 + 3 * VL) : (vec_t){0};
    if (b) {
      a0 += load(b + j0); a1 += load(b + j0 + VL); a2 += load(b + j0 + 2 * VL); a3 += load(b + j0 + 3 * VL);
    }
    for (int i = 0; i < n; ++i) {
      const real *row = M + (long)i * m + j0;
      a0 += x[i] * load(row); a1 += x[i] * load(row + VL); a2 += x[i] * load(row + 2 * VL); a3 += x[i] * load(row + 3 * VL);
    }
    store(out + j0, a0); store(out + j0 + VL, a1); store(out + j0 + 2 * VL, a2); store(out + j0 + 3 * VL, a3);
  }
  for (; j0 + BLOCK <= m; j0 += BLOCK) {
    vec_t a0 = add ? load(out + j0) : (vec_t){0}, a1 = add ? load(out + j0 + VL) : (vec_t){0};
    if (b) {
      a0 += load(b + j0);
      a1 += load(b + j0 + VL);
    }
    for (int i = 0; i < n; ++i) {
      const real *row = M + (long)i * m + j0;
      a0 += x[i] * load(row);
      a1 += x[i] * load(row + VL);
    }
    store(out + j0, a0);
    store(out + j0 + VL, a1);
  }
  for (int j = j0; j < m; ++j) {
    const real acc = Mt ? dot(n, x, Mt + (long)j * n) : 0;
    out[j] = (add ? out[j] : 0) + (b ? b[j] : 0) + acc;
  }
}

static inline real sigmoid(real v) { return (real)1 / ((real)1 + EXP(-v)); }

/* The hidden layers' nonlinearities (nnfmu/models/activation.py), by the codes of compiled_window.ACTIVATIONS. */
enum { ACT_TANH = 0, ACT_RELU = 1, ACT_SIGMOID = 2, ACT_ELU = 3, ACT_SILU = 4 };

/* o = act(a) on a row; keep receives what act_grad needs: o, or for silu a. */
static inline void activate(int act, int n, const real *a, real *restrict o, real *restrict keep) {
  switch (act) {
    case ACT_TANH: for (int j = 0; j < n; ++j) o[j] = TANH(a[j]); break;
    case ACT_RELU: for (int j = 0; j < n; ++j) o[j] = a[j] > 0 ? a[j] : 0; break;
    case ACT_SIGMOID: for (int j = 0; j < n; ++j) o[j] = sigmoid(a[j]); break;
    case ACT_ELU: for (int j = 0; j < n; ++j) o[j] = a[j] > 0 ? a[j] : EXP(a[j]) - 1; break;
    default: for (int j = 0; j < n; ++j) o[j] = a[j] * sigmoid(a[j]); break;
  }
  if (keep) memcpy(keep, act == ACT_SILU ? a : o, sizeof(real) * n);
}

/* ga = g * act'(.) from what activate kept. */
static inline void act_grad(int act, int n, const real *kept, const real *g, real *restrict ga) {
  switch (act) {
    case ACT_TANH: for (int j = 0; j < n; ++j) ga[j] = g[j] * ((real)1 - kept[j] * kept[j]); break;
    case ACT_RELU: for (int j = 0; j < n; ++j) ga[j] = kept[j] > 0 ? g[j] : 0; break;
    case ACT_SIGMOID: for (int j = 0; j < n; ++j) ga[j] = g[j] * kept[j] * ((real)1 - kept[j]); break;
    case ACT_ELU: for (int j = 0; j < n; ++j) ga[j] = kept[j] > 0 ? g[j] : g[j] * (kept[j] + 1); break;
    default:
      for (int j = 0; j < n; ++j) {
        const real sg = sigmoid(kept[j]);
        ga[j] = g[j] * sg * ((real)1 + kept[j] * ((real)1 - sg));
      }
  }
}

/* The linear path's step: z_next = A z + B u + b + G n, y_next = C z_next + d + alpha * n. */
static void path_forward(int n_z, int n_u, int n_y, const real **lin, const real *G, const real *alpha,
                         const real *z, const real *u, const real *n, real *restrict z_next, real *restrict y_next) {
  for (int i = 0; i < n_z; ++i)
    z_next[i] = lin[2][i] + dot(n_z, lin[0] + (long)i * n_z, z) + dot(n_u, lin[1] + (long)i * n_u, u) +
                dot(n_y, G + (long)i * n_y, n);
  for (int o = 0; o < n_y; ++o) y_next[o] = lin[4][o] + dot(n_z, lin[3] + (long)o * n_z, z_next) + alpha[o] * n[o];
}

/* acc (n, m) += sum_b a[b, :n]^T c[b, :m], rows of a and c strided by lda and ldc: the weight gradients
 * of one step over the whole batch, with BLOCK entries of acc in registers across the batch. */
static void outer_sum(int B, int n, int m, const real *restrict a, long lda, const real *restrict c, long ldc,
                      real *restrict acc) {
  for (int i = 0; i < n; ++i) {
    real *out = acc + (long)i * m;
    int j0 = 0;
    for (; j0 + BLOCK <= m; j0 += BLOCK) {
      vec_t s0 = load(out + j0), s1 = load(out + j0 + VL);
      for (int b = 0; b < B; ++b) {
        const real ai = a[b * lda + i], *row = c + b * ldc + j0;
        s0 += ai * load(row);
        s1 += ai * load(row + VL);
      }
      store(out + j0, s0);
      store(out + j0 + VL, s1);
    }
    for (int j = j0; j < m; ++j) {
      real sum = out[j];
      for (int b = 0; b < B; ++b) sum += a[b * lda + i] * c[b * ldc + j];
      out[j] = sum;
    }
  }
}

/* The linear path backwards for one sample: gy = dL/dy_{k+1} in full, cz = dL/dz_{k+1} through the later steps
 * on entry and dL/dz_k on exit; dn receives dL/dn_k; the gradients of G and alpha are added to gG, galpha. */
static void path_backward(int n_z, int n_y, const real **lin, const real *G, const real *alpha, const real *n,
                          const real *gy, real *restrict cz, real *restrict gz, real *restrict dn, real *gG,
                          real *galpha) {
  const real *A = lin[0], *C = lin[3];
  for (int i = 0; i < n_z; ++i) {  /* dL/dz_{k+1} = carried + C^T gy */
    real acc = cz[i];
    for (int o = 0; o < n_y; ++o) acc += C[(long)o * n_z + i] * gy[o];
    gz[i] = acc;
  }
  for (int o = 0; o < n_y; ++o) {  /* dL/dn_k = alpha gy + G^T gz */
    real acc = alpha[o] * gy[o];
    for (int i = 0; i < n_z; ++i) acc += G[(long)i * n_y + o] * gz[i];
    dn[o] = acc;
    galpha[o] += gy[o] * n[o];
  }
  for (int i = 0; i < n_z; ++i)
    for (int o = 0; o < n_y; ++o) gG[(long)i * n_y + o] += gz[i] * n[o];
  for (int j = 0; j < n_z; ++j) {  /* dL/dz_k = A^T gz */
    real acc = 0;
    for (int i = 0; i < n_z; ++i) acc += A[(long)i * n_z + j] * gz[i];
    cz[j] = acc;
  }
}

#endif
