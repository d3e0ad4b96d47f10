/* Free run of a window network (TCN or MLP) with output feedback, forward and back-propagation through time.
 *
 * nnfmu/training/compiled_rollout.py compiles this file once per machine (REAL = float and double) and
 * calls it from torch. It computes exactly what the free run of TCNStepModel (nnfmu/models/tcn.py, its step in
 * nnfmu/models/tcn_state.py) or MLPStepModel (nnfmu/models/mlp.py, window.py) computes, for L layers of width
 * H, without dropout or increment mode. Layer i reads K_i taps of its input, d_i steps apart:
 *
 *     s_k   = [y_k, u_k]                                               the newest sample, y_k fed back
 *     h^0_k = act(b_0 + sum_j W_0[j] s_{k - (K_0-1-j) d_0})
 *     h^i_k = [h^{i-1}_k +] act(b_i + sum_j W_i[j] h^{i-1}_{k - (K_i-1-j) d_i})     (i >= 1)
 *     n_k   = W_o h^{L-1}_k + b_o;    y_{k+1} = y_k + skip * n_k (skip)   or   n_k
 *
 * TCN: K_i = the kernel, d_i = 2^i, the residual [h^{i-1}_k +] for i >= 1, W_i[j] = conv.weight[:, :, j].
 * MLP: layer 0 reads the window (K_0 = its length L_w, d_0 = 1), the others one column (K_i = 1), no
 * residual; W_0[j] = the columns of sample j in the first Linear's weight (the window is flattened oldest
 * sample first, each sample's channels together).
 *
 * Before k = 0 the model is at rest (tcn_state.init, WindowStepModel._init_norm: every past sample is s_0,
 * and every TCN delay line holds the column its layer's input then has). That column is h^i_0 itself: at
 * k = 0 every tap of every layer reaches back to the rest, so h^i_0 is the layer over a constant input. Every
 * tap before 0 therefore reads (and back-propagates into) step 0, which is the same function of the weights,
 * y_0 and u_0 as torch's rest state.
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
 * (the activation, or for silu its argument), both (T - 1, L, B, H), and with a path the raw outputs
 * (T - 1, B, n_y). Without them (inference) it keeps a ring of the receptive field's steps only.
 */
#include "rollout_kernels.h"

enum { ACT_TANH = 0, ACT_RELU = 1, ACT_SIGMOID = 2, ACT_ELU = 3, ACT_SILU = 4 };
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

