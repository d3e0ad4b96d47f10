/* Free run of a recurrent step network with output feedback, forward and back-propagation through time.
 *
 * nnfmu/training/compiled_rollout.py compiles this file once per machine (REAL = float and double) and
 * calls it from torch. It computes exactly what RecurrentStepModel.free_run_norm computes with
 * torch.rnn_tanh_cell / rnn_relu_cell / lstm_cell / gru_cell, a linear readout and the optional skip
 * connection, for L stacked layers, without dropout:
 *
 *     x_k = [y_k + e_k, u_k];  h^l_{k+1} = cell_l(input^l, h^l_k);  input^0 = x_k, input^l = h^{l-1}_{k+1}
 *     y_{k+1} = y_k + e_k + skip_scale * (W_o h^{L-1}_{k+1} + b_o)   (skip)   or   W_o h^{L-1}_{k+1} + b_o
 *
 * e_k is the feedback noise of a training (zero without it), drawn by torch as its own loop draws it, one
 * (B, n_y) draw per step, and passed in, so that both compute the same numbers.
 *
 * With a linear path of n_z > 0 states (LinearPathStepModel, nnfmu/models/linear_path.py) the readout above
 * is the network's raw output n_k, and the output is that of a fixed linear model plus a learned correction:
 *
 *     z_{k+1} = A z_k + B u_k + b + G n_k;   y_{k+1} = C z_{k+1} + d + alpha * n_k   (z_0 given)
 *
 * A (n_z, n_z), B (n_z, n_u), b (n_z), C (n_y, n_z), d (n_y) are held fixed; G (n_z, n_y) and alpha (n_y) are
 * trained. The cells see y_k, the total output, as without the path.
 *
 * Why C: torch runs each step as 15-20 small operations (and as many autograd nodes), whose fixed
 * cost of a few microseconds each, not arithmetic, bounds training throughput at the batch sizes
 * used here. One call runs the whole rollout, one call its whole backward pass.
 *
 * Layout: time-major. un (T, B, n_u), yn0 (B, n_y), ys (T, B, n_y) with ys[0] = yn0, noise (T - 1, B, n_y) e_k
 * or NULL.
 * Parameters, in torch's layout, per layer: W_ih (G H, n_in), W_hh (G H, H), b_ih (G H), b_hh (G H);
 * then W_o (n_y, H), b_o (n_y); with a linear path then G (n_z, n_y), alpha (n_y). The path's fixed matrices
 * come separately, lin = {A, B, b, C, d}, row-major. G = 1 (RNN), 4 (LSTM: i, f, g, o), 3 (GRU: r, z, n).
 * For the backward pass the forward pass stores h (and c for the LSTM) of every layer and step,
 * (T, L, B, H), and the activated gates, (T - 1, L, B, S) with S = saved_width(): what torch's autograd
 * keeps too, in less memory; with a linear path also the raw outputs n_k, (T - 1, B, n_y).
 */
#include "rollout_kernels.h"

enum { RNN_TANH = 0, RNN_RELU = 1, LSTM = 2, GRU = 3 };

typedef struct {
  int cell, B, T, n_u, n_y, H, L, G, has_skip;
  real skip;
} shape_t;

typedef struct {                 /* one layer's weights, transposed so that inner loops run over G H */
  int n_in;
  const real *W_ih, *W_hh;       /* torch's layout: (G H, n_in), (G H, H) */
  real *Wt_ih, *Wt_hh;           /* (n_in, G H), (H, G H) */
  const real *b_ih, *b_hh;       /* (G H) */
  real *gWt_ih, *gWt_hh;         /* their gradients, same layout (backward only) */
} layer_t;

static int gates(int cell) { return cell == LSTM ? 4 : cell == GRU ? 3 : 1; }

/* Values per sample, layer and step that the backward pass needs: the activated gates (GRU: r, z, n and
 * W_hn h + b_hn). */
int nnfmu_rollout_saved_width(int cell, int H) { return cell == GRU ? 4 * H : gates(cell) * H; }

static void free_layers(layer_t *layers, int L) {
  if (!layers) return;
  for (int l = 0; l < L; ++l) {
    free(layers[l].Wt_ih); free(layers[l].Wt_hh); free(layers[l].gWt_ih); free(layers[l].gWt_hh);
  }
  free(layers);
}

