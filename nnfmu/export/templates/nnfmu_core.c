/* nnfmu FMU core: instance lifecycle, variables, the sampled step loop, FMU states and logging.
 * See nnfmu_core.h for the behaviour. No globals: everything lives in struct nnfmu_instance. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nnfmu_core.h"
#include "nnfmu_model.h"
#include "model_casadi.h"

#define ALLOC(n) ((n) > 0 ? (n) : 1)
#define REL_TOL 1e-9 /* relative tolerance on step sizes and communication points */
#define STATE_MAGIC 0x6e6e666d75737431ULL /* "nnfmust1" */

typedef enum { MODE_INSTANTIATED, MODE_INITIALIZATION, MODE_STEP, MODE_TERMINATED } nnfmu_mode;
static const char *const mode_names[] = {"the instantiated state", "initialization mode", "step mode",
                                         "the terminated state"};

/* Everything that changes while simulating: exactly what an FMU state snapshot holds. */
typedef struct {
  double start_time; /* s */
  long long samples; /* samples advanced since start_time */
  int x_ready;       /* x holds init(y0, u0, p) or a later state */
  double u[ALLOC(NNFMU_NU)];
  double y[ALLOC(NNFMU_NY)]; /* outputs after the last sample (before any: the <y>_start values) */
  double y_start[ALLOC(NNFMU_NY)];
  double p[ALLOC(NNFMU_NP)];
  double x[ALLOC(NNFMU_NX)];
} nnfmu_values;

typedef struct {
  unsigned long long magic;
  nnfmu_values values;
} nnfmu_state;

struct nnfmu_instance {
  char *name;
  nnfmu_log_sink sink;
  void *env;
  int logging_on;
  nnfmu_mode mode;
  nnfmu_values v;
  double xa[ALLOC(NNFMU_NX)], xb[ALLOC(NNFMU_NX)], y_next[ALLOC(NNFMU_NY)]; /* step scratch */
  const casadi_real **arg; /* CasADi's work arrays, sized by the generated *_work functions */
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  char message[1024];
};

static void format_message(char *buffer, size_t size, const char *fmt, va_list args) {
  char *c;
  vsnprintf(buffer, size, fmt, args);
  /* FMI 2 loggers treat the message as a printf format: keep it free of conversions. */
  for (c = buffer; *c; ++c) if (*c == '%') *c = '?';
}

nnfmu_status nnfmu_log(nnfmu_instance *inst, nnfmu_status status, const char *fmt, ...) {
  va_list args;
  if (!inst->sink || (status < NNFMU_ERROR && !inst->logging_on)) return status;
  va_start(args, fmt);
  format_message(inst->message, sizeof inst->message, fmt, args);
  va_end(args);
  inst->sink(inst->env, inst->name, status, status >= NNFMU_ERROR ? "logStatusError" : "logStatusWarning",
             inst->message);
  return status;
}

void nnfmu_log_early(nnfmu_log_sink sink, void *env, const char *instance_name, const char *fmt, ...) {
  char buffer[512];
  va_list args;
  if (!sink) return;
  va_start(args, fmt);
  format_message(buffer, sizeof buffer, fmt, args);
  va_end(args);
  sink(env, instance_name ? instance_name : "", NNFMU_ERROR, "logStatusError", buffer);
}

static int allocate_work(nnfmu_instance *inst) {
  casadi_int n_arg = 0, n_res = 0, n_iw = 0, n_w = 0, a, r, i, w;
  NNFMU_INIT_WORK(&a, &r, &i, &w);
  n_arg = a; n_res = r; n_iw = i; n_w = w;
  NNFMU_STEP_WORK(&a, &r, &i, &w);
  if (a > n_arg) n_arg = a;
  if (r > n_res) n_res = r;
  if (i > n_iw) n_iw = i;
  if (w > n_w) n_w = w;
  inst->arg = (const casadi_real **)calloc((size_t)ALLOC(n_arg), sizeof *inst->arg);
  inst->res = (casadi_real **)calloc((size_t)ALLOC(n_res), sizeof *inst->res);
  inst->iw = (casadi_int *)calloc((size_t)ALLOC(n_iw), sizeof *inst->iw);
  inst->w = (casadi_real *)calloc((size_t)ALLOC(n_w), sizeof *inst->w);
  return inst->arg && inst->res && inst->iw && inst->w;
}

