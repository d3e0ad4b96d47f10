/* nnfmu FMU core, internal: the instance and what nnfmu_core.c, nnfmu_step.c and nnfmu_state.c share.
 * The FMI wrappers never see this header; they talk to the core through nnfmu_core.h. */
#ifndef NNFMU_INSTANCE_H
#define NNFMU_INSTANCE_H

#include "nnfmu_core.h"
#include "nnfmu_model.h"
#include "model_casadi.h"

#define NNFMU_ALLOC(n) ((n) > 0 ? (n) : 1) /* C has no empty arrays */
/* The largest max_samples_per_step: the largest Int32 an importer can set. It bounds every step loop. */
#define NNFMU_MAX_SAMPLES_LIMIT 2147483647LL

/* The FMI modes as bit flags, so that a call names the set of modes it is allowed in. */
typedef enum {
  MODE_INSTANTIATED = 1,
  MODE_INITIALIZATION = 2,
  MODE_STEP = 4,
  MODE_TERMINATED = 8,
  MODE_ERROR = 16,
  MODE_EVENT = 32,     /* Model Exchange (nnfmu_me.c) */
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

struct nnfmu_instance {
  char *name;
  nnfmu_log_sink sink;
  void *env;
  int logging_on;
  nnfmu_values v;
  double xa[NNFMU_ALLOC(NNFMU_NX)], xb[NNFMU_ALLOC(NNFMU_NX)], y_next[NNFMU_ALLOC(NNFMU_NY)]; /* step scratch */
  double y_past[NNFMU_ALLOC(NNFMU_NWIN * NNFMU_NY)], u_past[NNFMU_ALLOC(NNFMU_NWIN * NNFMU_NU)]; /* init's window */
  const casadi_real **arg; /* CasADi's work arrays, sized by the generated *_work functions */
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  void *me; /* the Model Exchange workspace (nnfmu_me.c) in FMUs of continuous-time models, else NULL */
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

#endif /* NNFMU_INSTANCE_H */
