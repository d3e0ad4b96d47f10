/* nnfmu FMI 3.0 entry points over the shared core (nnfmu_core.h), common and co-simulation ones: each
 * translates the FMI 3 types and calls the core, which checks the state machine and does the work.
 * Co-simulation has no event mode. The Model Exchange entry points are in nnfmu_fmi3_me.c (the core
 * refuses Model Exchange in an FMU whose model has no ODE). Every FMI 3 function is exported (importers
 * look them all up); those that do not apply are in nnfmu_fmi3_unsupported.c. */
#include <stddef.h>
#include <stdlib.h>

#include "nnfmu_fmi3.h"

void nnfmu_fmi3_sink(void *env, const char *instance_name, nnfmu_status status, const char *category,
                     const char *message) {
  const logger_env *le = (const logger_env *)env;
  (void)instance_name;
  le->log_message(le->environment, (fmi3Status)status, category, message);
}

fmi3Status nnfmu_fmi3_unsupported(fmi3Instance instance, const char *caller, const char *why) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_error(INSTANCE, "%s is not supported: %s", caller, why);
}

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
  (void)nCategories; (void)categories;
  CHECK_INSTANCE();
  nnfmu_set_logging(INSTANCE, loggingOn);
  return fmi3OK;
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
  fmi3_instance *inst;
  logger_env le;
  (void)resourcePath; (void)visible; (void)earlyReturnAllowed; (void)requiredIntermediateVariables;
  (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
  le.log_message = logMessage;
  le.environment = instanceEnvironment;
  if (eventModeUsed) {
    nnfmu_log_early(logMessage ? nnfmu_fmi3_sink : NULL, &le, instanceName, "fmi3InstantiateCoSimulation: "
                    "eventModeUsed must be false (hasEventMode is false) but was true");
    return NULL;
  }
  inst = (fmi3_instance *)calloc(1, sizeof *inst);
  if (!inst) return NULL;
  inst->magic = FMI3_INSTANCE_MAGIC;
  inst->le = le;
  inst->core = nnfmu_instantiate("fmi3InstantiateCoSimulation", NNFMU_INTERFACE_CS, instanceName, instantiationToken,
                                 logMessage ? nnfmu_fmi3_sink : NULL, &inst->le, loggingOn);
  if (!inst->core) {
    free(inst);
    return NULL;
  }
  return inst;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
  logger_env le;
  (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn; (void)clockUpdate;
  (void)lockPreemption; (void)unlockPreemption;
  le.log_message = logMessage;
  le.environment = instanceEnvironment;
  nnfmu_log_early(logMessage ? nnfmu_fmi3_sink : NULL, &le, instanceName, "fmi3InstantiateScheduledExecution: this FMU "
                  "offers co-simulation and, if its model has an ODE, Model Exchange");
  return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
  if (!instance || ((fmi3_instance *)instance)->magic != FMI3_INSTANCE_MAGIC) return; /* NULL, or freed already */
  ((fmi3_instance *)instance)->magic = 0;
  nnfmu_free(INSTANCE);
  free(instance);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
  const char *caller = "fmi3EnterInitializationMode";
  (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
  CHECK_INSTANCE();
  if (nnfmu_set_start_time(INSTANCE, caller, startTime) != NNFMU_OK) return fmi3Error;
  return (fmi3Status)nnfmu_enter_initialization(INSTANCE, caller);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_exit_initialization(INSTANCE, "fmi3ExitInitializationMode");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_terminate(INSTANCE, "fmi3Terminate");
}

fmi3Status fmi3Reset(fmi3Instance instance) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_reset(INSTANCE);
}

/* Integer and Boolean variables are scalars: the value count must equal the value-reference count. */
static fmi3Status check_count(fmi3Instance instance, const char *caller, size_t n_refs, size_t n_values) {
  if (n_values == n_refs) return fmi3OK;
  return (fmi3Status)nnfmu_error(INSTANCE, "%s: expected nValues = nValueReferences = %lu (all variables are "
                                 "scalars), got %lu", caller, (unsigned long)n_refs, (unsigned long)n_values);
}

/* Float64 variables may be arrays (the init window's <c>_past): the values follow the references in order. */
static fmi3Status check_float64_count(fmi3Instance instance, const char *caller, const fmi3ValueReference refs[],
                                      size_t n_refs, size_t n_values) {
  size_t i, total = 0;
  for (i = 0; i < n_refs; ++i) total += nnfmu_real_size(refs[i]);
  if (n_values == total) return fmi3OK;
  return (fmi3Status)nnfmu_error(INSTANCE, "%s: expected nValues = %lu (the values of the %lu variables; arrays "
                                 "count their elements), got %lu", caller, (unsigned long)total,
                                 (unsigned long)n_refs, (unsigned long)n_values);
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Float64 values[], size_t nValues) {
  size_t i, k = 0;
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetFloat64", valueReferences, nValueReferences);
  NOT_NULL("fmi3GetFloat64", values, nValues);
  if (check_float64_count(instance, "fmi3GetFloat64", valueReferences, nValueReferences, nValues) != fmi3OK)
    return fmi3Error;
  for (i = 0; i < nValueReferences; k += nnfmu_real_size(valueReferences[i++]))
    if (nnfmu_get_real(INSTANCE, "fmi3GetFloat64", valueReferences[i], &values[k]) != NNFMU_OK) return fmi3Error;
  return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Float64 values[], size_t nValues) {
  size_t i, k = 0;
  CHECK_INSTANCE();
  NOT_NULL("fmi3SetFloat64", valueReferences, nValueReferences);
  NOT_NULL("fmi3SetFloat64", values, nValues);
  if (check_float64_count(instance, "fmi3SetFloat64", valueReferences, nValueReferences, nValues) != fmi3OK)
    return fmi3Error;
  for (i = 0; i < nValueReferences; k += nnfmu_real_size(valueReferences[i++]))
    if (nnfmu_set_real(INSTANCE, "fmi3SetFloat64", valueReferences[i], &values[k]) != NNFMU_OK) return fmi3Error;
  return fmi3OK;
}

/* Int32 and Boolean: the parameters max_samples_per_step and input_range_error. */
fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Int32 values[], size_t nValues) {
  size_t i;
  long long v;
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetInt32", valueReferences, nValueReferences);
  NOT_NULL("fmi3GetInt32", values, nValues);
  if (check_count(instance, "fmi3GetInt32", nValueReferences, nValues) != fmi3OK) return fmi3Error;
  for (i = 0; i < nValueReferences; ++i) {
    if (nnfmu_get_int(INSTANCE, "fmi3GetInt32", NNFMU_INTEGER, valueReferences[i], &v) != NNFMU_OK) return fmi3Error;
    values[i] = (fmi3Int32)v;
  }
  return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Int32 values[], size_t nValues) {
  size_t i;
  CHECK_INSTANCE();
  NOT_NULL("fmi3SetInt32", valueReferences, nValueReferences);
  NOT_NULL("fmi3SetInt32", values, nValues);
  if (check_count(instance, "fmi3SetInt32", nValueReferences, nValues) != fmi3OK) return fmi3Error;
  for (i = 0; i < nValueReferences; ++i)
    if (nnfmu_set_int(INSTANCE, "fmi3SetInt32", NNFMU_INTEGER, valueReferences[i], values[i]) != NNFMU_OK)
      return fmi3Error;
  return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          fmi3Boolean values[], size_t nValues) {
  size_t i;
  long long v;
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetBoolean", valueReferences, nValueReferences);
  NOT_NULL("fmi3GetBoolean", values, nValues);
  if (check_count(instance, "fmi3GetBoolean", nValueReferences, nValues) != fmi3OK) return fmi3Error;
  for (i = 0; i < nValueReferences; ++i) {
    if (nnfmu_get_int(INSTANCE, "fmi3GetBoolean", NNFMU_BOOLEAN, valueReferences[i], &v) != NNFMU_OK) return fmi3Error;
    values[i] = v ? fmi3True : fmi3False;
  }
  return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                          const fmi3Boolean values[], size_t nValues) {
  size_t i;
  CHECK_INSTANCE();
  NOT_NULL("fmi3SetBoolean", valueReferences, nValueReferences);
  NOT_NULL("fmi3SetBoolean", values, nValues);
  if (check_count(instance, "fmi3SetBoolean", nValueReferences, nValues) != fmi3OK) return fmi3Error;
  for (i = 0; i < nValueReferences; ++i)
    if (nnfmu_set_int(INSTANCE, "fmi3SetBoolean", NNFMU_BOOLEAN, valueReferences[i], values[i]) != NNFMU_OK)
      return fmi3Error;
  return fmi3OK;
}