nnfmu_instance *nnfmu_instantiate(const char *instance_name, const char *token, nnfmu_log_sink sink,
                                  void *env, int logging_on) {
  nnfmu_instance *inst;
  const char *name = instance_name ? instance_name : NNFMU_MODEL_IDENTIFIER;
  if (!token || strcmp(token, NNFMU_TOKEN) != 0) {
    nnfmu_log_early(sink, env, name, "instantiate: the instantiation token (GUID) must be %s but was %s; "
                    "the model description and the binary come from different builds", NNFMU_TOKEN,
                    token ? token : "NULL");
    return NULL;
  }
  inst = (nnfmu_instance *)calloc(1, sizeof *inst);
  if (inst) inst->name = (char *)malloc(strlen(name) + 1);
  if (!inst || !inst->name || !allocate_work(inst)) {
    nnfmu_log_early(sink, env, name, "instantiate: out of memory");
    nnfmu_free(inst);
    return NULL;
  }
  strcpy(inst->name, name);
  inst->sink = sink;
  inst->env = env;
  inst->logging_on = logging_on;
  nnfmu_reset(inst);
  return inst;
}

void nnfmu_free(nnfmu_instance *inst) {
  if (!inst) return;
  free(inst->name);
  free((void *)inst->arg);
  free(inst->res);
  free(inst->iw);
  free(inst->w);
  free(inst);
}

void nnfmu_set_logging(nnfmu_instance *inst, int logging_on) { inst->logging_on = logging_on; }

nnfmu_status nnfmu_reset(nnfmu_instance *inst) {
  nnfmu_values *v = &inst->v;
  memset(v, 0, sizeof *v);
  memcpy(v->u, nnfmu_u_start, sizeof v->u);
  memcpy(v->y_start, nnfmu_y_start, sizeof v->y_start);
  memcpy(v->y, nnfmu_y_start, sizeof v->y);
  memcpy(v->p, nnfmu_p_start, sizeof v->p);
  inst->mode = MODE_INSTANTIATED;
  return NNFMU_OK;
}

static nnfmu_status wrong_mode(nnfmu_instance *inst, const char *caller, const char *expected) {
  return nnfmu_log(inst, NNFMU_ERROR, "%s: expected %s but the instance is in %s", caller, expected,
                   mode_names[inst->mode]);
}

nnfmu_status nnfmu_set_start_time(nnfmu_instance *inst, const char *caller, double start_time) {
  if (inst->mode != MODE_INSTANTIATED) return wrong_mode(inst, caller, "the instantiated state");
  if (!isfinite(start_time))
    return nnfmu_log(inst, NNFMU_ERROR, "%s: the start time must be finite but was %g", caller, start_time);
  inst->v.start_time = start_time;
  return NNFMU_OK;
}

nnfmu_status nnfmu_enter_initialization(nnfmu_instance *inst, const char *caller) {
  if (inst->mode != MODE_INSTANTIATED) return wrong_mode(inst, caller, "the instantiated state");
  inst->mode = MODE_INITIALIZATION;
  return NNFMU_OK;
}

nnfmu_status nnfmu_exit_initialization(nnfmu_instance *inst, const char *caller) {
  int i;
  if (inst->mode != MODE_INITIALIZATION) return wrong_mode(inst, caller, "initialization mode");
  for (i = 0; i < NNFMU_NY; ++i)
    if (!isfinite(inst->v.y_start[i]))
      return nnfmu_log(inst, NNFMU_ERROR, "%s: %s_start (the initial output) must be finite but was %g",
                       caller, nnfmu_y_names[i], inst->v.y_start[i]);
  inst->mode = MODE_STEP;
  return NNFMU_OK;
}

