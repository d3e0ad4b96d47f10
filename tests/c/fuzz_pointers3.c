/* The FMI 3 pointer cases of the fuzz driver (see fuzz_pointers.c): NULL for each pointer argument of each
 * FMI 3 function an importer may call, one at a time. */
#include <stdio.h>

#include "fuzz.h"

/* The getters and setters of the types this FMU does not have: NULL references, then NULL values. */
#define ABSENT_TYPE(kind, type)                                                                          \
  TRY("fmi3" #kind "(valueReferences = NULL)", MUST_ERROR, F3(kind)(c, NULL, 1, (type *)any, 1));          \
  TRY("fmi3" #kind "(values = NULL)", MUST_ERROR, F3(kind)(c, vr, 1, NULL, 1));
#define BOTH(type, getter, setter) ABSENT_TYPE(getter, type) ABSENT_TYPE(setter, const type)

static int typed_cases(void *c) {
  const fmi3ValueReference vr[1] = {NNFMU_VR_U}, get_vr[2] = {NNFMU_VR_TIME, NNFMU_VR_Y};
  const fmi3ValueReference int_vr[1] = {NNFMU_VR_MAX_SAMPLES}, bool_vr[1] = {NNFMU_VR_RANGE_ERROR};
  double v[2] = {0.0, 0.0}, any[4] = {0.0, 0.0, 0.0, 0.0};
  fmi3Int32 iv[1] = {1000};
  fmi3Boolean bv[1] = {fmi3False};
  size_t sizes[1] = {0};
  fmi3Binary binary[1] = {NULL};
  fmi3Clock clocks[1] = {fmi3False};
  TRY("fmi3GetFloat64(valueReferences = NULL)", MUST_ERROR, F3(GetFloat64)(c, NULL, 2, v, 2));
  TRY("fmi3GetFloat64(values = NULL)", MUST_ERROR, F3(GetFloat64)(c, get_vr, 2, NULL, 2));
  TRY("fmi3SetFloat64(valueReferences = NULL)", MUST_ERROR, F3(SetFloat64)(c, NULL, 1, v, 1));
  TRY("fmi3SetFloat64(values = NULL)", MUST_ERROR, F3(SetFloat64)(c, vr, 1, NULL, 1));
  TRY("fmi3GetInt32(valueReferences = NULL)", MUST_ERROR, F3(GetInt32)(c, NULL, 1, iv, 1));
  TRY("fmi3GetInt32(values = NULL)", MUST_ERROR, F3(GetInt32)(c, int_vr, 1, NULL, 1));
  TRY("fmi3SetInt32(valueReferences = NULL)", MUST_ERROR, F3(SetInt32)(c, NULL, 1, iv, 1));
  TRY("fmi3SetInt32(values = NULL)", MUST_ERROR, F3(SetInt32)(c, int_vr, 1, NULL, 1));
  TRY("fmi3GetBoolean(valueReferences = NULL)", MUST_ERROR, F3(GetBoolean)(c, NULL, 1, bv, 1));
  TRY("fmi3GetBoolean(values = NULL)", MUST_ERROR, F3(GetBoolean)(c, bool_vr, 1, NULL, 1));
  TRY("fmi3SetBoolean(valueReferences = NULL)", MUST_ERROR, F3(SetBoolean)(c, NULL, 1, bv, 1));
  TRY("fmi3SetBoolean(values = NULL)", MUST_ERROR, F3(SetBoolean)(c, bool_vr, 1, NULL, 1));
  BOTH(fmi3Float32, GetFloat32, SetFloat32)
  BOTH(fmi3Int8, GetInt8, SetInt8)
  BOTH(fmi3UInt8, GetUInt8, SetUInt8)
  BOTH(fmi3Int16, GetInt16, SetInt16)
  BOTH(fmi3UInt16, GetUInt16, SetUInt16)
  BOTH(fmi3UInt32, GetUInt32, SetUInt32)
  BOTH(fmi3Int64, GetInt64, SetInt64)
  BOTH(fmi3UInt64, GetUInt64, SetUInt64)
  BOTH(fmi3String, GetString, SetString)
  TRY("fmi3GetBinary(valueReferences = NULL)", MUST_ERROR, F3(GetBinary)(c, NULL, 1, sizes, binary, 1));
  TRY("fmi3GetBinary(valueSizes = NULL)", MUST_ERROR, F3(GetBinary)(c, vr, 1, NULL, binary, 1));
  TRY("fmi3GetBinary(values = NULL)", MUST_ERROR, F3(GetBinary)(c, vr, 1, sizes, NULL, 1));
  TRY("fmi3SetBinary(valueReferences = NULL)", MUST_ERROR, F3(SetBinary)(c, NULL, 1, sizes, binary, 1));
  TRY("fmi3SetBinary(valueSizes = NULL)", MUST_ERROR, F3(SetBinary)(c, vr, 1, NULL, binary, 1));
  TRY("fmi3SetBinary(values = NULL)", MUST_ERROR, F3(SetBinary)(c, vr, 1, sizes, NULL, 1));
  TRY("fmi3GetClock(valueReferences = NULL)", MUST_ERROR, F3(GetClock)(c, NULL, 1, clocks));
  TRY("fmi3GetClock(values = NULL)", MUST_ERROR, F3(GetClock)(c, vr, 1, NULL));
  TRY("fmi3SetClock(valueReferences = NULL)", MUST_ERROR, F3(SetClock)(c, NULL, 1, clocks));
  TRY("fmi3SetClock(values = NULL)", MUST_ERROR, F3(SetClock)(c, vr, 1, NULL));
  return 0;
}

static int derivative_and_clock_cases(void *c) {
  const fmi3ValueReference known[1] = {NNFMU_VR_U}, unknown[1] = {NNFMU_VR_Y};
  const fmi3Int32 order[1] = {1};
  double v[1] = {1.0};
  fmi3UInt64 n64[1] = {1};
  fmi3IntervalQualifier q[1];
  size_t n;
  TRY("fmi3GetDirectionalDerivative(unknowns = NULL)", MUST_ERROR,
      F3(GetDirectionalDerivative)(c, NULL, 1, known, 1, v, 1, v, 1));
  TRY("fmi3GetDirectionalDerivative(knowns = NULL)", MUST_ERROR,
      F3(GetDirectionalDerivative)(c, unknown, 1, NULL, 1, v, 1, v, 1));
  TRY("fmi3GetDirectionalDerivative(seed = NULL)", MUST_ERROR,
      F3(GetDirectionalDerivative)(c, unknown, 1, known, 1, NULL, 1, v, 1));
  TRY("fmi3GetDirectionalDerivative(sensitivity = NULL)", MUST_ERROR,
      F3(GetDirectionalDerivative)(c, unknown, 1, known, 1, v, 1, NULL, 1));
  TRY("fmi3GetAdjointDerivative(unknowns = NULL)", MUST_ERROR,
      F3(GetAdjointDerivative)(c, NULL, 1, known, 1, v, 1, v, 1));
  TRY("fmi3GetAdjointDerivative(seed = NULL)", MUST_ERROR,
      F3(GetAdjointDerivative)(c, unknown, 1, known, 1, NULL, 1, v, 1));
  TRY("fmi3GetOutputDerivatives(valueReferences = NULL)", MUST_ERROR,
      F3(GetOutputDerivatives)(c, NULL, 1, order, v, 1));
  TRY("fmi3GetOutputDerivatives(orders = NULL)", MUST_ERROR, F3(GetOutputDerivatives)(c, unknown, 1, NULL, v, 1));
  TRY("fmi3GetOutputDerivatives(values = NULL)", MUST_ERROR,
      F3(GetOutputDerivatives)(c, unknown, 1, order, NULL, 1));
  TRY("fmi3GetIntervalDecimal(NULL arrays)", MUST_ERROR, F3(GetIntervalDecimal)(c, NULL, 1, NULL, NULL));
  TRY("fmi3GetIntervalFraction(NULL arrays)", MUST_ERROR, F3(GetIntervalFraction)(c, NULL, 1, NULL, NULL, q));
  TRY("fmi3GetShiftDecimal(NULL arrays)", MUST_ERROR, F3(GetShiftDecimal)(c, NULL, 1, NULL));
  TRY("fmi3GetShiftFraction(NULL arrays)", MUST_ERROR, F3(GetShiftFraction)(c, NULL, 1, NULL, n64));
  TRY("fmi3SetIntervalDecimal(NULL arrays)", MUST_ERROR, F3(SetIntervalDecimal)(c, NULL, 1, NULL));
  TRY("fmi3SetIntervalFraction(NULL arrays)", MUST_ERROR, F3(SetIntervalFraction)(c, NULL, 1, NULL, NULL));
  TRY("fmi3SetShiftDecimal(NULL arrays)", MUST_ERROR, F3(SetShiftDecimal)(c, NULL, 1, NULL));
  TRY("fmi3SetShiftFraction(NULL arrays)", MUST_ERROR, F3(SetShiftFraction)(c, NULL, 1, NULL, NULL));
  TRY("fmi3GetNumberOfVariableDependencies(nDependencies = NULL)", MUST_ERROR,
      F3(GetNumberOfVariableDependencies)(c, NNFMU_VR_Y, NULL));
  TRY("fmi3GetVariableDependencies(NULL arrays, nDependencies = 0)", ANY,
      F3(GetVariableDependencies)(c, NNFMU_VR_Y, NULL, NULL, NULL, NULL, 0));
  TRY("fmi3GetNumberOfEventIndicators(nEventIndicators = NULL)", MUST_ERROR,
      F3(GetNumberOfEventIndicators)(c, NULL));
  TRY("fmi3GetNumberOfContinuousStates(nContinuousStates = NULL)", MUST_ERROR,
      F3(GetNumberOfContinuousStates)(c, NULL));
  (void)n;
  return 0;
}

static int mode_cases(void *c) {
  const char *token = (const char *)NNFMU_TOKEN;
  fmi3Boolean b[5];
  fmi3Float64 t, x[NNFMU_ALLOC(NNFMU_NX)];
  fmi3DoStepTYPE *step = F3(DoStep);
  fmi3UpdateDiscreteStatesTYPE *update = F3(UpdateDiscreteStates);
  TRY("fmi3DoStep(eventHandlingNeeded = NULL)", ANY, step(c, 0.0, NNFMU_TS, fmi3True, NULL, b, b, &t));
  TRY("fmi3DoStep(terminateSimulation = NULL)", ANY, step(c, 0.0, NNFMU_TS, fmi3True, b, NULL, b, &t));
  TRY("fmi3DoStep(earlyReturn = NULL)", ANY, step(c, 0.0, NNFMU_TS, fmi3True, b, b, NULL, &t));
  TRY("fmi3DoStep(lastSuccessfulTime = NULL)", ANY, step(c, 0.0, NNFMU_TS, fmi3True, b, b, b, NULL));
  TRY("fmi3UpdateDiscreteStates(discreteStatesNeedUpdate = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, NULL, b, b, b, b, &t)));
  TRY("fmi3UpdateDiscreteStates(terminateSimulation = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, b, NULL, b, b, b, &t)));
  TRY("fmi3UpdateDiscreteStates(nominalsOfContinuousStatesChanged = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, b, b, NULL, b, b, &t)));
  TRY("fmi3UpdateDiscreteStates(valuesOfContinuousStatesChanged = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, b, b, b, NULL, b, &t)));
  TRY("fmi3UpdateDiscreteStates(nextEventTimeDefined = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, b, b, b, b, NULL, &t)));
  TRY("fmi3UpdateDiscreteStates(nextEventTime = NULL)", MUST_ERROR,
      (F3(EnterEventMode)(c), update(c, b, b, b, b, b, NULL)));
  TRY("fmi3CompletedIntegratorStep(enterEventMode = NULL)", MUST_ERROR,
      F3(CompletedIntegratorStep)(c, fmi3True, NULL, b));
  TRY("fmi3CompletedIntegratorStep(terminateSimulation = NULL)", MUST_ERROR,
      F3(CompletedIntegratorStep)(c, fmi3True, b, NULL));
  TRY("fmi3SetContinuousStates(continuousStates = NULL)", MUST_ERROR, F3(SetContinuousStates)(c, NULL, NNFMU_NX));
  TRY("fmi3GetContinuousStateDerivatives(derivatives = NULL)", MUST_ERROR,
      F3(GetContinuousStateDerivatives)(c, NULL, NNFMU_NX));
  TRY("fmi3GetEventIndicators(eventIndicators = NULL)", MUST_ERROR, F3(GetEventIndicators)(c, NULL, 1));
  TRY("fmi3GetContinuousStates(continuousStates = NULL)", MUST_ERROR, F3(GetContinuousStates)(c, NULL, NNFMU_NX));
  TRY("fmi3GetNominalsOfContinuousStates(nominals = NULL)", MUST_ERROR,
      F3(GetNominalsOfContinuousStates)(c, NULL, NNFMU_NX));
  TRY("fmi3SetDebugLogging(categories = NULL)", ANY, F3(SetDebugLogging)(c, fmi3True, 2, NULL));
  TRY("fmi3InstantiateCoSimulation(instanceName = NULL)", ANY, instantiated(F3(InstantiateCoSimulation)(
      NULL, token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 1, NULL, NULL, NULL)));
  TRY("fmi3InstantiateCoSimulation(instantiationToken = NULL)", MUST_FAIL, instantiated(F3(InstantiateCoSimulation)(
      "x", NULL, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, NULL, NULL)));
  TRY("fmi3InstantiateModelExchange(instanceName = NULL)", ANY, instantiated(F3(InstantiateModelExchange)(
      NULL, token, NULL, fmi3False, fmi3False, NULL, NULL)));
  (void)x;
  return 0;
}

int fmi3_cases(void *c) {
  int done = typed_cases(c);
  if (!done) done = derivative_and_clock_cases(c);
  if (!done) done = mode_cases(c);
  return done;
}
