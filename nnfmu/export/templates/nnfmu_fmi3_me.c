/* nnfmu FMI 3.0 Model Exchange entry points, in every FMU, over the core's Model Exchange part (nnfmu_core.h,
 * nnfmu_me.c), with fmi3EnterEventMode, fmi3UpdateDiscreteStates and fmi3GetDirectionalDerivative. In an FMU
 * without an ODE, fmi3InstantiateModelExchange is refused by the core and each of these is an Error that
 * says why. */
#include <stddef.h>
#include <stdlib.h>

#include "nnfmu_fmi3.h"

/* The core takes FMI 2 and 3 value references alike: both are 32-bit unsigned integers. */
typedef char nnfmu_vr_is_unsigned_int[sizeof(fmi3ValueReference) == sizeof(unsigned int) ? 1 : -1];

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
  fmi3_instance *inst;
  (void)resourcePath; (void)visible;
  inst = (fmi3_instance *)calloc(1, sizeof *inst);
  if (!inst) return NULL;
  inst->magic = FMI3_INSTANCE_MAGIC;
  inst->le.log_message = logMessage;
  inst->le.environment = instanceEnvironment;
  inst->core = nnfmu_instantiate("fmi3InstantiateModelExchange", NNFMU_INTERFACE_ME, instanceName,
                                 instantiationToken, logMessage ? nnfmu_fmi3_sink : NULL, &inst->le, loggingOn);
  if (!inst->core) {
    free(inst);
    return NULL;
  }
  return inst;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_enter_event_mode(INSTANCE, "fmi3EnterEventMode");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
  const char *caller = "fmi3UpdateDiscreteStates";
  nnfmu_event_info info;
  CHECK_INSTANCE();
  NOT_NULL(caller, discreteStatesNeedUpdate, 1);
  NOT_NULL(caller, terminateSimulation, 1);
  NOT_NULL(caller, nominalsOfContinuousStatesChanged, 1);
  NOT_NULL(caller, valuesOfContinuousStatesChanged, 1);
  NOT_NULL(caller, nextEventTimeDefined, 1);
  NOT_NULL(caller, nextEventTime, 1);
  if (nnfmu_me_update_discrete_states(INSTANCE, caller, &info) != NNFMU_OK) return fmi3Error;
  *discreteStatesNeedUpdate = info.discrete_states_need_update ? fmi3True : fmi3False;
  *terminateSimulation = info.terminate_simulation ? fmi3True : fmi3False;
  *nominalsOfContinuousStatesChanged = info.nominals_changed ? fmi3True : fmi3False;
  *valuesOfContinuousStatesChanged = info.values_changed ? fmi3True : fmi3False;
  *nextEventTimeDefined = info.next_event_time_defined ? fmi3True : fmi3False;
  *nextEventTime = info.next_event_time;
  return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_enter_continuous_time_mode(INSTANCE, "fmi3EnterContinuousTimeMode");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
  int enter, terminate;
  fmi3Status status;
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK_INSTANCE();
  NOT_NULL("fmi3CompletedIntegratorStep", enterEventMode, 1);
  NOT_NULL("fmi3CompletedIntegratorStep", terminateSimulation, 1);
  status = (fmi3Status)nnfmu_me_completed_integrator_step(INSTANCE, "fmi3CompletedIntegratorStep", &enter,
                                                           &terminate);
  *enterEventMode = enter ? fmi3True : fmi3False;
  *terminateSimulation = terminate ? fmi3True : fmi3False;
  return status;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_set_time(INSTANCE, "fmi3SetTime", time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_set_states(INSTANCE, "fmi3SetContinuousStates", continuousStates, nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_get_derivatives(INSTANCE, "fmi3GetContinuousStateDerivatives", derivatives,
                                              nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetEventIndicators", eventIndicators, nEventIndicators);
  return (fmi3Status)nnfmu_me_event_indicators(INSTANCE, "fmi3GetEventIndicators", nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_get_states(INSTANCE, "fmi3GetContinuousStates", continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_me_get_nominals(INSTANCE, "fmi3GetNominalsOfContinuousStates", nominals,
                                           nContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetNumberOfEventIndicators", nEventIndicators, 1);
  return (fmi3Status)nnfmu_me_number_of_event_indicators(INSTANCE, "fmi3GetNumberOfEventIndicators",
                                                         nEventIndicators);
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetNumberOfContinuousStates", nContinuousStates, 1);
  return (fmi3Status)nnfmu_me_number_of_states(INSTANCE, "fmi3GetNumberOfContinuousStates", nContinuousStates);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
  const char *caller = "fmi3GetDirectionalDerivative";
  CHECK_INSTANCE();
  if (nSeed != nKnowns || nSensitivity != nUnknowns)
    return (fmi3Status)nnfmu_error(INSTANCE, "%s: expected nSeed = nKnowns = %lu and nSensitivity = nUnknowns = %lu "
                                   "(all variables are scalars), got %lu and %lu", caller, (unsigned long)nKnowns,
                                   (unsigned long)nUnknowns, (unsigned long)nSeed, (unsigned long)nSensitivity);
  return (fmi3Status)nnfmu_me_directional_derivative(INSTANCE, caller, unknowns, nUnknowns, knowns, nKnowns, seed,
                                                     sensitivity);
}
