/* nnfmu FMI 2.0 Model Exchange entry points, in every FMU, over the core's Model Exchange part
 * (nnfmu_core.h, nnfmu_me.c), and fmi2GetDirectionalDerivative. In an FMU without an ODE, fmi2Instantiate
 * (nnfmu_fmi2.c) refuses fmi2ModelExchange and each of these is an Error that says why. */
#include <stddef.h>

#include "nnfmu_fmi2.h"

fmi2Status fmi2EnterEventMode(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_enter_event_mode(INSTANCE, "fmi2EnterEventMode");
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
  nnfmu_event_info info;
  CHECK_INSTANCE();
  NOT_NULL("fmi2NewDiscreteStates", eventInfo, 1);
  if (nnfmu_me_update_discrete_states(INSTANCE, "fmi2NewDiscreteStates", &info) != NNFMU_OK) return fmi2Error;
  eventInfo->newDiscreteStatesNeeded = info.discrete_states_need_update ? fmi2True : fmi2False;
  eventInfo->terminateSimulation = info.terminate_simulation ? fmi2True : fmi2False;
  eventInfo->nominalsOfContinuousStatesChanged = info.nominals_changed ? fmi2True : fmi2False;
  eventInfo->valuesOfContinuousStatesChanged = info.values_changed ? fmi2True : fmi2False;
  eventInfo->nextEventTimeDefined = info.next_event_time_defined ? fmi2True : fmi2False;
  eventInfo->nextEventTime = info.next_event_time;
  return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_enter_continuous_time_mode(INSTANCE, "fmi2EnterContinuousTimeMode");
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK_INSTANCE();
  NOT_NULL("fmi2CompletedIntegratorStep", enterEventMode, 1);
  NOT_NULL("fmi2CompletedIntegratorStep", terminateSimulation, 1);
  /* fmi2Boolean is int: the core writes the flags directly */
  return (fmi2Status)nnfmu_me_completed_integrator_step(INSTANCE, "fmi2CompletedIntegratorStep", enterEventMode,
                                                        terminateSimulation);
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_set_time(INSTANCE, "fmi2SetTime", time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_set_states(INSTANCE, "fmi2SetContinuousStates", x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_get_derivatives(INSTANCE, "fmi2GetDerivatives", derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
  CHECK_INSTANCE();
  NOT_NULL("fmi2GetEventIndicators", eventIndicators, ni);
  return (fmi2Status)nnfmu_me_event_indicators(INSTANCE, "fmi2GetEventIndicators", ni);
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_get_states(INSTANCE, "fmi2GetContinuousStates", x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_get_nominals(INSTANCE, "fmi2GetNominalsOfContinuousStates", x_nominal, nx);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_me_directional_derivative(INSTANCE, "fmi2GetDirectionalDerivative", vUnknown_ref,
                                                     nUnknown, vKnown_ref, nKnown, dvKnown, dvUnknown);
}
