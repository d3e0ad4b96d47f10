/* nnfmu FMU core: everything the FMI 2 and FMI 3 entry points share.
 *
 * Hand-written once and reviewed; the model's maths lives in the CasADi-generated model_casadi.c
 * and its sizes, value references, ranges and names in the generated nnfmu_model.h. The core keeps
 * no mutable globals: an instance owns all of its state, so several instances run side by side.
 * It owns the bookkeeping (time, samples, inputs held, the state machine of both interfaces, FMU
 * states, logging); the FMI 2 and FMI 3 files only translate types and call it. One framework for
 * co-simulation and Model Exchange, as in the FMI Reference FMUs: every FMU compiles the same files,
 * an instance knows its interface from nnfmu_instantiate, and the model supplies only its maths
 * (init and step; its ODE, if it has one). The user-level reference is docs/fmu.md; in short:
 *
 * - Time is counted in whole samples from the start time t0: sample k is at t0 + k * Ts. A
 *   communication point counts as reaching a sample instant when it is at most a tolerance before
 *   it; the tolerance is relative to the magnitude of the time (1e-9 of it, at most 1e-3 Ts, never
 *   below 16 rounding units), so no drift accumulates however long the run.
 * - doStep(t, h) accepts any h > 0: it advances every sample instant in (t, t + h]; the outputs are
 *   those of the last sample reached, and a step that reaches none changes nothing. The sample from
 *   t_k to t_k+1 uses the input that was held at t_k (set for the communication step containing t_k),
 *   as a sampled system sees a held input. x0 = init(y0, u0, p) is computed when the first sample is
 *   taken, from the <y>_start parameters and the input at t0; until then the outputs are y0.
 * - A step that would take more than max_samples_per_step samples is refused at once.
 * - Inputs outside their [min, max] give a Warning status (one message per excursion and input),
 *   or an Error without taking the step when input_range_error is true.
 * - Non-finite inputs, parameters or results give an Error; the step is not committed.
 * - Calls the FMI 2.0 / 3.0 state machines do not allow in the current state return an Error, and
 *   any Error puts the instance in the error state (reset, free, get or set an FMU state go on).
 * - An FMU state holds everything above, the mode included: set into a fresh instance, it resumes.
 *   A serialized state carries a checksum, and every field is checked when it is read back; a
 *   refused state is an Error that leaves the instance as it was.
 * - NULL pointer arguments (arrays with a nonzero count included) are an Error with a message.
 *
 * Model Exchange (nnfmu_me.c; docs/fmu-platforms.md), for FMUs of models with an ODE xdot = f(x, u, p),
 * y = g(x, p) (NNFMU_HAS_ODE in nnfmu_model.h; without one, Model Exchange is refused with a message):
 * - The state x is the co-simulation step's: x0 = init(y0, u0, p) is computed when initialization ends,
 *   from the <y>_start parameters and the inputs then; until then the states read as that formula gives.
 * - Modes: after exitInitializationMode the instance is in event mode; enterContinuousTimeMode and
 *   enterEventMode switch. The model has no event indicators, no time events and no discrete states.
 * - Inputs may be set in event and continuous-time mode; tunable parameters in event mode only.
 * - getDerivatives guards the inputs as doStep does: a Warning, and one message per excursion, for an
 *   input outside [min, max] (an Error with input_range_error), an Error for non-finite values.
 * - An event in which an input or a tunable parameter changed reports valuesOfContinuousStatesChanged
 *   once, so that every importer restarts its integrator there (the states themselves keep their values).
 * - Directional derivatives: unknowns are derivatives and outputs, knowns are states and inputs, in
 *   event and continuous-time mode of a Model Exchange instance.
 */
#ifndef NNFMU_CORE_H
#define NNFMU_CORE_H

#include <stddef.h>

#if defined(__GNUC__) && !defined(_WIN32) && !defined(__CYGWIN__)
#define NNFMU_INTERNAL __attribute__((visibility("hidden")))
#else
#define NNFMU_INTERNAL
#endif

/* Same numbers as fmi2Status and fmi3Status. */
typedef enum { NNFMU_OK = 0, NNFMU_WARNING = 1, NNFMU_DISCARD = 2, NNFMU_ERROR = 3, NNFMU_FATAL = 4 } nnfmu_status;

