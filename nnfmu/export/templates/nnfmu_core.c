/* nnfmu FMU core: the instance's lifecycle, the top of the core that the FMI wrappers call.
 * See nnfmu_core.h for the behaviour. The calls go one way, as in the FMI Reference FMUs: this file calls the
 * Model Exchange code (nnfmu_me.c) when initialization ends; that calls the step code's input checks
 * (nnfmu_step.c); and everything logs and checks modes through nnfmu_log.c, which calls no other file. The
 * variables are in nnfmu_variables.c, FMU states in nnfmu_state.c. */
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "nnfmu_instance.h"
#include "nnfmu_libm.h" /* math.h: NAN */

/* ---- lifecycle ----------------------------------------------------------------------------- */

/* The larger of the work sizes so far and those of a CasADi function (`work` may be NULL: no function). */
static void widen(casadi_int size[4], nnfmu_casadi_work work) {
  casadi_int n[4] = {0, 0, 0, 0};
  int k;
  if (work) work(&n[0], &n[1], &n[2], &n[3]);
  for (k = 0; k < 4; ++k) if (n[k] > size[k]) size[k] = n[k];
}

/* One set of CasADi work arrays for init, step and the ODE (the latter absent without an ODE). */
static int allocate_work(nnfmu_instance *inst) {
  casadi_int size[4] = {0, 0, 0, 0}; /* arg, res, iw, w */
  widen(size, NNFMU_INIT_WORK);
  widen(size, NNFMU_STEP_WORK);
  widen(size, nnfmu_model_ode.rhs_work);
  widen(size, nnfmu_model_ode.jvp_work);
  inst->arg = (const casadi_real **)calloc((size_t)NNFMU_ALLOC(size[0]), sizeof *inst->arg);
  inst->res = (casadi_real **)calloc((size_t)NNFMU_ALLOC(size[1]), sizeof *inst->res);
  inst->iw = (casadi_int *)calloc((size_t)NNFMU_ALLOC(size[2]), sizeof *inst->iw);
  inst->w = (casadi_real *)calloc((size_t)NNFMU_ALLOC(size[3]), sizeof *inst->w);
  return inst->arg && inst->res && inst->iw && inst->w;
}

nnfmu_instance *nnfmu_instantiate(const char *caller, nnfmu_interface interface_type, const char *instance_name,
                                  const char *token, nnfmu_log_sink sink, void *env, int logging_on) {
  nnfmu_instance *inst;
  const char *name = instance_name ? instance_name : NNFMU_MODEL_IDENTIFIER;
  const char *missing_math = nnfmu_libm_missing();
  if (interface_type == NNFMU_INTERFACE_ME && !NNFMU_HAS_ODE) {
    nnfmu_log_early(sink, env, name, "%s: this FMU is for co-simulation only: its model has no ODE for Model "
                    "Exchange", caller);
    return NULL;
  }
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
  if (!inst || !inst->name || !allocate_work(inst)) {
    nnfmu_log_early(sink, env, name, "instantiate: out of memory");
    nnfmu_free(inst);
    return NULL;
  }
  strcpy(inst->name, name);
  inst->interface_type = interface_type;
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
  if (inst->interface_type == NNFMU_INTERFACE_ME) nnfmu_me_start(inst);
  else inst->v.mode = MODE_STEP;
  return NNFMU_OK;
}

nnfmu_status nnfmu_terminate(nnfmu_instance *inst, const char *caller) {
  if (nnfmu_require(inst, caller, MODE_STEP | MODE_EVENT | MODE_CONTINUOUS) != NNFMU_OK) return NNFMU_ERROR;
  inst->v.mode = MODE_TERMINATED;
  return NNFMU_OK;
}
