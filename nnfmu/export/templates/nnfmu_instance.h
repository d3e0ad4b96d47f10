/* nnfmu FMU core, internal: the instance (both interfaces: co-simulation and Model Exchange), the
 * model's ODE as the core calls it, and what the core's files (nnfmu_core.c, nnfmu_variables.c,
 * nnfmu_step.c, nnfmu_state.c, nnfmu_me.c) share. The FMI wrappers never see this header; they talk
 * to the core through nnfmu_core.h. */
#ifndef NNFMU_INSTANCE_H
#define NNFMU_INSTANCE_H

#include "nnfmu_core.h"
#include "nnfmu_model.h"
#include "model_casadi.h"

#define NNFMU_ALLOC(n) ((n) > 0 ? (n) : 1) /* C has no empty arrays */
/* The largest max_samples_per_step: the largest Int32 an importer can set. It bounds every step loop. */
#define NNFMU_MAX_SAMPLES_LIMIT 2147483647LL
/* The continuous states Model Exchange exposes: the model state x if the model has an ODE, else none. */
#define NNFMU_N_STATES (NNFMU_HAS_ODE ? NNFMU_NX : 0)

/* The model's ODE, as the generated model_me_casadi.c provides it in every FMU (CasADi's calling
 * convention; nnfmu_me_model.c compiles it). In FMUs of models without an ODE (NNFMU_HAS_ODE 0 in
 * nnfmu_model.h) every entry is NULL and the core refuses Model Exchange. */
typedef int (*nnfmu_casadi_eval)(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w,
                                 int mem);
typedef int (*nnfmu_casadi_work)(casadi_int *n_arg, casadi_int *n_res, casadi_int *n_iw, casadi_int *n_w);
typedef struct {
  nnfmu_casadi_eval rhs; /* (x, u(, p)) -> (xdot, y): the right-hand side and the outputs */
  nnfmu_casadi_work rhs_work;
  nnfmu_casadi_eval jvp; /* (x, u(, p), dx, du) -> (dxdot, dy): its forward derivative along one seed */
  nnfmu_casadi_work jvp_work;
} nnfmu_ode_code;
NNFMU_INTERNAL extern const nnfmu_ode_code nnfmu_model_ode;

/* The FMI modes as bit flags, so that a call names the set of modes it is allowed in. */
typedef enum {
  MODE_INSTANTIATED = 1,
  MODE_INITIALIZATION = 2,
  MODE_STEP = 4,
  MODE_TERMINATED = 8,
  MODE_ERROR = 16,
  MODE_EVENT = 32,     /* Model Exchange: event mode */
  MODE_CONTINUOUS = 64 /* Model Exchange: continuous-time mode */
} nnfmu_mode;
#define ANY_MODE (MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_STEP | MODE_TERMINATED | MODE_ERROR | MODE_EVENT | \
                  MODE_CONTINUOUS)

/* Everything that changes while simulating: exactly what an FMU state snapshot holds. */
typedef struct {
  nnfmu_mode mode;
  double start_time;  /* t0, s */
  double time;        /* the communication point reached by the last doStep (t0 before any), s */
  long long samples;  /* sample instants t0 + k Ts reached, k = 1 .. samples */
  int x_ready;        /* x holds init(y0, u0, p) or a later state */
  long long max_samples; /* parameter max_samples_per_step */
  int range_error;       /* parameter input_range_error: out-of-range inputs are an Error */
  double u[NNFMU_ALLOC(NNFMU_NU)];        /* inputs as set by the importer */
  double u_sample[NNFMU_ALLOC(NNFMU_NU)]; /* the input held at the instant of the last sample reached */
  unsigned char outside[NNFMU_ALLOC(NNFMU_NU)]; /* input i is in an excursion outside [min, max] */
  double y[NNFMU_ALLOC(NNFMU_NY)]; /* outputs after the last sample (before any: the <y>_start values) */
  double y_start[NNFMU_ALLOC(NNFMU_NY)];
  double p[NNFMU_ALLOC(NNFMU_NP)];
  double past[NNFMU_ALLOC(NNFMU_NPAST)]; /* init window, channel by channel (outputs, then inputs), oldest
                                            sample first; NaN: not set (the rest state y0 / u0 there) */
  double x[NNFMU_ALLOC(NNFMU_NX)];
} nnfmu_values;

/* What Model Exchange evaluates and remembers besides the values (not part of an FMU state: every entry is
 * recomputed from the values, and the event snapshot restarts when an event begins). */
