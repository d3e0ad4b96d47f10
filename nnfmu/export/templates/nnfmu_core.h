/* nnfmu FMU core: everything the FMI 2 and FMI 3 entry points share.
 *
 * Hand-written once and reviewed; the model's maths lives in the CasADi-generated model_casadi.c
 * and its sizes, value references, ranges and names in the generated nnfmu_model.h. The core keeps
 * no mutable globals: an instance owns all of its state, so several instances run side by side.
 * It owns the bookkeeping (time, samples, inputs held, the state machine, FMU states, logging);
 * the FMI 2 and FMI 3 files only translate types and call it. The user-level reference is
 * docs/fmu.md; in short:
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

/* Lifecycle. nnfmu_instantiate logs through `sink` and returns NULL on a wrong token or no memory. */
NNFMU_INTERNAL nnfmu_instance *nnfmu_instantiate(const char *instance_name, const char *token,
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

/* An Error: log it (always) and put the instance in the error state; returns NNFMU_ERROR. */
NNFMU_INTERNAL nnfmu_status nnfmu_error(nnfmu_instance *inst, const char *fmt, ...);
/* NNFMU_OK if `pointer` is not NULL or `count` is 0; else an Error that names the argument `name`. */
NNFMU_INTERNAL nnfmu_status nnfmu_not_null(nnfmu_instance *inst, const char *caller, const char *name,
                                           const void *pointer, size_t count);
/* Log before an instance exists (wrong token, unsupported interface type). */
NNFMU_INTERNAL void nnfmu_log_early(nnfmu_log_sink sink, void *env, const char *instance_name, const char *fmt, ...);

#endif /* NNFMU_CORE_H */