static layer_t *make_layers(const shape_t *s, const real **params, int with_grads) {
  layer_t *layers = calloc((size_t)s->L, sizeof(layer_t));
  if (!layers) return NULL;
  const int GH = s->G * s->H;
  for (int l = 0; l < s->L; ++l) {
    layer_t *ly = layers + l;
    ly->n_in = l ? s->H : s->n_y + s->n_u;
    ly->Wt_ih = malloc(sizeof(real) * GH * ly->n_in);
    ly->Wt_hh = malloc(sizeof(real) * GH * s->H);
    ly->W_ih = params[4 * l];
    ly->W_hh = params[4 * l + 1];
    ly->b_ih = params[4 * l + 2];
    ly->b_hh = params[4 * l + 3];
    if (with_grads) {
      ly->gWt_ih = calloc((size_t)GH * ly->n_in, sizeof(real));
      ly->gWt_hh = calloc((size_t)GH * s->H, sizeof(real));
    }
    if (!ly->Wt_ih || !ly->Wt_hh || (with_grads && (!ly->gWt_ih || !ly->gWt_hh))) {
      free_layers(layers, s->L);
      return NULL;
    }
    transpose(GH, ly->n_in, params[4 * l], ly->Wt_ih);
    transpose(GH, s->H, params[4 * l + 1], ly->Wt_hh);
  }
  return layers;
}

/* One cell on one sample. gi, gh (G H) receive the activated gates (GRU: r, z, n in gi, W_hn h + b_hn in
 * gh[2H..]), h_new and c_new the new state. */
static void cell_forward(const shape_t *s, const layer_t *ly, const real *x, const real *h, const real *c,
                         real *restrict gi, real *restrict gh, real *h_new, real *c_new) {
  const int H = s->H, GH = s->G * H;
  vecmat(ly->n_in, GH, x, ly->Wt_ih, ly->W_ih, ly->b_ih, 0, gi);
  vecmat(H, GH, h, ly->Wt_hh, ly->W_hh, ly->b_hh, 0, gh);
  if (s->cell == GRU) {
    for (int j = 0; j < 2 * H; ++j) gi[j] = sigmoid(gi[j] + gh[j]);
    for (int j = 0; j < H; ++j) gi[2 * H + j] = TANH(gi[2 * H + j] + gi[j] * gh[2 * H + j]);
    for (int j = 0; j < H; ++j) h_new[j] = gi[2 * H + j] + gi[H + j] * (h[j] - gi[2 * H + j]);
  } else if (s->cell == LSTM) {
    for (int j = 0; j < GH; ++j) gi[j] += gh[j];
    for (int j = 0; j < 2 * H; ++j) gi[j] = sigmoid(gi[j]);
    for (int j = 2 * H; j < 3 * H; ++j) gi[j] = TANH(gi[j]);
    for (int j = 3 * H; j < 4 * H; ++j) gi[j] = sigmoid(gi[j]);
    for (int j = 0; j < H; ++j) {
      c_new[j] = gi[H + j] * c[j] + gi[j] * gi[2 * H + j];
      h_new[j] = gi[3 * H + j] * TANH(c_new[j]);
    }
  } else {
    for (int j = 0; j < H; ++j) {
      const real v = gi[j] + gh[j];
      gi[j] = s->cell == RNN_TANH ? TANH(v) : (v > 0 ? v : 0);
    }
    memcpy(h_new, gi, sizeof(real) * H);
  }
}

/* Gradients of the gate pre-activations (dgi for W_ih and b_ih, dgh for W_hh and b_hh) from dh (and dc)
 * of the cell's outputs, given the saved gates; adds the gradient reaching h (and c) of the previous step
 * to dh_prev (dc_prev). */
static void cell_backward(const shape_t *s, const real *gi, const real *h, const real *c,
                          const real *c_new, const real *dh, const real *dc, real *dgi, real *dgh,
                          real *dh_prev, real *dc_prev) {
  const int H = s->H, GH = s->G * H;
  if (s->cell == GRU) {
    for (int j = 0; j < H; ++j) {
      const real r = gi[j], z = gi[H + j], n = gi[2 * H + j];
      const real dn = dh[j] * ((real)1 - z) * ((real)1 - n * n);
      const real dr = dn * gi[3 * H + j] * r * ((real)1 - r);
      const real dz = dh[j] * (h[j] - n) * z * ((real)1 - z);
      dgi[j] = dgh[j] = dr;
      dgi[H + j] = dgh[H + j] = dz;
      dgi[2 * H + j] = dn;
      dgh[2 * H + j] = dn * r;
      dh_prev[j] += dh[j] * z;
    }
    return;
  }
  if (s->cell == LSTM) {
    for (int j = 0; j < H; ++j) {
      const real i = gi[j], f = gi[H + j], g = gi[2 * H + j], o = gi[3 * H + j], tc = TANH(c_new[j]);
      const real dcj = dc[j] + dh[j] * o * ((real)1 - tc * tc);
      dgi[j] = dcj * g * i * ((real)1 - i);
      dgi[H + j] = dcj * c[j] * f * ((real)1 - f);
      dgi[2 * H + j] = dcj * i * ((real)1 - g * g);
      dgi[3 * H + j] = dh[j] * tc * o * ((real)1 - o);
      dc_prev[j] = dcj * f;
    }
  } else {
    for (int j = 0; j < H; ++j)
      dgi[j] = s->cell == RNN_TANH ? dh[j] * ((real)1 - gi[j] * gi[j]) : (gi[j] > 0 ? dh[j] : 0);
  }
  memcpy(dgh, dgi, sizeof(real) * GH);
}

