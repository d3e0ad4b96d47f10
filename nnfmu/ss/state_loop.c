/* The ss network's state loop, forward and back-propagation through time.
 *
 * nnfmu/ss/compiled.py compiles this file once per machine (REAL = float and double) and calls it from torch for
 * SSStepModel._states (nnfmu/ss/model.py), which it computes exactly, for the state map f of L hidden layers of
 * width H on the state z (s) and the input:
 *
 *     a^0_k   = pre_k + W_z z_k                   pre_k = W_u u_k + b_0, computed by torch for all steps
 *     h^l_k   = act(a^l_k),  a^l_k = W_l h^{l-1}_k + b_l      (1 <= l < L)
 *     z_{k+1} = drive_k + A z_k + scale (W_o h^{L-1}_k + b_o)     drive_k = B u_k + b, also torch's
 *
 * The input's shares (pre, drive) and the initial state z_0 are torch's, so torch back-propagates from their
 * gradients into W_u, b_0, B, b and the encoder; this file returns those gradients and the gradients of W_z, W_l,
 * b_l, W_o and b_o. A is the identified linear model, held fixed (no gradient).
 *
 * Layout: time-major. z0 (B, s), drive (T, B, s), pre (T, B, H), zs (T, B, s) = z_1 .. z_T. Parameters in torch's
 * layout: A (s, s), then params = {W_z (H, s), W_1 (H, H), b_1 (H), ..., W_{L-1}, b_{L-1}, W_o (s, H), b_o (s)}.
 * For the backward pass the forward pass stores every h^l_k in hs (T, L, B, H) and, for silu, every a^l_k in as
 * (T, L, B, H); with hs == NULL (inference) it keeps one sample's layers only.
 */
#include "rollout_kernels.h"

typedef struct {
  int B, T, s, H, L, act;
  real scale;
} shape_t;

typedef struct { /* one matrix as the kernels read it: W (rows, cols) row-major and its transpose */
  const real *W;
  real *Wt;
} matrix_t;

typedef struct {
  matrix_t A, Wz, Wo, *W; /* W[l] for 1 <= l < L (W[0] unused) */
  const real **b;         /* b[l] for 1 <= l < L, then b[L] = b_o */
} weights_t;

static void free_weights(weights_t *w, int L) {
  free(w->A.Wt);
  free(w->Wz.Wt);
  free(w->Wo.Wt);
  if (w->W)
    for (int l = 0; l < L; ++l) free(w->W[l].Wt);
  free(w->W);
  free(w->b);
}

static int transposed(matrix_t *m, const real *W, int rows, int cols) {
  m->W = W;
  m->Wt = malloc(sizeof(real) * rows * cols);
  if (!m->Wt) return 0;
  transpose(rows, cols, W, m->Wt);
  return 1;
}

/* Returns 1, or 0 when memory runs out (w then holds what to free). */
static int make_weights(const shape_t *sh, const real *A, const real **params, weights_t *w) {
  const int s = sh->s, H = sh->H, L = sh->L;
  memset(w, 0, sizeof *w);
  w->W = calloc((size_t)L, sizeof(matrix_t));
  w->b = calloc((size_t)L + 1, sizeof(real *));
  if (!w->W || !w->b || !transposed(&w->A, A, s, s) || !transposed(&w->Wz, params[0], H, s)) return 0;
  for (int l = 1; l < L; ++l) {
    if (!transposed(&w->W[l], params[2 * l - 1], H, H)) return 0;
    w->b[l] = params[2 * l];
  }
  w->b[L] = params[2 * L];
  return transposed(&w->Wo, params[2 * L - 1], s, H);
}

/* One step of one sample: z_next from z; h (L, H) receives the layers' activations, pre_act (L, H) their
 * arguments (NULL: not kept), a (H) and o (s) are scratch. */
static void step(const shape_t *sh, const weights_t *w, const real *z, const real *drive, const real *pre, real *h,
                 real *pre_act, real *a, real *o, real *restrict z_next) {
  const int s = sh->s, H = sh->H;
  for (int l = 0; l < sh->L; ++l) {
    if (l == 0)
      vecmat(s, H, z, w->Wz.Wt, w->Wz.W, pre, 0, a);
    else
      vecmat(H, H, h + (long)(l - 1) * H, w->W[l].Wt, w->W[l].W, w->b[l], 0, a);
    activate(sh->act, H, a, h + (long)l * H, NULL);
    if (pre_act) memcpy(pre_act + (long)l * H, a, sizeof(real) * H);
  }
  vecmat(H, s, h + (long)(sh->L - 1) * H, w->Wo.Wt, w->Wo.W, w->b[sh->L], 0, o);
  vecmat(s, s, z, w->A.Wt, w->A.W, drive, 0, z_next);
  for (int i = 0; i < s; ++i) z_next[i] += sh->scale * o[i];
}

/* The free run of the state: zs from z0. hs, as: see the top (as is used for silu only). Returns 0, or -1 when
 * memory runs out. */