/* The type an importer's getter or setter works on (fmi2Integer/fmi3Int32 and the Booleans). */
typedef enum { NNFMU_INTEGER, NNFMU_BOOLEAN } nnfmu_int_type;

/* The FMI-version-specific wrapper passes a function that forwards one finished message. */
typedef void (*nnfmu_log_sink)(void *env, const char *instance_name, nnfmu_status status,
                               const char *category, const char *message);

typedef struct nnfmu_instance nnfmu_instance;

/* The interface an instance is instantiated for. */
typedef enum { NNFMU_INTERFACE_CS, NNFMU_INTERFACE_ME } nnfmu_interface;

/* Lifecycle. nnfmu_instantiate logs through `sink` and returns NULL on Model Exchange for an FMU without an ODE,
 * a wrong token or no memory; `caller` names the FMI function in those messages. */
NNFMU_INTERNAL nnfmu_instance *nnfmu_instantiate(const char *caller, nnfmu_interface interface_type,
                                                 const char *instance_name, const char *token,
                                                 nnfmu_log_sink sink, void *env, int logging_on);
NNFMU_INTERNAL void nnfmu_free(nnfmu_instance *inst);
NNFMU_INTERNAL void nnfmu_set_logging(nnfmu_instance *inst, int logging_on);
NNFMU_INTERNAL nnfmu_status nnfmu_set_start_time(nnfmu_instance *inst, const char *caller, double start_time);
NNFMU_INTERNAL nnfmu_status nnfmu_enter_initialization(nnfmu_instance *inst, const char *caller);
NNFMU_INTERNAL nnfmu_status nnfmu_exit_initialization(nnfmu_instance *inst, const char *caller);
NNFMU_INTERNAL nnfmu_status nnfmu_terminate(nnfmu_instance *inst, const char *caller);
NNFMU_INTERNAL nnfmu_status nnfmu_reset(nnfmu_instance *inst);

/* Variables, one value reference at a time (the wrappers loop; their VR types differ). A Real variable
 * has nnfmu_real_size(vr) values: 1, or the length of an FMI 3 array (the init window's <c>_past). */
NNFMU_INTERNAL size_t nnfmu_real_size(unsigned long vr);
NNFMU_INTERNAL nnfmu_status nnfmu_get_real(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value);
NNFMU_INTERNAL nnfmu_status nnfmu_set_real(nnfmu_instance *inst, const char *caller, unsigned long vr,
                                           const double *value);
NNFMU_INTERNAL nnfmu_status nnfmu_get_int(nnfmu_instance *inst, const char *caller, nnfmu_int_type type,
                                          unsigned long vr, long long *value);
NNFMU_INTERNAL nnfmu_status nnfmu_set_int(nnfmu_instance *inst, const char *caller, nnfmu_int_type type,
                                          unsigned long vr, long long value);
NNFMU_INTERNAL int nnfmu_is_output(unsigned long vr);

/* Co-simulation step, and the time it reached (the last communication point, in s). */
NNFMU_INTERNAL nnfmu_status nnfmu_do_step(nnfmu_instance *inst, const char *caller, double t, double h);
NNFMU_INTERNAL nnfmu_status nnfmu_last_time(nnfmu_instance *inst, const char *caller, double *time);
NNFMU_INTERNAL double nnfmu_time(const nnfmu_instance *inst);

/* FMU state: an opaque snapshot of the mode, time, inputs, parameters, outputs and model state x. */
NNFMU_INTERNAL nnfmu_status nnfmu_get_state(nnfmu_instance *inst, void **state);
NNFMU_INTERNAL nnfmu_status nnfmu_set_state(nnfmu_instance *inst, const void *state);
/* Frees *state and sets it to NULL. Tolerates the state itself passed instead of its address (fmusim 0.0.39). */
NNFMU_INTERNAL nnfmu_status nnfmu_free_state(nnfmu_instance *inst, const char *caller, void **state);
NNFMU_INTERNAL size_t nnfmu_serialized_size(void);
NNFMU_INTERNAL nnfmu_status nnfmu_serialize(nnfmu_instance *inst, const void *state, unsigned char *bytes, size_t size);
NNFMU_INTERNAL nnfmu_status nnfmu_deserialize(nnfmu_instance *inst, const unsigned char *bytes, size_t size,
                                              void **state);

