/* nnfmu FMI 2.0 entry points over the shared core (nnfmu_core.h), common and co-simulation ones: each
 * translates the FMI 2 types and calls the core, which checks the state machine and does the work. The
 * Model Exchange entry points are in nnfmu_fmi2_me.c; every FMU has both files, and the core refuses
 * Model Exchange in an FMU whose model has no ODE. */
#include <stddef.h>
#include <stdlib.h>

#include "nnfmu_fmi2.h"

/* The core hands over finished messages; FMI 2 loggers read them as printf formats (the core removed
 * every '%'), so the message itself is the format. */
static void fmi2_sink(void *env, const char *instance_name, nnfmu_status status, const char *category,
                      const char *message) {
  const logger_env *le = (const logger_env *)env;
  le->logger(le->environment, instance_name, (fmi2Status)status, category, message);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
  fmi2_instance *inst;
  logger_env le;
  (void)fmuResourceLocation;
  (void)visible;
  le.logger = functions ? functions->logger : NULL;
  le.environment = functions ? functions->componentEnvironment : NULL;
  if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
    nnfmu_log_early(le.logger ? fmi2_sink : NULL, &le, instanceName, "fmi2Instantiate: fmuType must be "
                    "fmi2ModelExchange or fmi2CoSimulation, got %d", (int)fmuType);
    return NULL;
  }
  inst = (fmi2_instance *)calloc(1, sizeof *inst);
  if (!inst) return NULL;
  inst->magic = FMI2_INSTANCE_MAGIC;
  inst->le = le;
  inst->core = nnfmu_instantiate("fmi2Instantiate", fmuType == fmi2ModelExchange ? NNFMU_INTERFACE_ME
                                 : NNFMU_INTERFACE_CS, instanceName, fmuGUID, le.logger ? fmi2_sink : NULL,
                                 &inst->le, loggingOn);
  if (!inst->core) {
    free(inst);
    return NULL;
  }
  return inst;
}

void fmi2FreeInstance(fmi2Component c) {
  if (!c || ((fmi2_instance *)c)->magic != FMI2_INSTANCE_MAGIC) return; /* NULL, or freed already */
  ((fmi2_instance *)c)->magic = 0;
  nnfmu_free(INSTANCE);
  free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
  (void)nCategories;
  (void)categories;
  CHECK_INSTANCE();
  nnfmu_set_logging(INSTANCE, loggingOn);
  return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
  (void)toleranceDefined;
  (void)tolerance;
  (void)stopTimeDefined;
  (void)stopTime;
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_set_start_time(INSTANCE, "fmi2SetupExperiment", startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_enter_initialization(INSTANCE, "fmi2EnterInitializationMode");
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_exit_initialization(INSTANCE, "fmi2ExitInitializationMode");
}

fmi2Status fmi2Terminate(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_terminate(INSTANCE, "fmi2Terminate");
}

fmi2Status fmi2Reset(fmi2Component c) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_reset(INSTANCE);
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
  size_t i;
  CHECK_INSTANCE();
  NOT_NULL("fmi2GetReal", vr, nvr);
  NOT_NULL("fmi2GetReal", value, nvr);
  for (i = 0; i < nvr; ++i)
    if (nnfmu_get_real(INSTANCE, "fmi2GetReal", vr[i], &value[i]) != NNFMU_OK) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
  size_t i;
  CHECK_INSTANCE();
  NOT_NULL("fmi2SetReal", vr, nvr);
  NOT_NULL("fmi2SetReal", value, nvr);
  for (i = 0; i < nvr; ++i)
    if (nnfmu_set_real(INSTANCE, "fmi2SetReal", vr[i], &value[i]) != NNFMU_OK) return fmi2Error;
  return fmi2OK;
}

/* Integer and Boolean: the parameters max_samples_per_step and input_range_error. FMI 2 declares both
 * fmi2Integer and fmi2Boolean as int, so one getter and one setter serve both types. */
