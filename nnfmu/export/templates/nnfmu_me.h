/* nnfmu FMU core, Model Exchange: what the FMI 2 and FMI 3 Model Exchange entry points share.
 *
 * Only in FMUs of continuous-time models (nnfmu_model.h defines NNFMU_MODEL_EXCHANGE). The ODE
 * xdot = f(x, u, p) and the outputs y = g(x, p) come from CasADi (model_me_casadi.c: `me`), and so
 * do the directional derivatives (`jvp`, CasADi's forward mode). The state x is the same as the
 * co-simulation step's: x0 = init(y0, u0, p) is computed when initialization ends, from the
 * <y>_start parameters and the inputs then; until then the states read as that formula gives them.
 *
 * - Modes: after exitInitializationMode the instance is in event mode; enterContinuousTimeMode and
 *   enterEventMode switch. The model has no event indicators, no time events and no discrete states.
 * - Inputs may be set in event and continuous-time mode; tunable parameters in event mode only.
 * - getDerivatives guards the inputs as doStep does: a Warning, and one message per excursion, for an
 *   input outside [min, max] (an Error with input_range_error), an Error for non-finite values.
 * - An event in which an input or a tunable parameter changed reports valuesOfContinuousStatesChanged
 *   once, so that every importer restarts its integrator there (the states themselves keep their values).
 * - Directional derivatives: unknowns are derivatives and outputs, knowns are states and inputs,
 *   in event and continuous-time mode.
 */
#ifndef NNFMU_ME_H
#define NNFMU_ME_H

#include <stddef.h>

#include "nnfmu_core.h"

/* The workspace of an instance of this FMU, either interface (the core calls it; 0 when out of memory). */
NNFMU_INTERNAL int nnfmu_me_enable(nnfmu_instance *inst);
/* Instantiated for Model Exchange: the FMI wrappers call this after instantiating. */
NNFMU_INTERNAL void nnfmu_me_select(nnfmu_instance *inst);
NNFMU_INTERNAL int nnfmu_me_interface(const nnfmu_instance *inst);

NNFMU_INTERNAL nnfmu_status nnfmu_me_set_time(nnfmu_instance *inst, const char *caller, double time);
NNFMU_INTERNAL nnfmu_status nnfmu_me_set_states(nnfmu_instance *inst, const char *caller, const double *x, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_states(nnfmu_instance *inst, const char *caller, double *x, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_derivatives(nnfmu_instance *inst, const char *caller, double *dx, size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_nominals(nnfmu_instance *inst, const char *caller, double *nominals,
                                                  size_t n);
NNFMU_INTERNAL nnfmu_status nnfmu_me_event_indicators(nnfmu_instance *inst, const char *caller, size_t n);
NNFMU_INTERNAL size_t nnfmu_me_number_of_states(void);

/* Mode changes: enter event mode, update the (absent) discrete states, enter continuous-time mode. */
NNFMU_INTERNAL nnfmu_status nnfmu_me_enter_event_mode(nnfmu_instance *inst, const char *caller);
/* *restart: whether an input or a tunable parameter changed since the event began (or since the last call), so
 * that the right-hand side jumped and the importer must restart its integrator: the wrappers report it as
 * valuesOfContinuousStatesChanged, the flag on which importers such as fmusim restart (docs/fmu.md). */
NNFMU_INTERNAL nnfmu_status nnfmu_me_update_discrete_states(nnfmu_instance *inst, const char *caller, int *restart);
NNFMU_INTERNAL nnfmu_status nnfmu_me_enter_continuous_time_mode(nnfmu_instance *inst, const char *caller);
NNFMU_INTERNAL nnfmu_status nnfmu_me_completed_integrator_step(nnfmu_instance *inst, const char *caller);

/* sensitivity[i] = sum_j d unknowns[i] / d knowns[j] * seed[j] (value references; FMI 2 and 3 both use
 * 32-bit unsigned ones). */
NNFMU_INTERNAL nnfmu_status nnfmu_me_directional_derivative(nnfmu_instance *inst, const char *caller,
                                                            const unsigned int *unknowns, size_t n_unknowns,
                                                            const unsigned int *knowns, size_t n_knowns,
                                                            const double *seed, double *sensitivity);

/* Hooks of the core (nnfmu_core.c): the variables this module answers for (states, derivatives, and the
 * outputs of a Model Exchange instance), and the end of initialization. */
NNFMU_INTERNAL int nnfmu_me_owns(const nnfmu_instance *inst, unsigned long vr);
NNFMU_INTERNAL nnfmu_status nnfmu_me_get_real(nnfmu_instance *inst, const char *caller, unsigned long vr,
                                              double *value);
NNFMU_INTERNAL nnfmu_status nnfmu_me_refuse_set(nnfmu_instance *inst, const char *caller, unsigned long vr);
NNFMU_INTERNAL nnfmu_status nnfmu_me_exit_initialization(nnfmu_instance *inst);

#endif /* NNFMU_ME_H */