typedef struct {
  double x_init[NNFMU_ALLOC(NNFMU_NX)]; /* init(y0, u, p) until initialization ends */
  double xdot[NNFMU_ALLOC(NNFMU_NX)], y[NNFMU_ALLOC(NNFMU_NY)]; /* the last evaluation of the ODE */
  double dx[NNFMU_ALLOC(NNFMU_NX)], du[NNFMU_ALLOC(NNFMU_NU)];   /* a directional derivative's seed */
  double dxdot[NNFMU_ALLOC(NNFMU_NX)], dy[NNFMU_ALLOC(NNFMU_NY)]; /* and its sensitivity */
  double u_event[NNFMU_ALLOC(NNFMU_NU)], p_event[NNFMU_ALLOC(NNFMU_NP)]; /* as when the event began */
} nnfmu_ode_values;

struct nnfmu_instance {
  char *name;
  nnfmu_interface interface_type; /* given at instantiation: co-simulation or Model Exchange */
  nnfmu_log_sink sink;
  void *env;
  int logging_on;
  nnfmu_values v;
  double xa[NNFMU_ALLOC(NNFMU_NX)], xb[NNFMU_ALLOC(NNFMU_NX)], y_next[NNFMU_ALLOC(NNFMU_NY)]; /* step scratch */
  double y_past[NNFMU_ALLOC(NNFMU_NWIN * NNFMU_NY)], u_past[NNFMU_ALLOC(NNFMU_NWIN * NNFMU_NU)]; /* init's window */
  nnfmu_ode_values ode; /* Model Exchange (nnfmu_me.c); a co-simulation instance reads x0 from x_init too */
  const casadi_real **arg; /* CasADi's work arrays, sized by the generated *_work functions (init, step and */
  casadi_real **res;       /* the ODE's alike: one is evaluated at a time) */
  casadi_int *iw;
  casadi_real *w;
  char message[1024];
};

/* Log a message of any status (Errors and Warnings always, OK only with logging on); returns status. */
NNFMU_INTERNAL nnfmu_status nnfmu_log(nnfmu_instance *inst, nnfmu_status status, const char *fmt, ...);
/* Log an Error but leave the instance as it was (a refused FMU state: the old one stays); returns NNFMU_ERROR. */
NNFMU_INTERNAL nnfmu_status nnfmu_reject(nnfmu_instance *inst, const char *fmt, ...);
/* NNFMU_OK if the instance is in one of `modes`; otherwise an Error that names the mode and the allowed ones. */
NNFMU_INTERNAL nnfmu_status nnfmu_require(nnfmu_instance *inst, const char *caller, int modes);
/* The values of a freshly instantiated (or reset) instance. */
NNFMU_INTERNAL void nnfmu_start_values(nnfmu_values *v);
/* How many sample instants t0 + k Ts (k >= 1) lie at or before time t, as a double (it may be huge). */
NNFMU_INTERNAL double nnfmu_samples_by(const nnfmu_values *v, double t);
/* Inputs and parameters finite (else an Error) and inputs inside [min, max] (else a Warning or an Error). */
NNFMU_INTERNAL nnfmu_status nnfmu_check_inputs(nnfmu_instance *inst, const char *caller, double t);
/* init's window (inst->y_past, inst->u_past) from the parameters <c>_past, NaN (not set) as the rest state:
 * returns the index of an infinite value of the parameters, or -1 (nnfmu_step.c). */
NNFMU_INTERNAL int nnfmu_fill_window(nnfmu_instance *inst, const double *u0);

/* Model Exchange (nnfmu_me.c). The continuous states: x once initialization has ended (or a solver set it),
 * before that init(y0, u, p) with the init window, if any (nnfmu_ode_values.x_init). */
NNFMU_INTERNAL const double *nnfmu_me_states(nnfmu_instance *inst);
/* Evaluate the ODE into inst->ode.xdot and inst->ode.y, the inputs guarded as in doStep: NNFMU_OK, a Warning (an
 * input outside its range) or an Error. */
NNFMU_INTERNAL nnfmu_status nnfmu_me_evaluate(nnfmu_instance *inst, const char *caller);
/* exitInitializationMode of a Model Exchange instance: x = x0, and event mode. */
NNFMU_INTERNAL void nnfmu_me_start(nnfmu_instance *inst);

#endif /* NNFMU_INSTANCE_H */
