/* nnfmu FMU core: time in whole samples, the input-range guard and the sampled step loop.
 * See nnfmu_core.h for the behaviour. Uses no function of the C math library. */
#include <float.h>
#include <string.h>

#include "nnfmu_instance.h"

/* A communication point counts as reaching a sample instant at most this far before it: 1e-9 of the
 * magnitude of the time, at most 1e-3 Ts, and never less than 16 rounding units of the time. */
#define TIME_REL_TOL 1e-9
#define TIME_MAX_TOL_TS 1e-3
#define TIME_MIN_TOL_ULPS 16.0

static double magnitude(double a) { return a < 0 ? -a : a; }
static int is_finite(double a) { return a - a == 0.0; }

static double time_tolerance(const nnfmu_values *v, double t) {
  double scale = magnitude(t) > magnitude(v->start_time) ? magnitude(t) : magnitude(v->start_time);
  double tol = TIME_REL_TOL * scale;
  if (tol > TIME_MAX_TOL_TS * NNFMU_TS) tol = TIME_MAX_TOL_TS * NNFMU_TS;
  if (tol < TIME_MIN_TOL_ULPS * DBL_EPSILON * scale) tol = TIME_MIN_TOL_ULPS * DBL_EPSILON * scale;
  return tol;
}

/* The time of sample instant k, s. */
static double instant(const nnfmu_values *v, long long k) { return v->start_time + (double)k * NNFMU_TS; }

double nnfmu_samples_by(const nnfmu_values *v, double t) {
  double r = (t - v->start_time + time_tolerance(v, t)) / NNFMU_TS;
  if (!(r >= 1.0)) return 0.0;
  return r < 4e18 ? (double)(long long)r : r; /* floor; beyond long long it only matters that it is huge */
}

nnfmu_status nnfmu_last_time(nnfmu_instance *inst, const char *caller, double *time) {
  if (nnfmu_require(inst, caller, MODE_STEP | MODE_TERMINATED) != NNFMU_OK) return NNFMU_ERROR;
  *time = inst->v.time;
  return NNFMU_OK;
}

double nnfmu_time(const nnfmu_instance *inst) { return inst->v.time; }

static int first_non_finite(const double *values, int n) {
  int i;
  for (i = 0; i < n; ++i) if (!is_finite(values[i])) return i;
  return -1;
}

/* Inputs and parameters must be finite before they enter the model. */
static nnfmu_status check_finite(nnfmu_instance *inst, const char *caller, double t) {
  int i = first_non_finite(inst->v.u, NNFMU_NU);
  if (i >= 0)
    return nnfmu_error(inst, "%s: input %s must be finite but was %g at t = %.16g s; the step was not taken",
                       caller, nnfmu_u_names[i], inst->v.u[i], t);
  i = first_non_finite(inst->v.p, NNFMU_NP);
  if (i >= 0)
    return nnfmu_error(inst, "%s: parameter %s must be finite but was %g; the step was not taken", caller,
                       nnfmu_p_names[i], inst->v.p[i]);
  return NNFMU_OK;
}

/* What returns the Warning while an input is outside its range, in the words of the interface. */
static const char *warned_calls(const nnfmu_instance *inst) {
  return inst->interface_type == NNFMU_INTERFACE_ME ? "every evaluation of the derivatives" : "every step";
}

/* The valid-range guard: a Warning with one message per excursion and input, or an Error. */
static nnfmu_status check_range(nnfmu_instance *inst, const char *caller, double t) {
  nnfmu_status status = NNFMU_OK;
  int i, outside;
  for (i = 0; i < NNFMU_NU; ++i) {
    double u = inst->v.u[i];
    outside = u < nnfmu_u_min[i] || u > nnfmu_u_max[i];
    if (outside && inst->v.range_error)
      return nnfmu_error(inst, "%s: input %s = %g %s at t = %.16g s is outside its valid range [%g, %g] %s; the "
                         "step was not taken (input_range_error is true; set it to false to compute anyway, "
                         "with a warning)", caller, nnfmu_u_names[i], u, nnfmu_u_units[i], t, nnfmu_u_min[i],
                         nnfmu_u_max[i], nnfmu_u_units[i]);
    if (outside && !inst->v.outside[i])
      nnfmu_log(inst, NNFMU_WARNING, "%s: input %s = %g %s at t = %.16g s leaves its valid range [%g, %g] %s; "
                "the outputs are extrapolated until it returns (one message per excursion; %s "
                "meanwhile returns a warning)", caller, nnfmu_u_names[i], u, nnfmu_u_units[i], t,
                nnfmu_u_min[i], nnfmu_u_max[i], nnfmu_u_units[i], warned_calls(inst));
    inst->v.outside[i] = (unsigned char)outside;
    if (outside) status = NNFMU_WARNING;
  }
  return status;
}

