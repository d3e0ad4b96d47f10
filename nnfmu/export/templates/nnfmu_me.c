/* nnfmu FMU core, Model Exchange: the ODE's states, derivatives, outputs and directional derivatives.
 * See nnfmu_me.h for the behaviour. Uses no function of the C math library. */
#include <stdlib.h>
#include <string.h>

#include "nnfmu_instance.h"
#include "nnfmu_me.h"
#include "model_me_casadi.h"

/* The workspace of a Model Exchange instance: one allocation (freed by the core's nnfmu_free). */
typedef struct {
  double x_init[NNFMU_ALLOC(NNFMU_NX)]; /* init(y0, u, p) until initialization ends */
  double xdot[NNFMU_ALLOC(NNFMU_NX)], y[NNFMU_ALLOC(NNFMU_NY)];
  double dx[NNFMU_ALLOC(NNFMU_NX)], du[NNFMU_ALLOC(NNFMU_NU)]; /* seed */
  double dxdot[NNFMU_ALLOC(NNFMU_NX)], dy[NNFMU_ALLOC(NNFMU_NY)]; /* sensitivity */
  double u_event[NNFMU_ALLOC(NNFMU_NU)], p_event[NNFMU_ALLOC(NNFMU_NP)]; /* as when the event began */
  int model_exchange; /* instantiated for Model Exchange (else: co-simulation of the same FMU) */
  double *w;
  casadi_int *iw;
  const casadi_real **arg;
  casadi_real **res;
} me_work;

#define ME(inst) ((me_work *)(inst)->me)
#define AFTER_INIT (MODE_EVENT | MODE_CONTINUOUS)
#define STATES_READABLE (MODE_INITIALIZATION | MODE_EVENT | MODE_CONTINUOUS | MODE_TERMINATED | MODE_ERROR)

static int is_finite(double a) { return a - a == 0.0; }

int nnfmu_me_enable(nnfmu_instance *inst) {
  casadi_int n_arg, n_res, n_iw, n_w, a, r, i, w;
  size_t bytes;
  me_work *me;
  NNFMU_ME_WORK(&a, &r, &i, &w);
  n_arg = a; n_res = r; n_iw = i; n_w = w;
  NNFMU_JVP_WORK(&a, &r, &i, &w);
  if (a > n_arg) n_arg = a;
  if (r > n_res) n_res = r;
  if (i > n_iw) n_iw = i;
  if (w > n_w) n_w = w;
  /* doubles, then casadi_ints, then pointers: each block stays aligned after the struct */
  bytes = sizeof(me_work) + (size_t)NNFMU_ALLOC(n_w) * sizeof(double) + (size_t)NNFMU_ALLOC(n_iw) * sizeof(casadi_int)
          + (size_t)(NNFMU_ALLOC(n_arg) + NNFMU_ALLOC(n_res)) * sizeof(void *);
  me = (me_work *)calloc(1, bytes);
  if (!me) return 0;
  me->w = (double *)(me + 1);
  me->iw = (casadi_int *)(me->w + NNFMU_ALLOC(n_w));
  me->arg = (const casadi_real **)(me->iw + NNFMU_ALLOC(n_iw));
  me->res = (casadi_real **)(me->arg + NNFMU_ALLOC(n_arg));
  inst->me = me;
  return 1;
}

void nnfmu_me_select(nnfmu_instance *inst) { ME(inst)->model_exchange = 1; }

int nnfmu_me_interface(const nnfmu_instance *inst) { return inst->me && ME(inst)->model_exchange; }

/* The state: x once initialization has ended (or an integrator set it), before that init(y0, u, p). */
static const double *state(nnfmu_instance *inst) {
  if (inst->v.x_ready) return inst->v.x;
  inst->arg[0] = inst->v.y_start;
  inst->arg[1] = inst->v.u;
#if NNFMU_NP > 0
  inst->arg[2] = inst->v.p;
#endif
  inst->res[0] = ME(inst)->x_init;
  if (NNFMU_INIT(inst->arg, inst->res, inst->iw, inst->w, 0) != 0)
    memset(ME(inst)->x_init, 0xff, sizeof ME(inst)->x_init); /* NaN: reported by the callers' checks */
  return ME(inst)->x_init;
}