nnfmu_status nnfmu_terminate(nnfmu_instance *inst, const char *caller) {
  if (inst->mode != MODE_STEP && inst->mode != MODE_INITIALIZATION)
    return wrong_mode(inst, caller, "step or initialization mode");
  inst->mode = MODE_TERMINATED;
  return NNFMU_OK;
}

double nnfmu_time(const nnfmu_instance *inst) {
  return inst->v.start_time + (double)inst->v.samples * NNFMU_TS;
}

int nnfmu_is_output(unsigned long vr) { return vr >= NNFMU_VR_Y && vr < NNFMU_VR_Y + NNFMU_NY; }

static int in_group(unsigned long vr, unsigned long first, unsigned long n) { return vr >= first && vr < first + n; }

nnfmu_status nnfmu_get(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value) {
  const nnfmu_values *v = &inst->v;
  if (vr == NNFMU_VR_TIME) *value = nnfmu_time(inst);
  else if (vr == NNFMU_VR_TS) *value = NNFMU_TS;
  else if (in_group(vr, NNFMU_VR_U, NNFMU_NU)) *value = v->u[vr - NNFMU_VR_U];
  else if (in_group(vr, NNFMU_VR_Y, NNFMU_NY)) /* until the first sample, the outputs are y0 */
    *value = v->samples ? v->y[vr - NNFMU_VR_Y] : v->y_start[vr - NNFMU_VR_Y];
  else if (in_group(vr, NNFMU_VR_Y_START, NNFMU_NY)) *value = v->y_start[vr - NNFMU_VR_Y_START];
  else if (in_group(vr, NNFMU_VR_P, NNFMU_NP)) *value = v->p[vr - NNFMU_VR_P];
  else return nnfmu_log(inst, NNFMU_ERROR, "%s: unknown value reference %lu; this FMU has value references "
                        "0 to %d", caller, vr, NNFMU_N_VR - 1);
  return NNFMU_OK;
}

nnfmu_status nnfmu_set(nnfmu_instance *inst, const char *caller, unsigned long vr, double value) {
  nnfmu_values *v = &inst->v;
  if (vr == NNFMU_VR_TIME)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: time (value reference 0) is the independent variable and "
                     "cannot be set", caller);
  if (vr == NNFMU_VR_TS)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: Ts (value reference 1) is a constant, Ts = %g s, and cannot be "
                     "set", caller, NNFMU_TS);
  if (in_group(vr, NNFMU_VR_U, NNFMU_NU)) v->u[vr - NNFMU_VR_U] = value;
  else if (in_group(vr, NNFMU_VR_Y, NNFMU_NY))
    return nnfmu_log(inst, NNFMU_ERROR, "%s: %s is an output and cannot be set; set %s_start for the initial "
                     "output", caller, nnfmu_y_names[vr - NNFMU_VR_Y], nnfmu_y_names[vr - NNFMU_VR_Y]);
  else if (in_group(vr, NNFMU_VR_Y_START, NNFMU_NY)) {
    if (inst->mode != MODE_INSTANTIATED && inst->mode != MODE_INITIALIZATION)
      return nnfmu_log(inst, NNFMU_ERROR, "%s: %s_start is a fixed parameter; set it before "
                       "exitInitializationMode, or call reset first", caller, nnfmu_y_names[vr - NNFMU_VR_Y_START]);
    v->y_start[vr - NNFMU_VR_Y_START] = value;
  } else if (in_group(vr, NNFMU_VR_P, NNFMU_NP)) v->p[vr - NNFMU_VR_P] = value;
  else return nnfmu_log(inst, NNFMU_ERROR, "%s: unknown value reference %lu; this FMU has value references "
                        "0 to %d", caller, vr, NNFMU_N_VR - 1);
  return NNFMU_OK;
}

static int first_non_finite(const double *values, int n) {
  int i;
  for (i = 0; i < n; ++i) if (!isfinite(values[i])) return i;
  return -1;
}

