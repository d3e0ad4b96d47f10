/* nnfmu FMU core: logging, the instance's lifecycle and state machine, and its variables.
 * See nnfmu_core.h for the behaviour; stepping is in nnfmu_step.c, FMU states in nnfmu_state.c. */
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nnfmu_instance.h"
#include "nnfmu_libm.h" /* math.h: NAN */
#ifdef NNFMU_MODEL_EXCHANGE
#include "nnfmu_me.h"
#endif

/* ---- logging ------------------------------------------------------------------------------- */

static void format_message(char *buffer, size_t size, const char *fmt, va_list args) {
  char *c;
  vsnprintf(buffer, size, fmt, args);
  /* FMI 2 loggers treat the message as a printf format: keep it free of conversions. */
  for (c = buffer; *c; ++c) if (*c == '%') *c = '?';
}

static nnfmu_status vlog(nnfmu_instance *inst, nnfmu_status status, const char *fmt, va_list args) {
  static const char *const categories[] = {"logStatusOK", "logStatusWarning", "logStatusDiscard",
                                           "logStatusError", "logStatusFatal"};
  /* Warnings and errors are always reported (FMI: the logger was called when such a status returns). */
  if (!inst->sink || (status == NNFMU_OK && !inst->logging_on)) return status;
  format_message(inst->message, sizeof inst->message, fmt, args);
  inst->sink(inst->env, inst->name, status, categories[status], inst->message);
  return status;
}

nnfmu_status nnfmu_log(nnfmu_instance *inst, nnfmu_status status, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, status, fmt, args);
  va_end(args);
  return status;
}

nnfmu_status nnfmu_error(nnfmu_instance *inst, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, NNFMU_ERROR, fmt, args);
  va_end(args);
  inst->v.mode = MODE_ERROR;
  return NNFMU_ERROR;
}

nnfmu_status nnfmu_reject(nnfmu_instance *inst, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, NNFMU_ERROR, fmt, args);
  va_end(args);
  return NNFMU_ERROR;
}