static void readout(const shape_t *s, const real *Wo, const real *bo, const real *h, const real *y, real *y_next) {
  for (int o = 0; o < s->n_y; ++o) {
    const real acc = bo[o] + dot(s->H, Wo + (long)o * s->H, h);
    y_next[o] = s->has_skip ? y[o] + s->skip * acc : acc;
  }
}

static shape_t make_shape(int cell, int B, int T, int n_u, int n_y, int H, int L, int has_skip, double skip) {
  shape_t s = {cell, B, T, n_u, n_y, H, L, gates(cell), has_skip, (real)skip};
  return s;
}

/* x (n_y + n_u) = [y_k + e_k, u_k] of row b (noise NULL: e_k = 0). */
static void sample(int n_y, int n_u, const real *ys, const real *un, const real *noise, int B, int k, int b, real *x) {
  const long at = ((long)k * B + b) * n_y;
  for (int o = 0; o < n_y; ++o) x[o] = noise ? ys[at + o] + noise[at + o] : ys[at + o];
  memcpy(x + n_y, un + ((long)k * B + b) * n_u, sizeof(real) * n_u);
}

/* The free run. hs, cs (T, L, B, H), saved (T - 1, L, B, S) and ns (T - 1, B, n_y) receive what the backward
 * pass needs; with hs == NULL only two steps are kept (inference). cs is used by the LSTM only. n_z > 0: the
 * linear path (lin, z0 (B, n_z); ns may be NULL for inference); n_z = 0: lin, z0 and ns are unused.
 * Returns 0, or -1 when memory runs out. */
int nnfmu_rollout_forward(int cell, int B, int T, int n_u, int n_y, int H, int L, int has_skip, double skip,
                          const real **params, const real *un, const real *yn0, const real *noise, real *ys,
                          real *hs, real *cs, real *saved, int n_z, const real **lin, const real *z0, real *ns) {
  const shape_t s = make_shape(cell, B, T, n_u, n_y, H, L, has_skip, skip);
  const long LBH = (long)L * B * H;
  const int n0 = n_y + n_u, GH = s.G * H, S = nnfmu_rollout_saved_width(cell, H);
  layer_t *layers = make_layers(&s, params, 0);
  real *gi = malloc(sizeof(real) * GH), *gh = malloc(sizeof(real) * GH), *x = malloc(sizeof(real) * n0);
  real *ring_h = hs ? NULL : calloc((size_t)2 * LBH, sizeof(real));
  real *ring_c = (hs || cell != LSTM) ? NULL : calloc((size_t)2 * LBH, sizeof(real));
  real *ring_z = n_z ? malloc(sizeof(real) * 2 * B * n_z) : NULL, *n_tmp = n_z ? malloc(sizeof(real) * n_y) : NULL;
  const int ok = layers && gi && gh && x && (hs || ring_h) && (hs || cell != LSTM || ring_c) &&
                 (!n_z || (ring_z && n_tmp));
  if (ok) {
    if (n_z) memcpy(ring_z, z0, sizeof(real) * (size_t)B * n_z);
    real *h_all = hs ? hs : ring_h, *c_all = hs ? cs : ring_c;
    memset(h_all, 0, sizeof(real) * LBH);
    if (cell == LSTM) memset(c_all, 0, sizeof(real) * LBH);
    memcpy(ys, yn0, sizeof(real) * (size_t)B * n_y);
    for (int k = 0; k + 1 < T; ++k) {
      const long now = (hs ? (long)k : (long)(k & 1)) * LBH, next = (hs ? (long)k + 1 : (long)((k + 1) & 1)) * LBH;
      for (int b = 0; b < B; ++b) {
        sample(n_y, n_u, ys, un, noise, B, k, b, x);
        const real *y = x, *in = x;  /* y_k + e_k: what the cells see and the skip adds to */
        for (int l = 0; l < L; ++l) {
          const long at = ((long)l * B + b) * H;
          real *c_now = cell == LSTM ? c_all + now + at : NULL, *c_next = cell == LSTM ? c_all + next + at : NULL;
          real *gates_out = saved ? saved + (((long)k * L + l) * B + b) * S : gi;
          cell_forward(&s, layers + l, in, h_all + now + at, c_now, gates_out, gh, h_all + next + at, c_next);
          if (saved && cell == GRU) memcpy(gates_out + 3 * H, gh + 2 * H, sizeof(real) * H);
          in = h_all + next + at;
        }
        real *y_next = ys + ((long)(k + 1) * B + b) * n_y;
        if (!n_z) {
          readout(&s, params[4 * L], params[4 * L + 1], in, y, y_next);
          continue;
        }
        real *n = ns ? ns + ((long)k * B + b) * n_y : n_tmp;
        const real *z = ring_z + ((long)(k & 1) * B + b) * n_z;
        readout(&s, params[4 * L], params[4 * L + 1], in, y, n);
        path_forward(n_z, n_u, n_y, lin, params[4 * L + 2], params[4 * L + 3], z, x + n_y, n,
                     ring_z + ((long)((k + 1) & 1) * B + b) * n_z, y_next);
      }
    }
  }
  free_layers(layers, L); free(gi); free(gh); free(x); free(ring_h); free(ring_c); free(ring_z); free(n_tmp);
  return ok ? 0 : -1;
}