static int first_non_finite(const double *values, int n) {
  int i;
  for (i = 0; i < n; ++i) if (!is_finite(values[i])) return i;
  return -1;
}

/* xdot and y at the current state, inputs and parameters; the inputs guarded as in doStep. */
static nnfmu_status evaluate(nnfmu_instance *inst, const char *caller) {
  me_work *me = ME(inst);
  const double *x = state(inst);
  nnfmu_status guard = nnfmu_check_inputs(inst, caller, inst->v.time);
  int bad;
  if (guard == NNFMU_ERROR) return NNFMU_ERROR;
  if ((bad = first_non_finite(x, NNFMU_NX)) >= 0)
    return nnfmu_error(inst, "%s: the state %s is %g at t = %.16g s; check the <output>_start values and the "
                       "inputs, or the states the solver set", caller, nnfmu_x_names[bad], x[bad], inst->v.time);
  me->arg[0] = x;
  me->arg[1] = inst->v.u;
#if NNFMU_NP > 0
  me->arg[2] = inst->v.p;
#endif
  me->res[0] = me->xdot;
  me->res[1] = me->y;
  if (NNFMU_ME(me->arg, me->res, me->iw, me->w, 0) != 0)
    return nnfmu_error(inst, "%s: the model's ODE failed at t = %.16g s", caller, inst->v.time);
  if ((bad = first_non_finite(me->xdot, NNFMU_NX)) >= 0)
    return nnfmu_error(inst, "%s: the derivative of %s became %g at t = %.16g s (are the inputs far outside the "
                       "range the model was made for?)", caller, nnfmu_x_names[bad], me->xdot[bad], inst->v.time);
  if ((bad = first_non_finite(me->y, NNFMU_NY)) >= 0)
    return nnfmu_error(inst, "%s: the output %s became %g at t = %.16g s", caller, nnfmu_y_names[bad], me->y[bad],
                       inst->v.time);
  return guard;
}

/* Remember the inputs and parameters as they are when an event begins (see nnfmu_me_update_discrete_states). */
static void event_begins(nnfmu_instance *inst) {
  memcpy(ME(inst)->u_event, inst->v.u, sizeof inst->v.u);
  memcpy(ME(inst)->p_event, inst->v.p, sizeof inst->v.p);
}

nnfmu_status nnfmu_me_exit_initialization(nnfmu_instance *inst) {
  memcpy(inst->v.x, state(inst), sizeof inst->v.x);
  inst->v.x_ready = 1;
  inst->v.mode = MODE_EVENT;
  event_begins(inst);
  return NNFMU_OK;
}

static nnfmu_status check_size(nnfmu_instance *inst, const char *caller, size_t n, size_t expected) {
  if (n == expected) return NNFMU_OK;
  return nnfmu_error(inst, "%s: this FMU has %lu continuous states (event indicators: 0), got n = %lu", caller,
                     (unsigned long)expected, (unsigned long)n);
}

size_t nnfmu_me_number_of_states(void) { return NNFMU_NX; }

