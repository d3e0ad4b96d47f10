/* nnfmu FMU core: the variables, one table of groups of Real variables with consecutive value references
 * (inputs, outputs, <y>_start, parameters, the init window, and for Model Exchange the continuous states
 * and their derivatives), and the Integer and Boolean parameters. See nnfmu_core.h for the behaviour. */
#include <stddef.h>
#include <string.h>

#include "nnfmu_instance.h"

/* STATE and DERIVATIVE: the ODE's, computed (nnfmu_me.c) and never set through the variables. */
typedef enum { KIND_INPUT, KIND_OUTPUT, KIND_FIXED, KIND_TUNABLE, KIND_STATE, KIND_DERIVATIVE } var_kind;

/* One group of Real variables with consecutive value references: adding an input of init or step
 * (e.g. a window of past samples) is one more row here and one more array in nnfmu_values. */
typedef struct {
  unsigned long first;
  int count;
  var_kind kind;
  size_t offset; /* of the group's array in nnfmu_values (the computed kinds: not read) */
  const char *const *names;
  int size; /* values per value reference: 1, or the length of an FMI 3 array */
} var_group;

static const var_group groups[] = {
  {NNFMU_VR_U, NNFMU_NU, KIND_INPUT, offsetof(nnfmu_values, u), nnfmu_u_names, 1},
  {NNFMU_VR_Y, NNFMU_NY, KIND_OUTPUT, offsetof(nnfmu_values, y), nnfmu_y_names, 1},
  {NNFMU_VR_Y_START, NNFMU_NY, KIND_FIXED, offsetof(nnfmu_values, y_start), nnfmu_y_start_names, 1},
  {NNFMU_VR_P, NNFMU_NP, KIND_TUNABLE, offsetof(nnfmu_values, p), nnfmu_p_names, 1},
  {NNFMU_VR_PAST, NNFMU_N_PAST_VR, KIND_FIXED, offsetof(nnfmu_values, past), nnfmu_past_names, NNFMU_PAST_PER_VR},
  {NNFMU_VR_X, NNFMU_N_STATES, KIND_STATE, offsetof(nnfmu_values, x), nnfmu_x_names, 1},
  {NNFMU_VR_DX, NNFMU_N_STATES, KIND_DERIVATIVE, offsetof(nnfmu_values, x), nnfmu_x_names, 1},
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

/* Model Exchange: the outputs and the derivatives follow from the ODE at the current states, inputs and
 * parameters. An input outside its range was logged; getDerivatives and doStep return the Warning. */
static nnfmu_status get_computed(nnfmu_instance *inst, const char *caller, var_kind kind, int i, double *value) {
  if (kind == KIND_STATE) {
    *value = nnfmu_me_states(inst)[i];
    return NNFMU_OK;
  }
  if (nnfmu_me_evaluate(inst, caller) == NNFMU_ERROR) return NNFMU_ERROR;
  *value = kind == KIND_DERIVATIVE ? inst->ode.xdot[i] : inst->ode.y[i];
  return NNFMU_OK;
}

nnfmu_status nnfmu_get_real(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value) {
  int i, k;
  const var_group *g;
  if (nnfmu_require(inst, caller, READABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (vr == NNFMU_VR_TIME) *value = inst->v.time;
  else if (vr == NNFMU_VR_TS) *value = NNFMU_TS;
  else if ((g = find_group(vr, &i)) == NULL)
    return vr == NNFMU_VR_MAX_SAMPLES || vr == NNFMU_VR_RANGE_ERROR ? wrong_type(inst, caller, vr)
                                                                     : unknown_vr(inst, caller, vr);
  else if (g->kind == KIND_STATE || g->kind == KIND_DERIVATIVE ||
           (g->kind == KIND_OUTPUT && inst->interface_type == NNFMU_INTERFACE_ME))
    return get_computed(inst, caller, g->kind, i, value);
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
  if ((g = find_group(vr, &i)) == NULL)
    return vr == NNFMU_VR_MAX_SAMPLES || vr == NNFMU_VR_RANGE_ERROR ? wrong_type(inst, caller, vr)
                                                                     : unknown_vr(inst, caller, vr);
  if (g->kind == KIND_STATE || g->kind == KIND_DERIVATIVE)
    return nnfmu_error(inst, "%s: %s%s%s is %s and cannot be set; Model Exchange sets the states with "
                       "setContinuousStates, and x0 follows from the <output>_start parameters", caller,
                       g->kind == KIND_STATE ? "" : "der(", g->names[i], g->kind == KIND_STATE ? "" : ")",
                       g->kind == KIND_STATE ? "a continuous state" : "a state derivative");
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
