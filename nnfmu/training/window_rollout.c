/* Free run of a window network (TCN or MLP) with output feedback, forward and back-propagation through time.
 *
 * nnfmu/training/compiled_rollout.py compiles this file once per machine (REAL = float and double) and
 * calls it from torch. It computes exactly what the free run of TCNStepModel (nnfmu/networks/tcn/model.py, its step in
 * nnfmu/networks/tcn/state.py) or MLPStepModel (nnfmu/networks/mlp/model.py, models/window.py) computes, for L layers of width
 * H, without dropout or increment mode. Layer i reads K_i taps of its input, d_i steps apart:
 *
 *     s_k   = [y_k + e_k, u_k]                       the newest sample: y_k fed back, e_k the feedback noise
 *     h^0_k = act(b_0 + sum_j W_0[j] s_{k - (K_0-1-j) d_0})
 *     h^i_k = [h^{i-1}_k +] act(b_i + sum_j W_i[j] h^{i-1}_{k - (K_i-1-j) d_i})     (i >= 1)
 *     n_k   = W_o h^{L-1}_k + b_o;    y_{k+1} = y_k + e_k + skip * n_k (skip)   or   n_k
 *
 * TCN: K_i = the kernel, d_i = 2^i, the residual [h^{i-1}_k +] for i >= 1, W_i[j] = conv.weight[:, :, j].
 * MLP: layer 0 reads the window (K_0 = its length L_w, d_0 = 1), the others one column (K_i = 1), no
 * residual; W_0[j] = the columns of sample j in the first Linear's weight (the window is flattened oldest
 * sample first, each sample's channels together).
 *
 * Before k = 0 the model is at rest (tcn_state.init, WindowStepModel.init_norm): every past sample is
 * r = [y_0, u_0], without noise, and every TCN delay line holds the column r^i its layer computes over that
 * constant input, r^0 = act(b_0 + sum_j W_0[j] r), r^i = r^{i-1} + act(b_i + sum_j W_i[j] r^{i-1}). A tap
 * before step 0 reads these (and back-propagates into them, and through them into the weights and y_0).
 * The feedback noise e_k (training only; zero without it) is drawn by torch, one (B, n_y) draw per step as
 * its own loop draws it, so that both compute the same numbers.
 *
 * With a linear path of n_z > 0 states (LinearPathStepModel, nnfmu/models/linear_path.py), n_k is the
 * network's raw output and the output is the linear model's plus a learned correction, as in rollout.c:
 *
 *     z_{k+1} = A z_k + B u_k + b + G n_k;   y_{k+1} = C z_{k+1} + d + alpha * n_k
 *
 * Layout: time-major. un (T, B, n_u), yn0 (B, n_y), ys (T, B, n_y) with ys[0] = yn0. Parameters in torch's
 * layout: per layer W_i and b_i (H), C_0 = n_y + n_u, C_i = H: the TCN's nn.Conv1d weight (H, C_i, K), channel
 * major; the MLP's nn.Linear weights (H, K_0 C_0), sample major, and (H, H); then W_o (n_y, H),
 * b_o (n_y); with a linear path G (n_z, n_y), alpha (n_y); lin = {A, B, b, C, d} row-major, held fixed.
 * For the backward pass the forward pass stores every h^i_k and what the activation's derivative needs
 * (the activation, or for silu its argument), both (T - 1, L, B, H), the rest columns r^i and theirs, both
 * (L, B, H), with noise the fed-back samples y_k + e_k (T - 1, B, n_y), and with a path the raw outputs
 * (T - 1, B, n_y). Without them (inference) it keeps a ring of the receptive field's steps only.
 */
#include "rollout_kernels.h"

enum { TCN = 0, MLP = 1 };

typedef struct {
  int kind, B, T, n_u, n_y, H, L, K, act, has_skip;  /* K: the TCN's kernel, the MLP's window */
  real skip;
} shape_t;

typedef struct {    /* one layer's weights, one matrix per tap j (oldest first) */
  int C, K, d;      /* input channels, taps, steps between taps */
  int residual;     /* h^i = h^{i-1} + act(...) */
  real *Wt;         /* (K, C, H): Wt[(j C + c) H + h] = W[h, c, j], rows of outputs for vecmat */
  real *Wn;         /* (K, H, C): Wn[(j H + h) C + c] = W[h, c, j], its transpose per tap */
  const real *b;    /* (H) */
  real *gWt;        /* the gradient of W in the layout of Wt (backward only) */
} layer_t;

