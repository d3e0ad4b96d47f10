/* nnfmu FMU core: everything the FMI 2 and FMI 3 entry points share.
 *
 * Hand-written once and reviewed; the model's maths lives in the CasADi-generated model_casadi.c
 * and its sizes and value references in the generated nnfmu_model.h. The core keeps no globals:
 * an instance owns all of its state, so several instances run side by side.
 *
 * Behaviour (see nnfmu/export/fmu.py for the user-level description):
 * - doStep(t, h) needs h = n * Ts (n >= 1, relative tolerance 1e-9) and t on the FMU's own time;
 *   it advances n samples with the inputs held. Anything else is an error naming Ts.
 * - The state x0 = init(y0, u0, p) is computed at the first doStep, from the <y>_start parameters
 *   and the inputs set for that first step (importers set inputs right before doStep).
 *   Until then the outputs equal their <y>_start values.
 * - Non-finite inputs, parameters or results give an error status with a message; the instance
 *   then stays at its last good sample (the step is not committed), so it never crashes.
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

/* Variables, one value reference at a time (the wrappers loop; their VR types differ). */
NNFMU_INTERNAL nnfmu_status nnfmu_get(nnfmu_instance *inst, const char *caller, unsigned long vr, double *value);
NNFMU_INTERNAL nnfmu_status nnfmu_set(nnfmu_instance *inst, const char *caller, unsigned long vr, double value);
NNFMU_INTERNAL int nnfmu_is_output(unsigned long vr);

/* Co-simulation step; nnfmu_time is the FMU's time (start time + samples * Ts), in s. */
NNFMU_INTERNAL nnfmu_status nnfmu_do_step(nnfmu_instance *inst, const char *caller, double t, double h);
NNFMU_INTERNAL double nnfmu_time(const nnfmu_instance *inst);

/* FMU state: an opaque snapshot of time, inputs, parameters, outputs and the model state x. */
NNFMU_INTERNAL nnfmu_status nnfmu_get_state(nnfmu_instance *inst, void **state);
NNFMU_INTERNAL nnfmu_status nnfmu_set_state(nnfmu_instance *inst, const void *state);
NNFMU_INTERNAL void nnfmu_free_state(void **state);
NNFMU_INTERNAL size_t nnfmu_serialized_size(void);
NNFMU_INTERNAL nnfmu_status nnfmu_serialize(nnfmu_instance *inst, const void *state, unsigned char *bytes, size_t size);
NNFMU_INTERNAL nnfmu_status nnfmu_deserialize(nnfmu_instance *inst, const unsigned char *bytes, size_t size,
                                              void **state);

/* Log through the instance (errors always; others only with logging on); returns `status`. */
NNFMU_INTERNAL nnfmu_status nnfmu_log(nnfmu_instance *inst, nnfmu_status status, const char *fmt, ...);
/* Log before an instance exists (wrong token, unsupported interface type). */
NNFMU_INTERNAL void nnfmu_log_early(nnfmu_log_sink sink, void *env, const char *instance_name, const char *fmt, ...);

#endif /* NNFMU_CORE_H */