int nnfmu_ss_forward(int B, int T, int s, int H, int L, int act, double scale, const real *A, const real **params,
                     const real *z0, const real *drive, const real *pre, real *zs, real *hs, real *as) {
  if (B <= 0 || T <= 0) return 0; /* nothing to run */
  const shape_t sh = {B, T, s, H, L, act, (real)scale};
  weights_t w;
  const int made = make_weights(&sh, A, params, &w);
  real *a = malloc(sizeof(real) * H), *o = malloc(sizeof(real) * s);
  real *h = malloc(sizeof(real) * L * H), *pre_act = malloc(sizeof(real) * L * H);
  const int ok = made && a && o && h && pre_act, keep_args = hs && as && act == ACT_SILU;
  if (ok)
    for (int k = 0; k < T; ++k)
      for (int b = 0; b < B; ++b) {
        const long row = (long)k * B + b;
        const real *z = k ? zs + (row - B) * s : z0 + (long)b * s;
        step(&sh, &w, z, drive + row * s, pre + row * H, h, keep_args ? pre_act : NULL, a, o, zs + row * s);
        if (hs)
          for (int l = 0; l < L; ++l) { /* (k, l, b) of (T, L, B, H) */
            const long at = (((long)k * L + l) * B + b) * H;
            memcpy(hs + at, h + (long)l * H, sizeof(real) * H);
            if (keep_args) memcpy(as + at, pre_act + (long)l * H, sizeof(real) * H);
          }
      }
  free_weights(&w, L);
  free(a);
  free(o);
  free(h);
  free(pre_act);
  return ok ? 0 : -1;
}

/* Back-propagation through the free run: from gzs = dL/dzs (T, B, s) to gz0 (B, s), gdrive (T, B, s), gpre
 * (T, B, H) and grads = {dW_z, dW_1, db_1, ..., dW_o, db_o} (params' shapes, added to: zero them first), with
 * what nnfmu_ss_forward stored. Returns 0, or -1 when memory runs out. */
int nnfmu_ss_backward(int B, int T, int s, int H, int L, int act, double scale, const real *A, const real **params,
                      const real *z0, const real *zs, const real *hs, const real *as, const real *gzs, real **grads,
                      real *gz0, real *gdrive, real *gpre) {
  if (B <= 0 || T <= 0) { /* nothing ran: dL/dz0 is dL/dzs's, which is empty */
    if (B > 0) memset(gz0, 0, sizeof(real) * B * s);
    return 0;
  }
  const shape_t sh = {B, T, s, H, L, act, (real)scale};
  weights_t w;
  const int made = make_weights(&sh, A, params, &w);
  real *carry = calloc((size_t)B * s, sizeof(real)), *go = malloc(sizeof(real) * B * s);
  real *gh = malloc(sizeof(real) * B * H), *ga = malloc(sizeof(real) * B * H);
  const int ok = made && carry && go && gh && ga;
  if (ok) {
    const long BH = (long)B * H;
    const real *kept = act == ACT_SILU ? as : hs; /* what act_grad reads: a for silu, else h */
    for (int k = T - 1; k >= 0; --k) {
      const real *h_k = hs + (long)k * L * BH, *kept_k = kept + (long)k * L * BH;
      const real *z_k = k ? zs + (long)(k - 1) * B * s : z0;
      real *gd = gdrive + (long)k * B * s, *gp = gpre + (long)k * BH;
      for (int b = 0; b < B; ++b)
        for (int i = 0; i < s; ++i) {
          const long at = (long)b * s + i;
          gd[at] = gzs[(long)k * B * s + at] + carry[at]; /* dL/dz_{k+1}, all of it */
          go[at] = sh.scale * gd[at];
        }
      outer_sum(B, s, H, go, s, h_k + (long)(L - 1) * BH, H, grads[2 * L - 1]);
      for (int b = 0; b < B; ++b) {
        for (int i = 0; i < s; ++i) grads[2 * L][i] += go[(long)b * s + i];
        vecmat(s, H, go + (long)b * s, w.Wo.W, w.Wo.Wt, NULL, 0, gh + (long)b * H);
      }
      for (int l = L - 1; l >= 0; --l) {
        real *g_arg = l ? ga : gp; /* dL/da^l */
        for (int b = 0; b < B; ++b)
          act_grad(act, H, kept_k + (long)l * BH + (long)b * H, gh + (long)b * H, g_arg + (long)b * H);
        if (!l) break;
        outer_sum(B, H, H, g_arg, H, h_k + (long)(l - 1) * BH, H, grads[2 * l - 1]);
        for (int b = 0; b < B; ++b) {
          for (int j = 0; j < H; ++j) grads[2 * l][j] += g_arg[(long)b * H + j];
          vecmat(H, H, g_arg + (long)b * H, w.W[l].W, w.W[l].Wt, NULL, 0, gh + (long)b * H);
        }
      }
      outer_sum(B, H, s, gp, H, z_k, s, grads[0]);
      for (int b = 0; b < B; ++b) { /* dL/dz_k through the later steps: A^T g + W_z^T dL/da^0 */
        vecmat(s, s, gd + (long)b * s, w.A.W, w.A.Wt, NULL, 0, carry + (long)b * s);
        vecmat(H, s, gp + (long)b * H, w.Wz.W, w.Wz.Wt, NULL, 1, carry + (long)b * s);
      }
    }
    memcpy(gz0, carry, sizeof(real) * B * s);
  }
  free_weights(&w, L);
  free(carry);
  free(go);
  free(gh);
  free(ga);
  return ok ? 0 : -1;
}