static void free_layers(layer_t *layers, int L) {
  if (!layers) return;
  for (int i = 0; i < L; ++i) { free(layers[i].Wt); free(layers[i].Wn); free(layers[i].gWt); }
  free(layers);
}

/* Where torch keeps W_i[j][h, c]: the TCN's (H, C, K), the MLP's (H, K C). */
static inline long weight_index(const shape_t *s, const layer_t *ly, int h, int c, int j) {
  return s->kind == TCN ? ((long)h * ly->C + c) * ly->K + j : ((long)h * ly->K + j) * ly->C + c;
}

static layer_t *make_layers(const shape_t *s, const real **params, int with_grads) {
  layer_t *layers = calloc((size_t)s->L, sizeof(layer_t));
  if (!layers) return NULL;
  const int H = s->H;
  for (int i = 0; i < s->L; ++i) {
    layer_t *ly = layers + i;
    const int C = i ? H : s->n_y + s->n_u, K = (s->kind == TCN || i == 0) ? s->K : 1;
    ly->C = C;
    ly->K = K;
    ly->d = s->kind == TCN ? 1 << i : 1;
    ly->residual = s->kind == TCN && i > 0;
    ly->b = params[2 * i + 1];
    ly->Wt = malloc(sizeof(real) * K * C * H);
    ly->Wn = malloc(sizeof(real) * K * C * H);
    ly->gWt = with_grads ? calloc((size_t)K * C * H, sizeof(real)) : NULL;
    if (!ly->Wt || !ly->Wn || (with_grads && !ly->gWt)) {
      free_layers(layers, s->L);
      return NULL;
    }
    for (int h = 0; h < H; ++h)
      for (int c = 0; c < C; ++c)
        for (int j = 0; j < K; ++j) {
          const real w = params[2 * i][weight_index(s, ly, h, c, j)];
          ly->Wt[((long)j * C + c) * H + h] = w;
          ly->Wn[((long)j * H + h) * C + c] = w;
        }
  }
  return layers;
}

/* The step that tap j of a layer reads at step k: k - (K-1-j) d; before 0, the rest. */
static inline long tap_step(const layer_t *ly, int j, long k) { return k - (long)(ly->K - 1 - j) * ly->d; }

/* x (C_0) = the first layer's input sample at step t of row b: [feed_t, u_t], or at rest [y_0, u_0]. */
static inline const real *sample(const shape_t *s, long t, int b, const real *feed, const real *ys, const real *un,
                                 real *x) {
  memcpy(x, t < 0 ? ys + (long)b * s->n_y : feed + (t * s->B + b) * s->n_y, sizeof(real) * s->n_y);
  memcpy(x + s->n_y, un + ((t < 0 ? 0 : t) * s->B + b) * s->n_u, sizeof(real) * s->n_u);
  return x;
}

/* One layer's column: h (H) = [in_below +] act(b + sum_j W[j] in_j); a (H) scratch; keep as activate's. */
static void column(const shape_t *s, const layer_t *ly, const real **in, const real *below, real *a, real *h,
                   real *keep) {
  for (int j = 0; j < ly->K; ++j)
    vecmat(ly->C, s->H, in[j], ly->Wt + (long)j * ly->C * s->H, ly->Wn + (long)j * s->H * ly->C, j ? NULL : ly->b,
           j > 0, a);
  activate(s->act, s->H, a, h, keep);
  if (ly->residual) for (int c = 0; c < s->H; ++c) h[c] += below[c];
}

/* The free run. hs and kept (T - 1, L, B, H), rest and rest_kept (L, B, H) and ns (T - 1, B, n_y) receive
 * what the backward pass needs; with hs == NULL (inference) a ring of the receptive field's steps is kept
 * instead and kept, ns are unused. noise (T - 1, B, n_y) or NULL: e_k; fed (T - 1, B, n_y) receives
 * y_k + e_k (unused without noise). n_z > 0: the linear path (lin, z0 (B, n_z)); n_z = 0: lin, z0 and ns are
 * unused. Returns 0, or -1 when memory runs out. */