nnfmu_status nnfmu_me_set_time(nnfmu_instance *inst, const char *caller, double time) {
  if (nnfmu_require(inst, caller, AFTER_INIT) != NNFMU_OK) return NNFMU_ERROR;
  if (!is_finite(time)) return nnfmu_error(inst, "%s: the time must be finite but was %g", caller, time);
  inst->v.time = time;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_set_states(nnfmu_instance *inst, const char *caller, const double *x, size_t n) {
  if (nnfmu_require(inst, caller, AFTER_INIT) != NNFMU_OK || check_size(inst, caller, n, NNFMU_NX) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "x", x, n) != NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(inst->v.x, x, sizeof inst->v.x);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_get_states(nnfmu_instance *inst, const char *caller, double *x, size_t n) {
  if (nnfmu_require(inst, caller, STATES_READABLE) != NNFMU_OK || check_size(inst, caller, n, NNFMU_NX) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "x", x, n) != NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(x, state(inst), NNFMU_NX * sizeof *x);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_get_derivatives(nnfmu_instance *inst, const char *caller, double *dx, size_t n) {
  nnfmu_status status;
  if (nnfmu_require(inst, caller, STATES_READABLE) != NNFMU_OK || check_size(inst, caller, n, NNFMU_NX) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "derivatives", dx, n) != NNFMU_OK)
    return NNFMU_ERROR;
  status = evaluate(inst, caller);
  if (status != NNFMU_ERROR) memcpy(dx, ME(inst)->xdot, NNFMU_NX * sizeof *dx);
  return status;
}

nnfmu_status nnfmu_me_get_nominals(nnfmu_instance *inst, const char *caller, double *nominals, size_t n) {
  if (check_size(inst, caller, n, NNFMU_NX) != NNFMU_OK || nnfmu_not_null(inst, caller, "nominals", nominals, n) !=
      NNFMU_OK)
    return NNFMU_ERROR;
  memcpy(nominals, nnfmu_x_nominal, NNFMU_NX * sizeof *nominals);
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_event_indicators(nnfmu_instance *inst, const char *caller, size_t n) {
  if (nnfmu_require(inst, caller, STATES_READABLE) != NNFMU_OK) return NNFMU_ERROR;
  if (n == 0) return NNFMU_OK;
  return nnfmu_error(inst, "%s: this FMU has no event indicators, got n = %lu", caller, (unsigned long)n);
}

nnfmu_status nnfmu_me_enter_event_mode(nnfmu_instance *inst, const char *caller) {
  if (nnfmu_require(inst, caller, AFTER_INIT) != NNFMU_OK) return NNFMU_ERROR;
  if (inst->v.mode == MODE_CONTINUOUS) event_begins(inst);
  inst->v.mode = MODE_EVENT;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_update_discrete_states(nnfmu_instance *inst, const char *caller, int *restart) {
  me_work *me = ME(inst);
  if (nnfmu_require(inst, caller, MODE_EVENT) != NNFMU_OK) return NNFMU_ERROR; /* no discrete states, time events */
  *restart = memcmp(me->u_event, inst->v.u, sizeof inst->v.u) != 0 ||
             memcmp(me->p_event, inst->v.p, sizeof inst->v.p) != 0;
  event_begins(inst); /* once per change: the next call of the same event iteration reports no restart */
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_enter_continuous_time_mode(nnfmu_instance *inst, const char *caller) {
  if (nnfmu_require(inst, caller, MODE_EVENT) != NNFMU_OK) return NNFMU_ERROR;
  inst->v.mode = MODE_CONTINUOUS;
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_completed_integrator_step(nnfmu_instance *inst, const char *caller) {
  return nnfmu_require(inst, caller, MODE_CONTINUOUS);
}

/* ---- directional derivatives -------------------------------------------------------------- */

static int in_range(unsigned long vr, unsigned long first, int count) {
  return vr >= first && vr < first + (unsigned long)count;
}

static nnfmu_status set_seeds(nnfmu_instance *inst, const char *caller, const unsigned int *knowns, size_t n,
                              const double *seed) {
  me_work *me = ME(inst);
  size_t i;
  memset(me->dx, 0, sizeof me->dx);
  memset(me->du, 0, sizeof me->du);
  for (i = 0; i < n; ++i) {
    if (in_range(knowns[i], NNFMU_VR_X, NNFMU_NX)) me->dx[knowns[i] - NNFMU_VR_X] += seed[i];
    else if (in_range(knowns[i], NNFMU_VR_U, NNFMU_NU)) me->du[knowns[i] - NNFMU_VR_U] += seed[i];
    else return nnfmu_error(inst, "%s: known %lu must be a continuous state (value references %d to %d) or an input "
                            "(%d to %d)", caller, (unsigned long)knowns[i], NNFMU_VR_X, NNFMU_VR_X + NNFMU_NX - 1,
                            NNFMU_VR_U, NNFMU_VR_U + NNFMU_NU - 1);
  }
  return NNFMU_OK;
}

nnfmu_status nnfmu_me_directional_derivative(nnfmu_instance *inst, const char *caller, const unsigned int *unknowns,
                                             size_t n_unknowns, const unsigned int *knowns, size_t n_knowns,
                                             const double *seed, double *sensitivity) {
  me_work *me = ME(inst);
  size_t i;
  if (!me->model_exchange)
    return nnfmu_error(inst, "%s: directional derivatives are provided for Model Exchange only "
                       "(providesDirectionalDerivative is false for co-simulation)", caller);
  if (nnfmu_require(inst, caller, AFTER_INIT) != NNFMU_OK || nnfmu_not_null(inst, caller, "unknowns", unknowns,
      n_unknowns) != NNFMU_OK || nnfmu_not_null(inst, caller, "knowns", knowns, n_knowns) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "seed", seed, n_knowns) != NNFMU_OK ||
      nnfmu_not_null(inst, caller, "sensitivity", sensitivity, n_unknowns) != NNFMU_OK)
    return NNFMU_ERROR;
  if (set_seeds(inst, caller, knowns, n_knowns, seed) != NNFMU_OK) return NNFMU_ERROR;
  me->arg[0] = state(inst);
  me->arg[1] = inst->v.u;
#if NNFMU_NP > 0
  me->arg[2] = inst->v.p;
#endif
  me->arg[2 + (NNFMU_NP > 0)] = me->dx;
  me->arg[3 + (NNFMU_NP > 0)] = me->du;
  me->res[0] = me->dxdot;
  me->res[1] = me->dy;
  if (NNFMU_JVP(me->arg, me->res, me->iw, me->w, 0) != 0)
    return nnfmu_error(inst, "%s: the model's derivative code failed at t = %.16g s", caller, inst->v.time);
  for (i = 0; i < n_unknowns; ++i) {
    if (in_range(unknowns[i], NNFMU_VR_DX, NNFMU_NX)) sensitivity[i] = me->dxdot[unknowns[i] - NNFMU_VR_DX];
    else if (in_range(unknowns[i], NNFMU_VR_Y, NNFMU_NY)) sensitivity[i] = me->dy[unknowns[i] - NNFMU_VR_Y];
    else return nnfmu_error(inst, "%s: unknown %lu must be a state derivative (value references %d to %d) or an "
                            "output (%d to %d)", caller, (unsigned long)unknowns[i], NNFMU_VR_DX,
                            NNFMU_VR_DX + NNFMU_NX - 1, NNFMU_VR_Y, NNFMU_VR_Y + NNFMU_NY - 1);
    if (!is_finite(sensitivity[i]))
      return nnfmu_error(inst, "%s: the directional derivative of value reference %lu is %g at t = %.16g s",
                         caller, (unsigned long)unknowns[i], sensitivity[i], inst->v.time);
  }
  return NNFMU_OK;
}

/* ---- hooks of the core -------------------------------------------------------------------- */

int nnfmu_me_owns(const nnfmu_instance *inst, unsigned long vr) {
  return in_range(vr, NNFMU_VR_X, 2 * NNFMU_NX) || (nnfmu_me_interface(inst) && in_range(vr, NNFMU_VR_Y, NNFMU_NY));
}

nnfmu_status nnfmu_me_get_real(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value) {
  nnfmu_status status;
  if (in_range(vr, NNFMU_VR_X, NNFMU_NX)) {
    *value = state(inst)[vr - NNFMU_VR_X];
    return NNFMU_OK;
  }
  status = evaluate(inst, caller);
  if (status == NNFMU_ERROR) return status;
  *value = in_range(vr, NNFMU_VR_DX, NNFMU_NX) ? ME(inst)->xdot[vr - NNFMU_VR_DX] : ME(inst)->y[vr - NNFMU_VR_Y];
  return NNFMU_OK; /* an input outside its range was logged; getDerivatives and doStep return the Warning */
}

nnfmu_status nnfmu_me_refuse_set(nnfmu_instance *inst, const char *caller, unsigned long vr) {
  int i = (int)((vr - NNFMU_VR_X) % NNFMU_NX);
  return nnfmu_error(inst, "%s: %s%s%s is %s and cannot be set; Model Exchange sets the states with "
                     "setContinuousStates, and x0 follows from the <output>_start parameters", caller,
                     vr < NNFMU_VR_DX ? "" : "der(", nnfmu_x_names[i], vr < NNFMU_VR_DX ? "" : ")",
                     vr < NNFMU_VR_DX ? "a continuous state" : "a state derivative");
}