nnfmu_status nnfmu_not_null(nnfmu_instance *inst, const char *caller, const char *name, const void *pointer,
                            size_t count) {
  if (pointer || count == 0) return NNFMU_OK;
  return nnfmu_error(inst, "%s: argument %s must not be NULL", caller, name);
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

/* ---- the state machine --------------------------------------------------------------------- */

static const char *mode_name(int mode) {
  switch (mode) {
    case MODE_INSTANTIATED: return "the instantiated state";
    case MODE_INITIALIZATION: return "initialization mode";
    case MODE_STEP: return "step mode";
    case MODE_TERMINATED: return "the terminated state";
    case MODE_EVENT: return "event mode";
    case MODE_CONTINUOUS: return "continuous-time mode";
    default: return "the error state (after an error: call reset, or set an FMU state saved before)";
  }
}

nnfmu_status nnfmu_require(nnfmu_instance *inst, const char *caller, int modes) {
  char allowed[200] = "";
  int m;
  if (inst->v.mode & modes) return NNFMU_OK;
  for (m = MODE_INSTANTIATED; m <= MODE_CONTINUOUS; m <<= 1)
    if (modes & m) {
      if (allowed[0]) strcat(allowed, ", ");
      strcat(allowed, m == MODE_ERROR ? "the error state" : mode_name(m));
    }
  return nnfmu_error(inst, "%s is not allowed in %s; FMI allows it in %s", caller, mode_name(inst->v.mode),
                     allowed);
}

/* ---- lifecycle ----------------------------------------------------------------------------- */

static int allocate_work(nnfmu_instance *inst) {
  casadi_int n_arg, n_res, n_iw, n_w, a, r, i, w;
  NNFMU_INIT_WORK(&a, &r, &i, &w);
  n_arg = a; n_res = r; n_iw = i; n_w = w;
  NNFMU_STEP_WORK(&a, &r, &i, &w);
  if (a > n_arg) n_arg = a;
  if (r > n_res) n_res = r;
  if (i > n_iw) n_iw = i;
  if (w > n_w) n_w = w;
  inst->arg = (const casadi_real **)calloc((size_t)NNFMU_ALLOC(n_arg), sizeof *inst->arg);
  inst->res = (casadi_real **)calloc((size_t)NNFMU_ALLOC(n_res), sizeof *inst->res);
  inst->iw = (casadi_int *)calloc((size_t)NNFMU_ALLOC(n_iw), sizeof *inst->iw);
  inst->w = (casadi_real *)calloc((size_t)NNFMU_ALLOC(n_w), sizeof *inst->w);
  return inst->arg && inst->res && inst->iw && inst->w;
}

/* FMUs of continuous-time models: every instance, of either interface, gets the ODE's workspace. */
static int allocate_model_exchange(nnfmu_instance *inst) {
#ifdef NNFMU_MODEL_EXCHANGE
  return nnfmu_me_enable(inst);
#else
  (void)inst;
  return 1;
#endif
}

nnfmu_instance *nnfmu_instantiate(const char *instance_name, const char *token, nnfmu_log_sink sink,
                                  void *env, int logging_on) {
  nnfmu_instance *inst;
  const char *name = instance_name ? instance_name : NNFMU_MODEL_IDENTIFIER;
  const char *missing_math = nnfmu_libm_missing();
  if (!token || strcmp(token, NNFMU_TOKEN) != 0) {
    nnfmu_log_early(sink, env, name, "instantiate: the instantiation token (GUID) must be %s but was %s; "
                    "the model description and the binary come from different builds", NNFMU_TOKEN,
                    token ? token : "NULL");
    return NULL;
  }
  if (missing_math) {
    nnfmu_log_early(sink, env, name, "instantiate: %s", missing_math);
    return NULL;
  }
  inst = (nnfmu_instance *)calloc(1, sizeof *inst);
  if (inst) inst->name = (char *)malloc(strlen(name) + 1);
  if (!inst || !inst->name || !allocate_work(inst) || !allocate_model_exchange(inst)) {
    nnfmu_log_early(sink, env, name, "instantiate: out of memory");
    nnfmu_free(inst);
    return NULL;
  }
  strcpy(inst->name, name);
  inst->sink = sink;
  inst->env = env;
  inst->logging_on = logging_on;
  nnfmu_start_values(&inst->v);
  return inst;
}

void nnfmu_free(nnfmu_instance *inst) {
  if (!inst) return;
  free(inst->name);
  free((void *)inst->arg);
  free(inst->res);
  free(inst->iw);
  free(inst->w);
  free(inst->me);
  free(inst);
}

void nnfmu_set_logging(nnfmu_instance *inst, int logging_on) { inst->logging_on = logging_on; }

void nnfmu_start_values(nnfmu_values *v) {
  int i;
  memset(v, 0, sizeof *v);
  v->mode = MODE_INSTANTIATED;
  v->max_samples = NNFMU_MAX_SAMPLES_DEFAULT;
  memcpy(v->u, nnfmu_u_start, sizeof v->u);
  memcpy(v->y_start, nnfmu_y_start, sizeof v->y_start);
  memcpy(v->y, nnfmu_y_start, sizeof v->y);
  memcpy(v->p, nnfmu_p_start, sizeof v->p);
  for (i = 0; i < NNFMU_NPAST; ++i) v->past[i] = NAN; /* the init window: not set */
}

nnfmu_status nnfmu_reset(nnfmu_instance *inst) {
  nnfmu_start_values(&inst->v);
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_start_time(nnfmu_instance *inst, const char *caller, double start_time) {
  if (nnfmu_require(inst, caller, MODE_INSTANTIATED) != NNFMU_OK) return NNFMU_ERROR;
  if (!(start_time - start_time == 0.0)) /* NaN or infinite */
    return nnfmu_error(inst, "%s: the start time must be finite but was %g", caller, start_time);
  inst->v.start_time = inst->v.time = start_time;
  return NNFMU_OK;
}

nnfmu_status nnfmu_enter_initialization(nnfmu_instance *inst, const char *caller) {
  if (nnfmu_require(inst, caller, MODE_INSTANTIATED) != NNFMU_OK) return NNFMU_ERROR;
  inst->v.mode = MODE_INITIALIZATION;
  return NNFMU_OK;
}

nnfmu_status nnfmu_exit_initialization(nnfmu_instance *inst, const char *caller) {
  int i;
  if (nnfmu_require(inst, caller, MODE_INITIALIZATION) != NNFMU_OK) return NNFMU_ERROR;
  for (i = 0; i < NNFMU_NY; ++i)
    if (!(inst->v.y_start[i] - inst->v.y_start[i] == 0.0))
      return nnfmu_error(inst, "%s: %s (the initial output) must be finite but was %g", caller,
                         nnfmu_y_start_names[i], inst->v.y_start[i]);
#ifdef NNFMU_MODEL_EXCHANGE
  if (nnfmu_me_interface(inst)) return nnfmu_me_exit_initialization(inst);
#endif
  inst->v.mode = MODE_STEP;
  return NNFMU_OK;
}

nnfmu_status nnfmu_terminate(nnfmu_instance *inst, const char *caller) {
  if (nnfmu_require(inst, caller, MODE_STEP | MODE_EVENT | MODE_CONTINUOUS) != NNFMU_OK) return NNFMU_ERROR;
  inst->v.mode = MODE_TERMINATED;
  return NNFMU_OK;
}

/* ---- variables ----------------------------------------------------------------------------- */

typedef enum { KIND_INPUT, KIND_OUTPUT, KIND_FIXED, KIND_TUNABLE } var_kind;

/* One group of Real variables with consecutive value references: adding an input of init or step
 * (e.g. a window of past samples) is one more row here and one more array in nnfmu_values. */
typedef struct {
  unsigned long first;
  int count;
  var_kind kind;
  size_t offset; /* of the group's array in nnfmu_values */
  const char *const *names;
  int size; /* values per value reference: 1, or the length of an FMI 3 array */
} var_group;

static const var_group groups[] = {
  {NNFMU_VR_U, NNFMU_NU, KIND_INPUT, offsetof(nnfmu_values, u), nnfmu_u_names, 1},
  {NNFMU_VR_Y, NNFMU_NY, KIND_OUTPUT, offsetof(nnfmu_values, y), nnfmu_y_names, 1},
  {NNFMU_VR_Y_START, NNFMU_NY, KIND_FIXED, offsetof(nnfmu_values, y_start), nnfmu_y_start_names, 1},
  {NNFMU_VR_P, NNFMU_NP, KIND_TUNABLE, offsetof(nnfmu_values, p), nnfmu_p_names, 1},
  {NNFMU_VR_PAST, NNFMU_N_PAST_VR, KIND_FIXED, offsetof(nnfmu_values, past), nnfmu_past_names, NNFMU_PAST_PER_VR},
};

#define READABLE (MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED | MODE_ERROR | MODE_EVENT | MODE_CONTINUOUS)
#define TUNABLE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_EVENT | MODE_CONTINUOUS)
#define FIXED (MODE_INSTANTIATED | MODE_INITIALIZATION)

static const var_group *find_group(unsigned long vr, int *index) {
  size_t g;
  for (g = 0; g < sizeof groups / sizeof groups[0]; ++g)
    if (vr >= groups[g].first && vr < groups[g].first + (unsigned long)groups[g].count) {
      *index = (int)(vr - groups[g].first);
      return &groups[g];
    }
  return NULL;
}

static double *group_values(nnfmu_values *v, const var_group *g) { return (double *)((char *)v + g->offset); }

int nnfmu_is_output(unsigned long vr) { return vr >= NNFMU_VR_Y && vr < NNFMU_VR_Y + NNFMU_NY; }

size_t nnfmu_real_size(unsigned long vr) {
  int i;
  const var_group *g = find_group(vr, &i);
  return g ? (size_t)g->size : 1;
}

static nnfmu_status unknown_vr(nnfmu_instance *inst, const char *caller, unsigned long vr) {
  return nnfmu_error(inst, "%s: unknown value reference %lu; this FMU has value references 0 to %d", caller,
                     vr, NNFMU_N_VR - 1);
}

/* Model Exchange: parameters change in event mode only, where the importer restarts its solver. */
static nnfmu_status parameter_in_continuous_time(nnfmu_instance *inst, const char *caller) {
  return nnfmu_error(inst, "%s: parameters can be set in event mode but not in continuous-time mode; call "
                     "enterEventMode first", caller);
}

static nnfmu_status wrong_type(nnfmu_instance *inst, const char *caller, unsigned long vr) {
  const char *what = vr == NNFMU_VR_MAX_SAMPLES ? "max_samples_per_step is an Integer (FMI 3: Int32)"
                     : vr == NNFMU_VR_RANGE_ERROR ? "input_range_error is a Boolean"
                                                  : "it is a Real (FMI 3: Float64)";
  return nnfmu_error(inst, "%s: value reference %lu has another type: %s", caller, vr, what);
}

nnfmu_status nnfmu_get_real(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value) {
  int i, k;
  const var_group *g;
  if (nnfmu_require(inst, caller, READABLE) != NNFMU_OK) return NNFMU_ERROR;
#ifdef NNFMU_MODEL_EXCHANGE
  if (nnfmu_me_owns(inst, vr)) return nnfmu_me_get_real(inst, caller, vr, value);
#endif
  if (vr == NNFMU_VR_TIME) *value = inst->v.time;
  else if (vr == NNFMU_VR_TS) *value = NNFMU_TS;
  else if ((g = find_group(vr, &i)) == NULL)
    return vr == NNFMU_VR_MAX_SAMPLES || vr == NNFMU_VR_RANGE_ERROR ? wrong_type(inst, caller, vr)
                                                                     : unknown_vr(inst, caller, vr);
  else if (g->kind == KIND_OUTPUT && inst->v.samples == 0) *value = inst->v.y_start[i]; /* y(t0) = y0 */
  else for (k = 0; k < g->size; ++k) value[k] = group_values(&inst->v, g)[i * g->size + k];
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_real(nnfmu_instance *inst, const char *caller, unsigned long vr, const double *value) {
  int i, k;
  const var_group *g;
  if (nnfmu_require(inst, caller, TUNABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (vr == NNFMU_VR_TIME)
    return nnfmu_error(inst, "%s: time (value reference 0) is the independent variable and cannot be set", caller);
  if (vr == NNFMU_VR_TS)
    return nnfmu_error(inst, "%s: Ts (value reference 1) is a constant, Ts = %g s, and cannot be set", caller,
                       NNFMU_TS);
#ifdef NNFMU_MODEL_EXCHANGE
  if (nnfmu_me_owns(inst, vr) && !nnfmu_is_output(vr)) return nnfmu_me_refuse_set(inst, caller, vr);
#endif
  if ((g = find_group(vr, &i)) == NULL)
    return vr == NNFMU_VR_MAX_SAMPLES || vr == NNFMU_VR_RANGE_ERROR ? wrong_type(inst, caller, vr)
                                                                     : unknown_vr(inst, caller, vr);
  if (g->kind == KIND_OUTPUT)
    return nnfmu_error(inst, "%s: %s is an output and cannot be set; set %s for the initial output", caller,
                       g->names[i], nnfmu_y_start_names[i]);
  if (g->kind == KIND_FIXED && !(inst->v.mode & FIXED))
    return nnfmu_error(inst, "%s: %s is a fixed parameter; set it before exitInitializationMode, or call reset "
                       "first", caller, g->names[i]);
  if (g->kind == KIND_TUNABLE && inst->v.mode == MODE_CONTINUOUS) return parameter_in_continuous_time(inst, caller);
  for (k = 0; k < g->size; ++k) group_values(&inst->v, g)[i * g->size + k] = value[k];
  return NNFMU_OK;
}

nnfmu_status nnfmu_get_int(nnfmu_instance *inst, const char *caller, nnfmu_int_type type, unsigned long vr,
                           long long *value) {
  if (nnfmu_require(inst, caller, READABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (type == NNFMU_INTEGER && vr == NNFMU_VR_MAX_SAMPLES) *value = inst->v.max_samples;
  else if (type == NNFMU_BOOLEAN && vr == NNFMU_VR_RANGE_ERROR) *value = inst->v.range_error;
  else return vr < NNFMU_N_VR ? wrong_type(inst, caller, vr) : unknown_vr(inst, caller, vr);
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_int(nnfmu_instance *inst, const char *caller, nnfmu_int_type type, unsigned long vr,
                           long long value) {
  if (nnfmu_require(inst, caller, TUNABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (inst->v.mode == MODE_CONTINUOUS) return parameter_in_continuous_time(inst, caller);
  if (type == NNFMU_INTEGER && vr == NNFMU_VR_MAX_SAMPLES) {
    if (value < 1)
      return nnfmu_error(inst, "%s: max_samples_per_step must be at least 1 but was %lld", caller, value);
    inst->v.max_samples = value;
  } else if (type == NNFMU_BOOLEAN && vr == NNFMU_VR_RANGE_ERROR) {
    inst->v.range_error = value != 0;
  } else {
    return vr < NNFMU_N_VR ? wrong_type(inst, caller, vr) : unknown_vr(inst, caller, vr);
  }
  return NNFMU_OK;
}
