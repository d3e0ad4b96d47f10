/* nnfmu FMU core, Model Exchange: the ODE's states, derivatives, outputs, event and continuous-time modes
 * and directional derivatives. See nnfmu_core.h for the behaviour. The ODE's maths come through the
 * generated table nnfmu_model_ode (nnfmu_instance.h); in an FMU without an ODE (NNFMU_HAS_ODE 0) the
 * core never instantiates Model Exchange, and every call here is an Error that says so. Uses no
 * function of the C math library. */
#include <string.h>

#include "nnfmu_instance.h"

#define AFTER_INIT (MODE_EVENT | MODE_CONTINUOUS)
#define STATES_READABLE (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED | MODE_ERROR)

static int is_finite(double a) { return a - a == 0.0; }

/* NNFMU_OK if this FMU has an ODE; else an Error: Model Exchange calls do not apply. */
static nnfmu_status has_ode(nnfmu_instance *inst, const char *caller) {
  if (NNFMU_HAS_ODE) return NNFMU_OK;
  return nnfmu_error(inst, "%s is not supported: this FMU is for co-simulation only (its model has no ODE for "
                     "Model Exchange)", caller);
}

/* has_ode, then the modes that allow the call. */
static nnfmu_status require(nnfmu_instance *inst, const char *caller, int modes) {
  if (has_ode(inst, caller) != NNFMU_OK) return NNFMU_ERROR;
  return nnfmu_require(inst, caller, modes);
}

/* The ODE's arguments x, u(, p) into arg[0 ..]; returns how many. */
static int ode_arguments(nnfmu_instance *inst, const double *x) {
  int n = 0;
  inst->arg[n++] = x;
  inst->arg[n++] = inst->v.u;
  if (NNFMU_NP > 0) inst->arg[n++] = inst->v.p;
  return n;
}

/* The state: x once initialization has ended (or an integrator set it), before that init(y0, u, p), with the
 * init window if any (an infinite window value gives NaN, as a failed init). */
const double *nnfmu_me_states(nnfmu_instance *inst) {
  int n = 2, bad = -1;
  if (inst->v.x_ready) return inst->v.x;
  inst->arg[0] = inst->v.y_start;
  inst->arg[1] = inst->v.u;
  if (NNFMU_NP > 0) inst->arg[n++] = inst->v.p;
#if NNFMU_NWIN > 0
  bad = nnfmu_fill_window(inst, inst->v.u);
  inst->arg[n++] = inst->y_past;
  inst->arg[n++] = inst->u_past;
#endif
  (void)n;
  inst->res[0] = inst->ode.x_init;
  if (bad >= 0 || NNFMU_INIT(inst->arg, inst->res, inst->iw, inst->w, 0) != 0)
    memset(inst->ode.x_init, 0xff, sizeof inst->ode.x_init); /* NaN: reported by the callers' checks */
  return inst->ode.x_init;
}

static int first_non_finite(const double *values, int n) {
  int i;
  for (i = 0; i < n; ++i) if (!is_finite(values[i])) return i;
  return -1;
}

nnfmu_status nnfmu_me_evaluate(nnfmu_instance *inst, const char *caller) {
  nnfmu_ode_values *ode = &inst->ode;
  const double *x = nnfmu_me_states(inst);
  nnfmu_status guard = nnfmu_check_inputs(inst, caller, inst->v.time);
  int bad;
  if (guard == NNFMU_ERROR) return NNFMU_ERROR;
  if ((bad = first_non_finite(x, NNFMU_NX)) >= 0)
    return nnfmu_error(inst, "%s: the state %s is %g at t = %.16g s; check the <output>_start values and the "
                       "inputs, or the states the solver set", caller, nnfmu_x_names[bad], x[bad], inst->v.time);
  ode_arguments(inst, x);
  inst->res[0] = ode->xdot;
  inst->res[1] = ode->y;
  if (nnfmu_model_ode.rhs(inst->arg, inst->res, inst->iw, inst->w, 0) != 0)
    return nnfmu_error(inst, "%s: the model's ODE failed at t = %.16g s", caller, inst->v.time);
  if ((bad = first_non_finite(ode->xdot, NNFMU_NX)) >= 0)
    return nnfmu_error(inst, "%s: the derivative of %s became %g at t = %.16g s (are the inputs far outside the "
                       "range the model was made for?)", caller, nnfmu_x_names[bad], ode->xdot[bad], inst->v.time);
  if ((bad = first_non_finite(ode->y, NNFMU_NY)) >= 0)
    return nnfmu_error(inst, "%s: the output %s became %g at t = %.16g s", caller, nnfmu_y_names[bad], ode->y[bad],
                       inst->v.time);
  return guard;
}