/* Back-propagation through the free run. gys (T, B, n_y): dL/dys. grads: same layout as params, added to
 * (zero them first). gyn0 (B, n_y) receives dL/dyn0, gz0 (B, n_z) dL/dz0 (linear path; unused for n_z = 0).
 * un, ys, hs, cs, saved, ns as left by the forward pass.
 * Each step runs layer by layer over the whole batch, so that the weight gradients of a step are sums
 * over the batch (outer_sum) instead of B separate updates. */
int nnfmu_rollout_backward(int cell, int B, int T, int n_u, int n_y, int H, int L, int has_skip, double skip,
                           const real **params, const real *un, const real *ys, const real *noise, const real *hs,
                           const real *cs, const real *saved, const real *gys, real **grads, real *gyn0, int n_z,
                           const real **lin, const real *ns, real *gz0) {
  const shape_t s = make_shape(cell, B, T, n_u, n_y, H, L, has_skip, skip);
  const long LBH = (long)L * B * H, BH = (long)B * H;
  const int n0 = n_y + n_u, GH = s.G * H, n_max = n0 > H ? n0 : H, S = nnfmu_rollout_saved_width(cell, H);
  const real *Wo = params[4 * L];
  layer_t *layers = make_layers(&s, params, 1);
  real *carry_y = calloc((size_t)B * n_y, sizeof(real));      /* dL/dy_{k+1} through the later steps */
  real *carry_h = calloc((size_t)LBH, sizeof(real));          /* dL/dh^l_{k+1} through the later steps */
  real *carry_c = calloc((size_t)LBH, sizeof(real));          /* dL/dc^l_{k+1} (LSTM) */
  real *dgi = malloc(sizeof(real) * GH * B), *dgh = malloc(sizeof(real) * GH * B);   /* (B, G H) */
  real *dh = malloc(sizeof(real) * BH), *din = malloc(sizeof(real) * n_max * B);      /* (B, H), (B, n_in) */
  real *x = malloc(sizeof(real) * n0 * B), *go = malloc(sizeof(real) * n_y * B);
  real *dc_next = calloc((size_t)H, sizeof(real));
  real *carry_z = n_z ? calloc((size_t)B * n_z, sizeof(real)) : NULL;  /* dL/dz_{k+1} through the later steps */
  real *gz = n_z ? malloc(sizeof(real) * n_z) : NULL, *dn_path = n_z ? malloc(sizeof(real) * B * n_y) : NULL;
  real *dn = n_z ? dn_path : carry_y;  /* dL/dn_k (B, n_y): without the path, dL/dy_{k+1} */
  const int ok = layers && carry_y && carry_h && carry_c && dgi && dgh && dh && din && x && go && dc_next &&
                 (!n_z || (carry_z && gz && dn_path));
  for (int k = T - 2; ok && k >= 0; --k) {
    const real *h_top = hs + (long)(k + 1) * LBH + (long)(L - 1) * BH;
    for (int b = 0; b < B; ++b) {  /* the readout: y_{k+1} = [y_k +] skip * (W_o h + b_o) */
      real *g = go + (long)b * n_y, *cy = carry_y + (long)b * n_y, *dnb = dn + (long)b * n_y;
      for (int o = 0; o < n_y; ++o) cy[o] += gys[((long)(k + 1) * B + b) * n_y + o];  /* now the whole dL/dy_{k+1} */
      if (n_z)
        path_backward(n_z, n_y, lin, params[4 * L + 2], params[4 * L + 3], ns + ((long)k * B + b) * n_y, cy,
                      carry_z + (long)b * n_z, gz, dnb, grads[4 * L + 2], grads[4 * L + 3]);
      for (int o = 0; o < n_y; ++o) {
        g[o] = has_skip ? s.skip * dnb[o] : dnb[o];
        grads[4 * L + 1][o] += g[o];
      }
      memcpy(dh + (long)b * H, carry_h + (long)(L - 1) * BH + (long)b * H, sizeof(real) * H);
      for (int o = 0; o < n_y; ++o)     /* dL/dh += W_o^T g */
        for (int j = 0; j < H; ++j) dh[(long)b * H + j] += g[o] * Wo[(long)o * H + j];
      sample(n_y, n_u, ys, un, noise, B, k, b, x + (long)b * n0);
    }
    outer_sum(B, n_y, H, go, n_y, h_top, H, grads[4 * L]);
    for (int l = L - 1; l >= 0; --l) {
      const layer_t *ly = layers + l;
      const real *in = l ? hs + (long)(k + 1) * LBH + (long)(l - 1) * BH : x;
      const long ld_in = l ? H : n0;
      const real *h = hs + (long)k * LBH + (long)l * BH;
      for (int b = 0; b < B; ++b) {
        const long at = (long)l * BH + (long)b * H;
        real *dh_prev = carry_h + at;     /* becomes dL/dh^l_k */
        if (cell == LSTM) memcpy(dc_next, carry_c + at, sizeof(real) * H);
        memset(dh_prev, 0, sizeof(real) * H);
        cell_backward(&s, saved + (((long)k * L + l) * B + b) * S, h + (long)b * H,
                      cell == LSTM ? cs + (long)k * LBH + at : NULL, cell == LSTM ? cs + (long)(k + 1) * LBH + at : NULL,
                      dh + (long)b * H, dc_next, dgi + (long)b * GH, dgh + (long)b * GH, dh_prev, carry_c + at);
        vecmat(GH, ly->n_in, dgi + (long)b * GH, ly->W_ih, ly->Wt_ih, NULL, 0, din + (long)b * n_max); /* W_ih^T dgi */
        vecmat(GH, H, dgh + (long)b * GH, ly->W_hh, ly->Wt_hh, NULL, 1, dh_prev);                     /* W_hh^T dgh */
        real *gb_ih = grads[4 * l + 2], *gb_hh = grads[4 * l + 3];
        for (int j = 0; j < GH; ++j) { gb_ih[j] += dgi[(long)b * GH + j]; gb_hh[j] += dgh[(long)b * GH + j]; }
      }
      outer_sum(B, ly->n_in, GH, in, ld_in, dgi, GH, ly->gWt_ih);
      outer_sum(B, H, GH, h, H, dgh, GH, ly->gWt_hh);
      if (l)  /* the layer below: its output at k+1 feeds this layer now and itself at the next step */
        for (int b = 0; b < B; ++b)
          for (int j = 0; j < H; ++j) dh[(long)b * H + j] = din[(long)b * n_max + j] + carry_h[(long)(l - 1) * BH + (long)b * H + j];
    }
    for (int b = 0; b < B; ++b)
      for (int o = 0; o < n_y; ++o)
        carry_y[(long)b * n_y + o] = din[(long)b * n_max + o] + (has_skip ? dn[(long)b * n_y + o] : 0);
  }
  if (ok) {
    for (long i = 0; i < (long)B * n_y; ++i) gyn0[i] = gys[i] + carry_y[i];
    if (n_z) memcpy(gz0, carry_z, sizeof(real) * (size_t)B * n_z);
    for (int l = 0; l < L; ++l) {
      const layer_t *ly = layers + l;
      real *g_ih = grads[4 * l], *g_hh = grads[4 * l + 1];
      for (int j = 0; j < GH; ++j) {
        for (int i = 0; i < ly->n_in; ++i) g_ih[(long)j * ly->n_in + i] += ly->gWt_ih[(long)i * GH + j];
        for (int i = 0; i < H; ++i) g_hh[(long)j * H + i] += ly->gWt_hh[(long)i * GH + j];
      }
    }
  }
  free_layers(layers, L); free(carry_y); free(carry_h); free(carry_c); free(dgi); free(dgh);
  free(dh); free(din); free(x); free(go); free(dc_next); free(carry_z); free(gz); free(dn_path);
  return ok ? 0 : -1;
}