nnfmu_status nnfmu_check_inputs(nnfmu_instance *inst, const char *caller, double t) {
  if (check_finite(inst, caller, t) != NNFMU_OK) return NNFMU_ERROR;
  return check_range(inst, caller, t);
}

/* init's window in CasADi's layout (y_past, u_past: sample by sample, oldest first) from the parameters
 * <c>_past (channel by channel); a sample not set (NaN) is the rest state: y0, or the first input u0.
 * Returns the index of an infinite value of the parameters, or -1. */
int nnfmu_fill_window(nnfmu_instance *inst, const double *u0) {
  int c, j;
  for (c = 0; c < NNFMU_NY + NNFMU_NU; ++c)
    for (j = 0; j < NNFMU_NWIN; ++j) {
      double value = inst->v.past[c * NNFMU_NWIN + j];
      int unset = value != value;
      if (!unset && !is_finite(value)) return c * NNFMU_NWIN + j;
      if (c < NNFMU_NY)
        inst->y_past[j * NNFMU_NY + c] = unset ? inst->v.y_start[c] : value;
      else
        inst->u_past[j * NNFMU_NU + c - NNFMU_NY] = unset ? u0[c - NNFMU_NY] : value;
    }
  return -1;
}

static int eval_init(nnfmu_instance *inst, const double *u0, double *x0) {
  int n = 2;
  inst->arg[0] = inst->v.y_start;
  inst->arg[1] = u0;
#if NNFMU_NP > 0
  inst->arg[n++] = inst->v.p;
#endif
#if NNFMU_NWIN > 0
  inst->arg[n++] = inst->y_past;
  inst->arg[n++] = inst->u_past;
#endif
  (void)n;
  inst->res[0] = x0;
  return NNFMU_INIT(inst->arg, inst->res, inst->iw, inst->w, 0);
}

static int eval_step(nnfmu_instance *inst, const double *x, const double *u, double *x_next, double *y_next) {
  inst->arg[0] = x;
  inst->arg[1] = u;
#if NNFMU_NP > 0
  inst->arg[2] = inst->v.p;
#endif
  inst->res[0] = x_next;
  inst->res[1] = y_next;
  return NNFMU_STEP(inst->arg, inst->res, inst->iw, inst->w, 0);
}

/* Take n >= 1 samples from the committed state into the scratch buffers; the first with `u_first`, the
 * others with the inputs as set. Commit only if every result is finite. */