/* Inputs and parameters must be finite before they enter the model. */
static nnfmu_status check_inputs(nnfmu_instance *inst, const char *caller) {
  int i = first_non_finite(inst->v.u, NNFMU_NU);
  if (i >= 0)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: input %s must be finite but was %g at t = %.17g s; the step "
                     "was not taken", caller, nnfmu_u_names[i], inst->v.u[i], nnfmu_time(inst));
  i = first_non_finite(inst->v.p, NNFMU_NP);
  if (i >= 0)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: parameter %s must be finite but was %g; the step was not taken",
                     caller, nnfmu_p_names[i], inst->v.p[i]);
  return NNFMU_OK;
}

static int eval_init(nnfmu_instance *inst, double *x0) {
  inst->arg[0] = inst->v.y_start;
  inst->arg[1] = inst->v.u;
#if NNFMU_NP > 0
  inst->arg[2] = inst->v.p;
#endif
  inst->res[0] = x0;
  return NNFMU_INIT(inst->arg, inst->res, inst->iw, inst->w, 0);
}

static int eval_step(nnfmu_instance *inst, const double *x, double *x_next, double *y_next) {
  inst->arg[0] = x;
  inst->arg[1] = inst->v.u;
#if NNFMU_NP > 0
  inst->arg[2] = inst->v.p;
#endif
  inst->res[0] = x_next;
  inst->res[1] = y_next;
  return NNFMU_STEP(inst->arg, inst->res, inst->iw, inst->w, 0);
}

static nnfmu_status check_step_size(nnfmu_instance *inst, const char *caller, double t, double h, long long *n) {
  double now = nnfmu_time(inst), ratio = h / NNFMU_TS;
  *n = (ratio >= 0.5 && ratio < 1e15) ? (long long)floor(ratio + 0.5) : 0; /* also false for NaN */
  if (*n < 1 || fabs(h - (double)*n * NNFMU_TS) > REL_TOL * h)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: Communication step size must be a multiple of Ts = %g s but "
                     "was %.17g s", caller, NNFMU_TS, h);
  if (!(fabs(t - now) <= REL_TOL * fmax(fabs(now), NNFMU_TS)))
    return nnfmu_log(inst, NNFMU_ERROR, "%s: currentCommunicationPoint must be the FMU's time %.17g s (the "
                     "start time plus %lld samples of Ts = %g s) but was %.17g s", caller, now,
                     inst->v.samples, NNFMU_TS, t);
  return NNFMU_OK;
}

/* Advance n samples from the committed state into the scratch buffers; commit only if all is finite. */
nnfmu_status nnfmu_do_step(nnfmu_instance *inst, const char *caller, double t, double h) {
  long long n, k;
  int bad;
  double *current = inst->xa, *next = inst->xb, *swap;
  if (inst->mode != MODE_STEP) return wrong_mode(inst, caller, "step mode (call exitInitializationMode first)");
  if (check_step_size(inst, caller, t, h, &n) != NNFMU_OK || check_inputs(inst, caller) != NNFMU_OK)
    return NNFMU_ERROR;
  if (inst->v.x_ready) memcpy(current, inst->v.x, sizeof inst->v.x);
  else if (eval_init(inst, current) != 0 || first_non_finite(current, NNFMU_NX) >= 0)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: the initial state init(y0, u0) is not finite at t = %.17g s; "
                     "check the <output>_start values and the inputs", caller, t);
  for (k = 0; k < n; ++k) {
    if (eval_step(inst, current, next, inst->y_next) != 0)
      return nnfmu_log(inst, NNFMU_ERROR, "%s: the model's step function failed at t = %.17g s", caller,
                       t + (double)k * NNFMU_TS);
    bad = first_non_finite(inst->y_next, NNFMU_NY);
    if (bad >= 0)
      return nnfmu_log(inst, NNFMU_ERROR, "%s: the model's output %s became %g at t = %.17g s; the step was "
                       "not taken (are the inputs far outside the range the model was made for?)", caller,
                       nnfmu_y_names[bad], inst->y_next[bad], t + (double)(k + 1) * NNFMU_TS);
    swap = current; current = next; next = swap;
  }
  if (first_non_finite(current, NNFMU_NX) >= 0)
    return nnfmu_log(inst, NNFMU_ERROR, "%s: the model's state became non-finite by t = %.17g s; the step was "
                     "not taken", caller, t + h);
  memcpy(inst->v.x, current, sizeof inst->v.x);
  memcpy(inst->v.y, inst->y_next, sizeof inst->v.y);
  inst->v.x_ready = 1;
  inst->v.samples += n;
  return NNFMU_OK;
}