/* Remember the inputs and parameters as they are when an event begins (see nnfmu_me_update_discrete_states). */
static void event_begins(nnfmu_instance *inst) {
  memcpy(inst->ode.u_event, inst->v.u, sizeof inst->v.u);
  memcpy(inst->ode.p_event, inst->v.p, sizeof inst->v.p);
}

void nnfmu_me_start(nnfmu_instance *inst) {
  memcpy(inst->v.x, nnfmu_me_states(inst), sizeof inst->v.x);
  inst->v.x_ready = 1;
  inst->v.mode = MODE_EVENT;
  event_begins(inst);
}

static nnfmu_status check_size(nnfmu_instance *inst, const char *caller, size_t n, size_t expected) {
  if (n == expected) return NNFMU_OK;
  return nnfmu_error(inst, "%s: this FMU has %lu continuous states (event indicators: 0), got n = %lu", caller,
                     (unsigned long)expected, (unsigned long)n);
}

nnfmu_status nnfmu_me_number_of_states(nnfmu_instance *inst, const char *caller, size_t *n) {
  if (has_ode(inst, caller) != NNFMU_OK) return NNFMU_ERROR;
  *n = NNFMU_N_STATES;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_number_of_event_indicators(nnfmu_instance *inst, const char *caller, size_t *n) {
  if (has_ode(inst, caller) != NNFMU_OK) return NNFMU_ERROR;
  *n = 0;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_set_time(nnfmu_instance *inst, const char *caller, double time) {
  if (require(inst, caller, AFTER_INIT) != NNFMU_OK) return NNFMU_ERROR;
  if (!is_finite(time)) return nnfmu_error(inst, "%s: the time must be finite but was %g", caller, time);
  inst->v.time = time;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_set_states(nnfmu_instance *inst, const char *caller, const double *x, size_t n) {
  if (require(inst, caller, AFTER_INIT) != NNFMU_OK || check_size(inst, caller, n, NNFMU_N_STATES) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "x", x, n) != NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(inst->v.x, x, NNFMU_N_STATES * sizeof *x);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_get_states(nnfmu_instance *inst, const char *caller, double *x, size_t n) {
  if (require(inst, caller, STATES_READABLE) != NNFMU_OK || check_size(inst, caller, n, NNFMU_N_STATES) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "x", x, n) != NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(x, nnfmu_me_states(inst), NNFMU_N_STATES * sizeof *x);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_get_derivatives(nnfmu_instance *inst, const char *caller, double *dx, size_t n) {
  nnfmu_status status;
  if (require(inst, caller, STATES_READABLE) != NNFMU_OK || check_size(inst, caller, n, NNFMU_N_STATES) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "derivatives", dx, n) != NNFMU_OK)
    return NNFMU_ERROR;
  status = nnfmu_me_evaluate(inst, caller);
  if (status != NNFMU_ERROR) memcpy(dx, inst->ode.xdot, NNFMU_N_STATES * sizeof *dx);
  return status;
}

nnfmu_status nnfmu_me_get_nominals(nnfmu_instance *inst, const char *caller, double *nominals, size_t n) {
  if (has_ode(inst, caller) != NNFMU_OK || check_size(inst, caller, n, NNFMU_N_STATES) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "nominals", nominals, n) != NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(nominals, nnfmu_x_nominal, NNFMU_N_STATES * sizeof *nominals);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_event_indicators(nnfmu_instance *inst, const char *caller, size_t n) {
  if (require(inst, caller, STATES_READABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (n == 0) return NNFMU_OK;
  return nnfmu_error(inst, "%s: this FMU has no event indicators, got n = %lu", caller, (unsigned long)n);
}

nnfmu_status nnfmu_me_enter_event_mode(nnfmu_instance *inst, const char *caller) {
  if (require(inst, caller, AFTER_INIT) != NNFMU_OK) return NNFMU_ERROR;
  if (inst->v.mode == MODE_CONTINUOUS) event_begins(inst);
  inst->v.mode = MODE_EVENT;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_update_discrete_states(nnfmu_instance *inst, const char *caller, nnfmu_event_info *info) {
  memset(info, 0, sizeof *info); /* no discrete states, no time events, nothing ends the simulation */
  if (require(inst, caller, MODE_EVENT) != NNFMU_OK) return NNFMU_ERROR;
  info->values_changed = memcmp(inst->ode.u_event, inst->v.u, sizeof inst->v.u) != 0 ||
                         memcmp(inst->ode.p_event, inst->v.p, sizeof inst->v.p) != 0;
  event_begins(inst); /* once per change: the next call of the same event iteration reports no restart */
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_enter_continuous_time_mode(nnfmu_instance *inst, const char *caller) {
  if (require(inst, caller, MODE_EVENT) != NNFMU_OK) return NNFMU_ERROR;
  inst->v.mode = MODE_CONTINUOUS;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_completed_integrator_step(nnfmu_instance *inst, const char *caller, int *enter_event_mode,
                                                int *terminate) {
  *enter_event_mode = 0; /* no state events, and the inputs' changes come with the importer's own events */
  *terminate = 0;
  return require(inst, caller, MODE_CONTINUOUS);
}

/* ---- directional derivatives -------------------------------------------------------------- */

static int in_range(unsigned long vr, unsigned long first, int count) {
  return vr >= first && vr < first + (unsigned long)count;
}

static nnfmu_status set_seeds(nnfmu_instance *inst, const char *caller, const unsigned int *knowns, size_t n,
                              const double *seed) {
  nnfmu_ode_values *ode = &inst->ode;
  size_t i;
  memset(ode->dx, 0, sizeof ode->dx);
  memset(ode->du, 0, sizeof ode->du);
  for (i = 0; i < n; ++i) {
    if (in_range(knowns[i], NNFMU_VR_X, NNFMU_N_STATES)) ode->dx[knowns[i] - NNFMU_VR_X] += seed[i];
    else if (in_range(knowns[i], NNFMU_VR_U, NNFMU_NU)) ode->du[knowns[i] - NNFMU_VR_U] += seed[i];
    else return nnfmu_error(inst, "%s: known %lu must be a continuous state (value references %d to %d) or an input "
                            "(%d to %d)", caller, (unsigned long)knowns[i], NNFMU_VR_X, NNFMU_VR_X + NNFMU_N_STATES - 1,
                            NNFMU_VR_U, NNFMU_VR_U + NNFMU_NU - 1);
  }
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_directional_derivative(nnfmu_instance *inst, const char *caller, const unsigned int *unknowns,
                                             size_t n_unknowns, const unsigned int *knowns, size_t n_knowns,
                                             const double *seed, double *sensitivity) {
  nnfmu_ode_values *ode = &inst->ode;
  const double *x;
  size_t i;
  int n;
  if (!NNFMU_HAS_ODE)
    return nnfmu_error(inst, "%s is not supported: this FMU provides no directional derivatives (its model has no "
                       "ODE)", caller);
  if (inst->interface_type != NNFMU_INTERFACE_ME)
    return nnfmu_error(inst, "%s: directional derivatives are provided for Model Exchange only "
                       "(providesDirectionalDerivative is false for co-simulation)", caller);
  if (nnfmu_require(inst, caller, AFTER_INIT) != NNFMU_OK || nnfmu_not_null(inst, caller, "unknowns", unknowns,
      n_unknowns) != NNFMU_OK || nnfmu_not_null(inst, caller, "knowns", knowns, n_knowns) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "seed", seed, n_knowns) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "sensitivity", sensitivity, n_unknowns) != NNFMU_OK)
    return NNFMU_ERROR;
  if (set_seeds(inst, caller, knowns, n_knowns, seed) != NNFMU_OK) return NNFMU_ERROR;
  x = nnfmu_me_states(inst); /* before the arguments: it may evaluate init in the same work arrays */
  n = ode_arguments(inst, x);
  inst->arg[n++] = ode->dx;
  inst->arg[n] = ode->du;
  inst->res[0] = ode->dxdot;
  inst->res[1] = ode->dy;
  if (nnfmu_model_ode.jvp(inst->arg, inst->res, inst->iw, inst->w, 0) != 0)
    return nnfmu_error(inst, "%s: the model's derivative code failed at t = %.16g s", caller, inst->v.time);
  for (i = 0; i < n_unknowns; ++i) {
    if (in_range(unknowns[i], NNFMU_VR_DX, NNFMU_N_STATES)) sensitivity[i] = ode->dxdot[unknowns[i] - NNFMU_VR_DX];
    else if (in_range(unknowns[i], NNFMU_VR_Y, NNFMU_NY)) sensitivity[i] = ode->dy[unknowns[i] - NNFMU_VR_Y];
    else return nnfmu_error(inst, "%s: unknown %lu must be a state derivative (value references %d to %d) or an "
                            "output (%d to %d)", caller, (unsigned long)unknowns[i], NNFMU_VR_DX,
                            NNFMU_VR_DX + NNFMU_N_STATES - 1, NNFMU_VR_Y, NNFMU_VR_Y + NNFMU_NY - 1);
    if (!is_finite(sensitivity[i]))
      return nnfmu_error(inst, "%s: the directional derivative of value reference %lu is %g at t = %.16g s",
                         caller, (unsigned long)unknowns[i], sensitivity[i], inst->v.time);
  }
  return NNFMU_OK;
}