static nnfmu_status advance(nnfmu_instance *inst, const char *caller, long long n, const double *u_first) {
  nnfmu_values *v = &inst->v;
  double *current = inst->xa, *next = inst->xb, *swap;
  long long k;
  int bad;
  if (!v->x_ready && (bad = nnfmu_fill_window(inst, u_first)) >= 0)
    return nnfmu_error(inst, "%s: sample %d (1 = the oldest) of the init window %s is %g; give finite values, or "
                       "NaN where a sample is not known (the rest state is used there)", caller,
                       bad % NNFMU_ALLOC(NNFMU_NWIN) + 1, /* ALLOC: no constant division by 0 without a window */
                       nnfmu_window_names[bad / NNFMU_ALLOC(NNFMU_NWIN)], v->past[bad]);
  if (v->x_ready) memcpy(current, v->x, sizeof v->x);
  else if (eval_init(inst, u_first, current) != 0 || first_non_finite(current, NNFMU_NX) >= 0)
    return nnfmu_error(inst, "%s: the initial state init(y0, u0) is not finite; check the <output>_start values "
                       "and the inputs at t = %.16g s", caller, v->start_time);
  for (k = 0; k < n; ++k) {
    if (eval_step(inst, current, k == 0 ? u_first : v->u, next, inst->y_next) != 0)
      return nnfmu_error(inst, "%s: the model's step function failed at t = %.16g s; the step was not taken",
                         caller, instant(v, v->samples + k));
    bad = first_non_finite(inst->y_next, NNFMU_NY);
    if (bad >= 0)
      return nnfmu_error(inst, "%s: the model's output %s became %g at t = %.16g s; the step was not taken (are "
                         "the inputs far outside the range the model was made for?)", caller, nnfmu_y_names[bad],
                         inst->y_next[bad], instant(v, v->samples + k + 1));
    swap = current; current = next; next = swap;
  }
  if (first_non_finite(current, NNFMU_NX) >= 0)
    return nnfmu_error(inst, "%s: the model's state became non-finite by t = %.16g s; the step was not taken",
                       caller, instant(v, v->samples + n));
  memcpy(v->x, current, sizeof v->x);
  memcpy(v->y, inst->y_next, sizeof v->y);
  v->x_ready = 1;
  v->samples += n;
  return NNFMU_OK;
}

nnfmu_status nnfmu_do_step(nnfmu_instance *inst, const char *caller, double t, double h) {
  nnfmu_values *v = &inst->v;
  double tol, wanted, target = t + h;
  nnfmu_status guard;
  const double *u_first;
  if (nnfmu_require(inst, caller, MODE_STEP) != NNFMU_OK) return NNFMU_ERROR;
  if (!(h > 0.0) || !is_finite(target))
    return nnfmu_error(inst, "%s: the communication step size must be positive and finite but was %g s", caller, h);
  if (v->samples < 0 || v->max_samples < 1 || v->max_samples > NNFMU_MAX_SAMPLES_LIMIT) /* states are checked */
    return nnfmu_error(inst, "%s: the sample count %lld or max_samples_per_step %lld is corrupt; call reset", caller,
                       v->samples, v->max_samples);
  tol = time_tolerance(v, t);
  if (!(magnitude(t - v->time) <= tol))
    return nnfmu_error(inst, "%s: currentCommunicationPoint must be where the previous step ended, t = %.16g s "
                       "(the start time plus %lld samples of Ts = %g s and what followed), but was %.16g s",
                       caller, v->time, v->samples, NNFMU_TS, t);
  if (TIME_MIN_TOL_ULPS * DBL_EPSILON * magnitude(target) > 0.25 * NNFMU_TS)
    return nnfmu_error(inst, "%s: at t = %g s double precision cannot resolve Ts = %g s; start the simulation "
                       "at a smaller start time", caller, target, NNFMU_TS);
  wanted = nnfmu_samples_by(v, target) - (double)v->samples;
  if (wanted > (double)v->max_samples)
    return nnfmu_error(inst, "%s: the step from t = %.16g s to %.16g s would take %.0f samples of Ts = %g s, more "
                       "than the limit of %lld (parameter max_samples_per_step); take smaller communication "
                       "steps or raise max_samples_per_step", caller, t, target, wanted, NNFMU_TS, v->max_samples);
  if (check_finite(inst, caller, t) != NNFMU_OK) return NNFMU_ERROR;
  guard = check_range(inst, caller, t);
  if (guard == NNFMU_ERROR) return NNFMU_ERROR;
  /* The first sample, from t_k, uses the input held at t_k: this step's if t_k lies in it, else the latched one. */
  u_first = instant(v, v->samples) >= t - tol ? v->u : v->u_sample;
  if (wanted >= 1.0 && advance(inst, caller, (long long)wanted, u_first) != NNFMU_OK) return NNFMU_ERROR;
  if (instant(v, v->samples) >= t - tol) memcpy(v->u_sample, v->u, sizeof v->u);
  v->time = target;
  return guard;
}