int nnfmu_window_forward(int kind, int B, int T, int n_u, int n_y, int H, int L, int K, int act, int has_skip,
                         double skip, const real **params, const real *un, const real *yn0, const real *noise,
                         real *ys, real *fed, real *hs, real *kept, real *rest, real *rest_kept, int n_z,
                         const real **lin, const real *z0, real *ns) {
  const shape_t s = {kind, B, T, n_u, n_y, H, L, K, act, has_skip, (real)skip};
  const long BH = (long)B * H, LBH = (long)L * BH;
  const real *Wo = params[2 * L], *bo = params[2 * L + 1], *feed = noise ? fed : ys;
  layer_t *layers = make_layers(&s, params, 0);
  long R = 1, K_max = 1;  /* the ring's length: one more than the longest reach back of a tap */
  for (int i = 0; layers && i < L; ++i) {
    if ((long)(layers[i].K - 1) * layers[i].d + 1 > R) R = (long)(layers[i].K - 1) * layers[i].d + 1;
    if (layers[i].K > K_max) K_max = layers[i].K;
  }
  real *ring = hs ? NULL : malloc(sizeof(real) * R * LBH), *h_all = hs ? hs : ring;
  real *a = malloc(sizeof(real) * H), *x = malloc(sizeof(real) * K_max * (n_y + n_u)), *n = malloc(sizeof(real) * n_y);
  const real **in = malloc(sizeof(real *) * K_max);
  real *zs = n_z ? malloc(sizeof(real) * 2 * B * n_z) : NULL;
  const int ok = layers && h_all && a && x && n && in && (!n_z || zs);
  if (ok) {
    if (n_z) memcpy(zs, z0, sizeof(real) * (size_t)B * n_z);
    memcpy(ys, yn0, sizeof(real) * (size_t)B * n_y);
    for (int b = 0; b < B; ++b)  /* the rest columns r^i */
      for (int i = 0; i < L; ++i) {
        const real *below = i ? rest + ((long)(i - 1) * B + b) * H : NULL;
        for (int j = 0; j < layers[i].K; ++j) in[j] = i ? below : sample(&s, -1, b, feed, ys, un, x);
        column(&s, layers + i, in, below, a, rest + ((long)i * B + b) * H, rest_kept + ((long)i * B + b) * H);
      }
  }
  for (long k = 0; ok && k + 1 < T; ++k) {
    for (int b = 0; b < B; ++b) {
      if (noise)
        for (long o = (k * B + b) * n_y; o < (k * B + b + 1) * n_y; ++o) fed[o] = ys[o] + noise[o];
      const real *top = NULL;
      for (int i = 0; i < L; ++i) {
        const layer_t *ly = layers + i;
        for (int j = 0; j < ly->K; ++j) {
          const long t = tap_step(ly, j, k);
          if (i == 0)
            in[j] = sample(&s, t, b, feed, ys, un, x + (long)j * (n_y + n_u));
          else
            in[j] = (t < 0 ? rest + (long)(i - 1) * BH : h_all + ((hs ? t : t % R) * L + i - 1) * BH) + (long)b * H;
        }
        const long now = ((hs ? k : k % R) * L + i) * BH + (long)b * H;
        column(&s, ly, in, i ? h_all + now - BH : NULL, a, h_all + now, kept ? kept + now : NULL);
        top = h_all + now;
      }
      for (int o = 0; o < n_y; ++o) n[o] = bo[o] + dot(H, Wo + (long)o * H, top);
      const real *y = feed + (k * B + b) * n_y;
      real *y_next = ys + ((k + 1) * B + b) * n_y;
      if (!n_z) {
        for (int o = 0; o < n_y; ++o) y_next[o] = has_skip ? y[o] + s.skip * n[o] : n[o];
        continue;
      }
      if (ns) memcpy(ns + (k * B + b) * n_y, n, sizeof(real) * n_y);
      path_forward(n_z, n_u, n_y, lin, params[2 * L + 2], params[2 * L + 3], zs + ((k & 1) * B + b) * n_z,
                   un + (k * B + b) * n_u, n, zs + (((k + 1) & 1) * B + b) * n_z, y_next);
    }
  }
  free_layers(layers, L); free(ring); free(a); free(x); free(n); free(in); free(zs);
  return ok ? 0 : -1;
}

/* One layer backwards over the batch at one step (or at rest): gh (B, H) dL/d its output; the gradient of its
 * bias and taps' weights is added, and W_j^T ga of each tap is added where that tap's input came from:
 * gin_h[j] (B rows of H, layers above the first) or, for the first layer, gin_y[j] (B rows of n_y, stride n_y;
 * the input rows: in_y[j], in_u[j]); in_h[j]: the inputs of a layer above the first (B rows of H). */