static fmi2Status get_ints(fmi2Component c, const char *caller, nnfmu_int_type type, const fmi2ValueReference vr[],
                           size_t nvr, int value[]) {
  size_t i;
  long long v;
  CHECK_INSTANCE();
  NOT_NULL(caller, vr, nvr);
  NOT_NULL(caller, value, nvr);
  for (i = 0; i < nvr; ++i) {
    if (nnfmu_get_int(INSTANCE, caller, type, vr[i], &v) != NNFMU_OK) return fmi2Error;
    value[i] = type == NNFMU_BOOLEAN ? (v ? fmi2True : fmi2False) : (int)v;
  }
  return fmi2OK;
}

static fmi2Status set_ints(fmi2Component c, const char *caller, nnfmu_int_type type, const fmi2ValueReference vr[],
                           size_t nvr, const int value[]) {
  size_t i;
  CHECK_INSTANCE();
  NOT_NULL(caller, vr, nvr);
  NOT_NULL(caller, value, nvr);
  for (i = 0; i < nvr; ++i)
    if (nnfmu_set_int(INSTANCE, caller, type, vr[i], value[i]) != NNFMU_OK) return fmi2Error;
  return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
  return get_ints(c, "fmi2GetInteger", NNFMU_INTEGER, vr, nvr, value);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
  return set_ints(c, "fmi2SetInteger", NNFMU_INTEGER, vr, nvr, value);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
  return get_ints(c, "fmi2GetBoolean", NNFMU_BOOLEAN, vr, nvr, value);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
  return set_ints(c, "fmi2SetBoolean", NNFMU_BOOLEAN, vr, nvr, value);
}

/* String: this FMU has none. */
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
  (void)vr; (void)value;
  CHECK_INSTANCE();
  return nvr ? (fmi2Status)nnfmu_error(INSTANCE, "fmi2GetString: this FMU has no String variables") : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
  (void)vr; (void)value;
  CHECK_INSTANCE();
  return nvr ? (fmi2Status)nnfmu_error(INSTANCE, "fmi2SetString: this FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_get_state(INSTANCE, FMUstate);
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_set_state(INSTANCE, FMUstate);
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_free_state(INSTANCE, "fmi2FreeFMUstate", FMUstate);
}
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
  (void)FMUstate;
  CHECK_INSTANCE();
  NOT_NULL("fmi2SerializedFMUstateSize", size, 1);
  *size = nnfmu_serialized_size();
  return fmi2OK;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_serialize(INSTANCE, FMUstate, (unsigned char *)serializedState, size);
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_deserialize(INSTANCE, (const unsigned char *)serializedState, size, FMUstate);
}

static fmi2Status unsupported(fmi2Component c, const char *caller, const char *why) {
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_error(INSTANCE, "%s is not supported: %s", caller, why);
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
  (void)vr; (void)nvr; (void)order; (void)value;
  return unsupported(c, "fmi2SetRealInputDerivatives", "inputs are held over each sample (canInterpolateInputs "
                     "is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
  (void)vr; (void)nvr; (void)order; (void)value;
  return unsupported(c, "fmi2GetRealOutputDerivatives", "outputs are piecewise constant (maxOutputDerivativeOrder "
                     "is 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
  (void)noSetFMUStatePriorToCurrentPoint;
  CHECK_INSTANCE();
  return (fmi2Status)nnfmu_do_step(INSTANCE, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) {
  return unsupported(c, "fmi2CancelStep", "doStep always completes before it returns");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
  (void)s;
  (void)value;
  return unsupported(c, "fmi2GetStatus", "doStep is never asynchronous");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
  CHECK_INSTANCE();
  NOT_NULL("fmi2GetRealStatus", value, 1);
  if (s != fmi2LastSuccessfulTime) return unsupported(c, "fmi2GetRealStatus", "only fmi2LastSuccessfulTime exists");
  return (fmi2Status)nnfmu_last_time(INSTANCE, "fmi2GetRealStatus", value);
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
  (void)s;
  (void)value;
  return unsupported(c, "fmi2GetIntegerStatus", "there is no integer status");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
  CHECK_INSTANCE();
  NOT_NULL("fmi2GetBooleanStatus", value, 1);
  if (s != fmi2Terminated) return unsupported(c, "fmi2GetBooleanStatus", "only fmi2Terminated exists");
  *value = fmi2False; /* the FMU never asks to end the simulation */
  return fmi2OK;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
  (void)s;
  (void)value;
  return unsupported(c, "fmi2GetStringStatus", "doStep is never asynchronous");
}