/* o = act(a) on a row; keep receives what act_grad needs: o, or for silu a. */
static void activate(int act, int n, const real *a, real *restrict o, real *restrict keep) {
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
static void act_grad(int act, int n, const real *kept, const real *g, real *restrict ga) {
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

/* The step whose value tap j of a layer reads at step k: k - (K-1-j) d, the rest (step 0) before 0. */
static inline long tap_step(const layer_t *ly, int j, int k) {
  const long t = (long)k - (long)(ly->K - 1 - j) * ly->d;
  return t > 0 ? t : 0;
}

/* The free run. hs and kept (T - 1, L, B, H) and ns (T - 1, B, n_y) receive what the backward pass needs;
 * with hs == NULL (inference) a ring of the receptive field's steps is kept instead and kept, ns are unused.
 * n_z > 0: the linear path (lin, z0 (B, n_z)); n_z = 0: lin, z0 and ns are unused. Returns 0, or -1 when
 * memory runs out. */
int nnfmu_window_forward(int kind, int B, int T, int n_u, int n_y, int H, int L, int K, int act, int has_skip,
                         double skip, const real **params, const real *un, const real *yn0, real *ys, real *hs,
                         real *kept, int n_z, const real **lin, const real *z0, real *ns) {
  const shape_t s = {kind, B, T, n_u, n_y, H, L, K, act, has_skip, (real)skip};
  const long LBH = (long)L * B * H;
  const int C0 = n_y + n_u;
  const real *Wo = params[2 * L], *bo = params[2 * L + 1];
  layer_t *layers = make_layers(&s, params, 0);
  long R = 1;  /* the ring's length: one more than the longest reach back of a tap */
  for (int i = 0; layers && i < L; ++i)
    if ((long)(layers[i].K - 1) * layers[i].d + 1 > R) R = (long)(layers[i].K - 1) * layers[i].d + 1;
  real *ring = hs ? NULL : malloc(sizeof(real) * R * LBH), *h_all = hs ? hs : ring;
  real *a = malloc(sizeof(real) * H), *x = malloc(sizeof(real) * C0), *n = malloc(sizeof(real) * n_y);
  real *zs = n_z ? malloc(sizeof(real) * 2 * B * n_z) : NULL;
  const int ok = layers && h_all && a && x && n && (!n_z || zs);
  if (ok) {
    if (n_z) memcpy(zs, z0, sizeof(real) * (size_t)B * n_z);
    memcpy(ys, yn0, sizeof(real) * (size_t)B * n_y);
  }
  for (int k = 0; ok && k + 1 < T; ++k) {
    for (int b = 0; b < B; ++b) {
      const real *in = NULL;
      for (int i = 0; i < L; ++i) {
        const layer_t *ly = layers + i;
        for (int j = 0; j < ly->K; ++j) {
          const long t = tap_step(ly, j, k), at = hs ? t : t % R;
          if (i == 0) {
            memcpy(x, ys + (t * B + b) * n_y, sizeof(real) * n_y);
            memcpy(x + n_y, un + (t * B + b) * n_u, sizeof(real) * n_u);
            in = x;
          } else {
            in = h_all + (at * L + i - 1) * B * H + (long)b * H;
          }
          vecmat(ly->C, H, in, ly->Wt + (long)j * ly->C * H, ly->Wn + (long)j * H * ly->C, j ? NULL : ly->b, j > 0, a);
        }
        const long now = ((hs ? k : k % R) * L + i) * B * H + (long)b * H;
        real *h = h_all + now;
        activate(act, H, a, h, kept ? kept + now : NULL);
        if (ly->residual) for (int c = 0; c < H; ++c) h[c] += h[c - (long)B * H];  /* h^{i-1}_k: the layer below */
        in = h;
      }
      for (int o = 0; o < n_y; ++o) n[o] = bo[o] + dot(H, Wo + (long)o * H, in);
      const real *y = ys + ((long)k * B + b) * n_y;
      real *y_next = ys + ((long)(k + 1) * B + b) * n_y;
      if (!n_z) {
        for (int o = 0; o < n_y; ++o) y_next[o] = has_skip ? y[o] + s.skip * n[o] : n[o];
        continue;
      }
      if (ns) memcpy(ns + ((long)k * B + b) * n_y, n, sizeof(real) * n_y);
      path_forward(n_z, n_u, n_y, lin, params[2 * L + 2], params[2 * L + 3], zs + ((long)(k & 1) * B + b) * n_z,
                   un + ((long)k * B + b) * n_u, n, zs + ((long)((k + 1) & 1) * B + b) * n_z, y_next);
    }
  }
  free_layers(layers, L); free(ring); free(a); free(x); free(n); free(zs);
  return ok ? 0 : -1;
}

/* Back-propagation through the free run. gys (T, B, n_y): dL/dys. grads: same layout as params, added to
 * (zero them first). gyn0 (B, n_y) receives dL/dyn0, gz0 (B, n_z) dL/dz0 (linear path). un, ys, hs, kept, ns
 * as left by the forward pass. Steps run backwards; within a step the layers run from the top, each over the
 * whole batch, so that every gradient reaching a value has arrived before the value is processed (its later
 * taps and the layer above at the same step come first), and the weight gradients of a step are sums over the
 * batch (outer_sum). */
int nnfmu_window_backward(int kind, int B, int T, int n_u, int n_y, int H, int L, int K, int act, int has_skip,
                          double skip, const real **params, const real *un, const real *ys, const real *hs,
                          const real *kept, const real *gys, real **grads, real *gyn0, int n_z, const real **lin,
                          const real *ns, real *gz0) {
  const shape_t s = {kind, B, T, n_u, n_y, H, L, K, act, has_skip, (real)skip};
  const long BH = (long)B * H, LBH = (long)L * BH, steps = T > 1 ? T - 1 : 0;
  const int C0 = n_y + n_u, C_max = C0 > H ? C0 : H;
  const real *Wo = params[2 * L];
  layer_t *layers = make_layers(&s, params, 1);
  real *gy_all = malloc(sizeof(real) * (size_t)T * B * n_y);           /* dL/dy_k, complete once k is reached */
  real *gh_all = calloc((size_t)(steps * LBH) + 1, sizeof(real));      /* dL/dh^i_k, likewise */
  real *ga = malloc(sizeof(real) * BH), *gin = malloc(sizeof(real) * C_max), *gn = malloc(sizeof(real) * B * n_y);
  real *carry_z = n_z ? calloc((size_t)B * n_z, sizeof(real)) : NULL, *gz = n_z ? malloc(sizeof(real) * n_z) : NULL;
  real *dn = malloc(sizeof(real) * n_y);
  const int ok = layers && gy_all && gh_all && ga && gin && gn && dn && (!n_z || (carry_z && gz));
  if (ok) memcpy(gy_all, gys, sizeof(real) * (size_t)T * B * n_y);
  for (long k = steps - 1; ok && k >= 0; --k) {
    const real *h_top = hs + (k * L + L - 1) * BH;
    for (int b = 0; b < B; ++b) {  /* the output: y_{k+1} from n_k (and y_k) */
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
      for (int b = 0; b < B; ++b) {
        const real *gh = gh_all + at + (long)b * H;
        act_grad(act, H, kept + at + (long)b * H, gh, ga + (long)b * H);
        if (ly->residual) for (int c = 0; c < H; ++c) gh_all[at - BH + (long)b * H + c] += gh[c];
        real *gb = grads[2 * i + 1];
        for (int c = 0; c < H; ++c) gb[c] += ga[(long)b * H + c];
        for (int j = 0; j < ly->K; ++j) {  /* dL/d(the tap's input) += W_j^T ga */
          const long t = tap_step(ly, j, (int)k);
          const real *Wn = ly->Wn + (long)j * H * ly->C, *Wt = ly->Wt + (long)j * ly->C * H;
          if (i) {
            vecmat(H, H, ga + (long)b * H, Wn, Wt, NULL, 1, gh_all + (t * L + i - 1) * BH + (long)b * H);
          } else {
            vecmat(H, C0, ga + (long)b * H, Wn, Wt, NULL, 0, gin);
            for (int o = 0; o < n_y; ++o) gy_all[(t * B + b) * n_y + o] += gin[o];
          }
        }
      }
      for (int j = 0; j < ly->K; ++j) {  /* dL/dW_j += sum_b input_b^T ga_b */
        const long t = tap_step(ly, j, (int)k);
        real *gW = ly->gWt + (long)j * ly->C * H;
        if (i) {
          outer_sum(B, H, H, hs + (t * L + i - 1) * BH, H, ga, H, gW);
        } else {
          outer_sum(B, n_y, H, ys + t * B * n_y, n_y, ga, H, gW);
          outer_sum(B, n_u, H, un + t * B * n_u, n_u, ga, H, gW + (long)n_y * H);
        }
      }
    }
  }
  if (ok) {
    memcpy(gyn0, gy_all, sizeof(real) * (size_t)B * n_y);
    if (n_z) memcpy(gz0, carry_z, sizeof(real) * (size_t)B * n_z);
    for (int i = 0; i < L; ++i) {
      const layer_t *ly = layers + i;
      for (int h = 0; h < H; ++h)
        for (int c = 0; c < ly->C; ++c)
          for (int j = 0; j < ly->K; ++j)
            grads[2 * i][weight_index(&s, ly, h, c, j)] += ly->gWt[((long)j * ly->C + c) * H + h];
    }
  }
  free_layers(layers, L); free(gy_all); free(gh_all); free(ga); free(gin); free(gn); free(carry_z); free(gz);
  free(dn);
  return ok ? 0 : -1;
}