/* Outputs never depend on the inputs of the same instant (no feedthrough). */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
  CHECK_INSTANCE();
  NOT_NULL("fmi3GetNumberOfVariableDependencies", nDependencies, 1);
  if (!nnfmu_is_output(valueReference))
    return (fmi3Status)nnfmu_error(INSTANCE, "fmi3GetNumberOfVariableDependencies: value reference %lu "
                                 "is not an output", (unsigned long)valueReference);
  *nDependencies = 0;
  return fmi3OK;
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
  (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents; (void)dependencyKinds;
  CHECK_INSTANCE();
  if (!nnfmu_is_output(dependent) || nDependencies != 0)
    return (fmi3Status)nnfmu_error(INSTANCE, "fmi3GetVariableDependencies: expected an output and "
                                 "nDependencies = 0, got value reference %lu and %lu", (unsigned long)dependent,
                                 (unsigned long)nDependencies);
  return fmi3OK;
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_get_state(INSTANCE, FMUState);
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_set_state(INSTANCE, FMUState);
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_free_state(INSTANCE, "fmi3FreeFMUState", FMUState);
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
  (void)FMUState;
  CHECK_INSTANCE();
  NOT_NULL("fmi3SerializedFMUStateSize", size, 1);
  *size = nnfmu_serialized_size();
  return fmi3OK;
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_serialize(INSTANCE, FMUState, serializedState, size);
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
  CHECK_INSTANCE();
  return (fmi3Status)nnfmu_deserialize(INSTANCE, serializedState, size, FMUState);
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
  nnfmu_status status;
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK_INSTANCE();
  status = nnfmu_do_step(INSTANCE, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
  if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
  if (terminateSimulation) *terminateSimulation = fmi3False;
  if (earlyReturn) *earlyReturn = fmi3False;
  if (lastSuccessfulTime) *lastSuccessfulTime = nnfmu_time(INSTANCE);
  return (fmi3Status)status;
}