nnfmu_status nnfmu_get_state(nnfmu_instance *inst, void **state) {
  nnfmu_state *s = (nnfmu_state *)(*state ? *state : malloc(sizeof(nnfmu_state)));
  if (!s) return nnfmu_log(inst, NNFMU_ERROR, "getFMUState: out of memory");
  s->magic = STATE_MAGIC;
  s->values = inst->v;
  *state = s;
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_state(nnfmu_instance *inst, const void *state) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  if (!s || s->magic != STATE_MAGIC)
    return nnfmu_log(inst, NNFMU_ERROR, "setFMUState: expected an FMU state of this FMU, got %s",
                     s ? "something else" : "NULL");
  inst->v = s->values;
  return NNFMU_OK;
}

void nnfmu_free_state(void **state) {
  if (state && *state) {
    free(*state);
    *state = NULL;
  }
}

/* Serialized layout: 8-byte magic, 8-byte hash of the instantiation token, then the values. */
static unsigned long long token_hash(void) {
  unsigned long long h = 1469598103934665603ULL; /* FNV-1a */
  const char *c;
  for (c = NNFMU_TOKEN; *c; ++c) h = (h ^ (unsigned char)*c) * 1099511628211ULL;
  return h;
}

size_t nnfmu_serialized_size(void) { return 2 * sizeof(unsigned long long) + sizeof(nnfmu_values); }

nnfmu_status nnfmu_serialize(nnfmu_instance *inst, const void *state, unsigned char *bytes, size_t size) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  unsigned long long header[2];
  if (!s || s->magic != STATE_MAGIC || !bytes || size < nnfmu_serialized_size())
    return nnfmu_log(inst, NNFMU_ERROR, "serializeFMUState: expected a state of this FMU and a buffer of %lu "
                     "bytes, got a buffer of %lu bytes", (unsigned long)nnfmu_serialized_size(), (unsigned long)size);
  header[0] = STATE_MAGIC;
  header[1] = token_hash();
  memcpy(bytes, header, sizeof header);
  memcpy(bytes + sizeof header, &s->values, sizeof s->values);
  return NNFMU_OK;
}

nnfmu_status nnfmu_deserialize(nnfmu_instance *inst, const unsigned char *bytes, size_t size, void **state) {
  unsigned long long header[2];
  nnfmu_state *s;
  if (!bytes || size != nnfmu_serialized_size())
    return nnfmu_log(inst, NNFMU_ERROR, "deserializeFMUState: expected %lu bytes, got %lu",
                     (unsigned long)nnfmu_serialized_size(), (unsigned long)size);
  memcpy(header, bytes, sizeof header);
  if (header[0] != STATE_MAGIC || header[1] != token_hash())
    return nnfmu_log(inst, NNFMU_ERROR, "deserializeFMUState: the bytes are not a serialized state of this FMU "
                     "(%s)", NNFMU_MODEL_IDENTIFIER);
  s = (nnfmu_state *)malloc(sizeof(nnfmu_state)); /* always a new state; *state is untouched on failure */
  if (!s) return nnfmu_log(inst, NNFMU_ERROR, "deserializeFMUState: out of memory");
  s->magic = STATE_MAGIC;
  memcpy(&s->values, bytes + sizeof header, sizeof s->values);
  *state = s;
  return NNFMU_OK;
}