static void layer_backward(const shape_t *s, const layer_t *ly, real *gb, const real *kept, const real *gh,
                           real *ga, real *gin, real **gin_y, real **gin_h, const real **in_y, const real **in_u,
                           const real **in_h, long y_stride) {
  const int H = s->H, C0 = s->n_y + s->n_u;
  for (int b = 0; b < s->B; ++b) {
    act_grad(s->act, H, kept + (long)b * H, gh + (long)b * H, ga + (long)b * H);
    for (int c = 0; c < H; ++c) gb[c] += ga[(long)b * H + c];
    for (int j = 0; j < ly->K; ++j) {  /* dL/d(the tap's input) += W_j^T ga */
      const real *Wn = ly->Wn + (long)j * H * ly->C, *Wt = ly->Wt + (long)j * ly->C * H;
      if (gin_h) {
        vecmat(H, H, ga + (long)b * H, Wn, Wt, NULL, 1, gin_h[j] + (long)b * H);
      } else {
        vecmat(H, C0, ga + (long)b * H, Wn, Wt, NULL, 0, gin);
        for (int o = 0; o < s->n_y; ++o) gin_y[j][(long)b * y_stride + o] += gin[o];
      }
    }
  }
  for (int j = 0; j < ly->K; ++j) {  /* dL/dW_j += sum_b input_b^T ga_b */
    real *gW = ly->gWt + (long)j * ly->C * H;
    if (gin_h) {
      outer_sum(s->B, H, H, in_h[j], H, ga, H, gW);
    } else {
      outer_sum(s->B, s->n_y, H, in_y[j], s->n_y, ga, H, gW);
      outer_sum(s->B, s->n_u, H, in_u[j], s->n_u, ga, H, gW + (long)s->n_y * H);
    }
  }
}

/* Back-propagation through the free run. gys (T, B, n_y): dL/dys. grads: same layout as params, added to
 * (zero them first). gyn0 (B, n_y) receives dL/dyn0, gz0 (B, n_z) dL/dz0 (linear path). un, ys, fed, hs, kept,
 * rest, rest_kept, ns as left by the forward pass (fed NULL without noise). Steps run backwards; within a step
 * the layers run from the top, each over the whole batch, so that every gradient reaching a value has arrived
 * before the value is processed (its later taps and the layer above at the same step come first), and the
 * weight gradients of a step are sums over the batch (outer_sum); the rest columns come last. */