/* Model Exchange. In an FMU without an ODE each is an Error that says so; directional derivatives also need a
 * Model Exchange instance, and the rest follow the modes of FMI (so on a co-simulation instance of an FMU
 * with an ODE, the states read in initialization mode, and the nominals and the state count always). */
NNFMU_INTERNAL nnfmu_status nnfmu_me_set_time(nnfmu_instance *inst, const char *caller, double time);
NNFMU_INTERNAL nnfmu_status nnfmu_me_set_states(nnfmu_instance *inst, const char *caller, const double *x, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_states(nnfmu_instance *inst, const char *caller, double *x, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_derivatives(nnfmu_instance *inst, const char *caller, double *dx, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_nominals(nnfmu_instance *inst, const char *caller, double *nominals,
                                                  size_t n);
/* The model has no event indicators: n must be 0. */
NNFMU_INTERNAL nnfmu_status nnfmu_me_event_indicators(nnfmu_instance *inst, const char *caller, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_number_of_states(nnfmu_instance *inst, const char *caller, size_t *n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_number_of_event_indicators(nnfmu_instance *inst, const char *caller, size_t *n);
/* What an event iteration tells the importer: the fields of FMI 2's fmi2EventInfo and the outputs of FMI 3's
 * fmi3UpdateDiscreteStates, in the same order (the wrappers only copy them into their own types). */
typedef struct {
  int discrete_states_need_update; /* never: the model has no discrete states */
  int terminate_simulation;
  int nominals_changed;
  /* An input or a tunable parameter changed since the event began (or since the last call), so that the
   * right-hand side jumped and the importer must restart its integrator: valuesOfContinuousStatesChanged, the
   * flag on which importers such as fmusim restart (docs/fmu.md). */
  int values_changed;
  int next_event_time_defined; /* never: no time events */
  double next_event_time;
} nnfmu_event_info;

/* Mode changes: enter event mode, update the (absent) discrete states, enter continuous-time mode. */
NNFMU_INTERNAL nnfmu_status nnfmu_me_enter_event_mode(nnfmu_instance *inst, const char *caller);
NNFMU_INTERNAL nnfmu_status nnfmu_me_update_discrete_states(nnfmu_instance *inst, const char *caller,
                                                            nnfmu_event_info *info);
NNFMU_INTERNAL nnfmu_status nnfmu_me_enter_continuous_time_mode(nnfmu_instance *inst, const char *caller);
/* After an accepted integrator step: the model asks for no event (*enter_event_mode 0) and no end (*terminate 0). */
NNFMU_INTERNAL nnfmu_status nnfmu_me_completed_integrator_step(nnfmu_instance *inst, const char *caller,
                                                               int *enter_event_mode, int *terminate);
/* sensitivity[i] = sum_j d unknowns[i] / d knowns[j] * seed[j] (value references; FMI 2 and 3 both use
 * 32-bit unsigned ones). */
NNFMU_INTERNAL nnfmu_status nnfmu_me_directional_derivative(nnfmu_instance *inst, const char *caller,
                                                            const unsigned int *unknowns, size_t n_unknowns,
                                                            const unsigned int *knowns, size_t n_knowns,
                                                            const double *seed, double *sensitivity);

/* An Error: log it (always) and put the instance in the error state; returns NNFMU_ERROR. */
NNFMU_INTERNAL nnfmu_status nnfmu_error(nnfmu_instance *inst, const char *fmt, ...);
/* NNFMU_OK if `pointer` is not NULL or `count` is 0; else an Error that names the argument `name`. */
NNFMU_INTERNAL nnfmu_status nnfmu_not_null(nnfmu_instance *inst, const char *caller, const char *name,
                                           const void *pointer, size_t count);
/* Log before an instance exists (wrong token, unsupported interface type). */
NNFMU_INTERNAL void nnfmu_log_early(nnfmu_log_sink sink, void *env, const char *instance_name, const char *fmt, ...);

#endif /* NNFMU_CORE_H */