int nnfmu_window_backward(int kind, int B, int T, int n_u, int n_y, int H, int L, int K, int act, int has_skip,
                          double skip, const real **params, const real *un, const real *ys, const real *fed,
                          const real *hs, const real *kept, const real *rest, const real *rest_kept,
                          const real *gys, real **grads, real *gyn0, int n_z, const real **lin, const real *ns,
                          real *gz0) {
  const shape_t s = {kind, B, T, n_u, n_y, H, L, K, act, has_skip, (real)skip};
  const long BH = (long)B * H, LBH = (long)L * BH, steps = T > 1 ? T - 1 : 0;
  const int C0 = n_y + n_u, C_max = C0 > H ? C0 : H;
  const real *Wo = params[2 * L], *feed = fed ? fed : ys;
  layer_t *layers = make_layers(&s, params, 1);
  int K_max = 1;
  for (int i = 0; layers && i < L; ++i) K_max = layers[i].K > K_max ? layers[i].K : K_max;
  real *gy_all = malloc(sizeof(real) * (size_t)T * B * n_y);           /* dL/dy_k, complete once k is reached */
  real *gh_all = calloc((size_t)(steps * LBH) + 1, sizeof(real));      /* dL/dh^i_k, likewise */
  real *g_rest = calloc((size_t)LBH, sizeof(real)), *g_rest_y = calloc((size_t)B * n_y, sizeof(real));
  real *ga = malloc(sizeof(real) * BH), *gin = malloc(sizeof(real) * C_max), *gn = malloc(sizeof(real) * B * n_y);
  real *carry_z = n_z ? calloc((size_t)B * n_z, sizeof(real)) : NULL, *gz = n_z ? malloc(sizeof(real) * n_z) : NULL;
  real *dn = malloc(sizeof(real) * n_y);
  real **gin_y = malloc(sizeof(real *) * K_max), **gin_h = malloc(sizeof(real *) * K_max);
  const real **in_y = malloc(sizeof(real *) * K_max), **in_u = malloc(sizeof(real *) * K_max);
  const real **in_h = malloc(sizeof(real *) * K_max);
  const int ok = layers && gy_all && gh_all && g_rest && g_rest_y && ga && gin && gn && dn && gin_y && gin_h &&
                 in_y && in_u && in_h && (!n_z || (carry_z && gz));
  if (ok) memcpy(gy_all, gys, sizeof(real) * (size_t)T * B * n_y);
  for (long k = steps - 1; ok && k >= 0; --k) {
    const real *h_top = hs + (k * L + L - 1) * BH;
    for (int b = 0; b < B; ++b) {  /* the output: y_{k+1} from n_k (and y_k + e_k) */
      const real *gy = gy_all + ((k + 1) * B + b) * n_y;
      real *g = gn + (long)b * n_y;
      if (n_z)
        path_backward(n_z, n_y, lin, params[2 * L + 2], params[2 * L + 3], ns + (k * B + b) * n_y, gy,
                      carry_z + (long)b * n_z, gz, dn, grads[2 * L + 2], grads[2 * L + 3]);
      else
        memcpy(dn, gy, sizeof(real) * n_y);
      for (int o = 0; o < n_y; ++o) {
        g[o] = has_skip ? s.skip * dn[o] : dn[o];
        if (has_skip) gy_all[(k * B + b) * n_y + o] += dn[o];
        grads[2 * L + 1][o] += g[o];
      }
      real *gh = gh_all + (k * L + L - 1) * BH + (long)b * H;
      for (int o = 0; o < n_y; ++o)  /* dL/dh^{L-1}_k += W_o^T g */
        for (int c = 0; c < H; ++c) gh[c] += g[o] * Wo[(long)o * H + c];
    }
    outer_sum(B, n_y, H, gn, n_y, h_top, H, grads[2 * L]);
    for (int i = L - 1; i >= 0; --i) {
      const layer_t *ly = layers + i;
      const long at = (k * L + i) * BH;
      if (ly->residual) for (long c = 0; c < BH; ++c) gh_all[at - BH + c] += gh_all[at + c];
      for (int j = 0; j < ly->K; ++j) {
        const long t = tap_step(ly, j, k);
        if (i) {
          gin_h[j] = t < 0 ? g_rest + (long)(i - 1) * BH : gh_all + (t * L + i - 1) * BH;
          in_h[j] = t < 0 ? rest + (long)(i - 1) * BH : hs + (t * L + i - 1) * BH;
        } else {
          gin_y[j] = t < 0 ? g_rest_y : gy_all + t * B * n_y;
          in_y[j] = t < 0 ? ys : feed + t * B * n_y;
          in_u[j] = un + (t < 0 ? 0 : t) * B * n_u;
        }
      }
      layer_backward(&s, ly, grads[2 * i + 1], kept + at, gh_all + at, ga, gin, gin_y, i ? gin_h : NULL, in_y, in_u,
                     in_h, n_y);
    }
  }
  for (int i = L - 1; ok && i >= 0; --i) {  /* the rest columns: every tap reads the layer below at rest */
    const layer_t *ly = layers + i;
    if (ly->residual) for (long c = 0; c < BH; ++c) g_rest[(long)(i - 1) * BH + c] += g_rest[(long)i * BH + c];
    for (int j = 0; j < ly->K; ++j) {
      gin_h[j] = i ? g_rest + (long)(i - 1) * BH : NULL;
      in_h[j] = i ? rest + (long)(i - 1) * BH : NULL;
      gin_y[j] = g_rest_y;
      in_y[j] = ys;
      in_u[j] = un;
    }
    layer_backward(&s, ly, grads[2 * i + 1], rest_kept + (long)i * BH, g_rest + (long)i * BH, ga, gin, gin_y,
                   i ? gin_h : NULL, in_y, in_u, in_h, n_y);
  }
  if (ok) {
    for (long c = 0; c < (long)B * n_y; ++c) gyn0[c] = gy_all[c] + g_rest_y[c];
    if (n_z) memcpy(gz0, carry_z, sizeof(real) * (size_t)B * n_z);
    for (int i = 0; i < L; ++i) {
      const layer_t *ly = layers + i;
      for (int h = 0; h < H; ++h)
        for (int c = 0; c < ly->C; ++c)
          for (int j = 0; j < ly->K; ++j)
            grads[2 * i][weight_index(&s, ly, h, c, j)] += ly->gWt[((long)j * ly->C + c) * H + h];
    }
  }
  free_layers(layers, L); free(gy_all); free(gh_all); free(g_rest); free(g_rest_y); free(ga); free(gin); free(gn);
  free(carry_z); free(gz); free(dn); free(gin_y); free(gin_h); free(in_y); free(in_u); free(in_h);
  return ok ? 0 : -1;
}
