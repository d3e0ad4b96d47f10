/* nnfmu FMI 3.0: the functions that do not apply to this FMU, in every FMU: variables of the types it does
 * not have, clocks, configuration mode, step mode after event mode, adjoint and output derivatives. They
 * exist because importers look up the whole API; each logs why and returns fmi3Error (the getters and
 * setters of absent types return fmi3OK when asked for no variables). */
#include <stddef.h>

#include "nnfmu_fmi3.h"

#define U(x) (void)(x)

/* Getters and setters of the types this FMU does not have: fine when empty, an error otherwise. */
#define NO_VARIABLES_OF_TYPE(function, value_type)                                                          \
  fmi3Status function(fmi3Instance instance, const fmi3ValueReference valueReferences[],                  \
                      size_t nValueReferences, value_type values[], size_t nValues) {                     \
    (void)valueReferences; (void)values; (void)nValues;                                                   \
    CHECK_INSTANCE();                                                                                     \
    return nValueReferences ? nnfmu_fmi3_unsupported(instance, #function, NO_TYPE) : fmi3OK;                         \
  }
NO_VARIABLES_OF_TYPE(fmi3GetFloat32, fmi3Float32)
NO_VARIABLES_OF_TYPE(fmi3GetInt8, fmi3Int8)
NO_VARIABLES_OF_TYPE(fmi3GetUInt8, fmi3UInt8)
NO_VARIABLES_OF_TYPE(fmi3GetInt16, fmi3Int16)
NO_VARIABLES_OF_TYPE(fmi3GetUInt16, fmi3UInt16)
NO_VARIABLES_OF_TYPE(fmi3GetUInt32, fmi3UInt32)
NO_VARIABLES_OF_TYPE(fmi3GetInt64, fmi3Int64)
NO_VARIABLES_OF_TYPE(fmi3GetUInt64, fmi3UInt64)
NO_VARIABLES_OF_TYPE(fmi3GetString, fmi3String)
NO_VARIABLES_OF_TYPE(fmi3SetFloat32, const fmi3Float32)
NO_VARIABLES_OF_TYPE(fmi3SetInt8, const fmi3Int8)
NO_VARIABLES_OF_TYPE(fmi3SetUInt8, const fmi3UInt8)
NO_VARIABLES_OF_TYPE(fmi3SetInt16, const fmi3Int16)
NO_VARIABLES_OF_TYPE(fmi3SetUInt16, const fmi3UInt16)
NO_VARIABLES_OF_TYPE(fmi3SetUInt32, const fmi3UInt32)
NO_VARIABLES_OF_TYPE(fmi3SetInt64, const fmi3Int64)
NO_VARIABLES_OF_TYPE(fmi3SetUInt64, const fmi3UInt64)
NO_VARIABLES_OF_TYPE(fmi3SetString, const fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         size_t valueSizes[], fmi3Binary values[], size_t nValues) {
  (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
  CHECK_INSTANCE();
  return nValueReferences ? nnfmu_fmi3_unsupported(instance, "fmi3GetBinary", NO_TYPE) : fmi3OK;
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                         const size_t valueSizes[], const fmi3Binary values[], size_t nValues) {
  (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
  CHECK_INSTANCE();
  return nValueReferences ? nnfmu_fmi3_unsupported(instance, "fmi3SetBinary", NO_TYPE) : fmi3OK;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        fmi3Clock values[]) {
  (void)valueReferences; (void)values;
  CHECK_INSTANCE();
  return nValueReferences ? nnfmu_fmi3_unsupported(instance, "fmi3GetClock", NO_CLOCKS) : fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[], size_t nValueReferences,
                        const fmi3Clock values[]) {
  (void)valueReferences; (void)values;
  CHECK_INSTANCE();
  return nValueReferences ? nnfmu_fmi3_unsupported(instance, "fmi3SetClock", NO_CLOCKS) : fmi3OK;
}

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3EnterStepMode",
                                "without event mode the FMU is in step mode after initialization");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3EnterConfigurationMode", "this FMU has no structural parameters");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3ExitConfigurationMode", "this FMU has no structural parameters");
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3EvaluateDiscreteStates", NO_CLOCKS);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
  U(unknowns); U(nUnknowns); U(knowns); U(nKnowns); U(seed); U(nSeed); U(sensitivity); U(nSensitivity);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives is false");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
  U(valueReferences); U(nValueReferences); U(orders); U(values); U(nValues);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetOutputDerivatives", "outputs are piecewise constant");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[], fmi3IntervalQualifier qualifiers[]) {
  U(valueReferences); U(nValueReferences); U(intervals); U(qualifiers);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetIntervalDecimal", NO_CLOCKS);
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
  U(valueReferences); U(nValueReferences); U(counters); U(resolutions); U(qualifiers);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetIntervalFraction", NO_CLOCKS);
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
  U(valueReferences); U(nValueReferences); U(shifts);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetShiftDecimal", NO_CLOCKS);
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
  U(valueReferences); U(nValueReferences); U(counters); U(resolutions);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetShiftFraction", NO_CLOCKS);
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
  U(valueReferences); U(nValueReferences); U(intervals);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetIntervalDecimal", NO_CLOCKS);
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
  U(valueReferences); U(nValueReferences); U(counters); U(resolutions);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetIntervalFraction", NO_CLOCKS);
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
  U(valueReferences); U(nValueReferences); U(shifts);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetShiftDecimal", NO_CLOCKS);
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
  U(valueReferences); U(nValueReferences); U(counters); U(resolutions);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetShiftFraction", NO_CLOCKS);
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
  U(clockReference); U(activationTime);
  return nnfmu_fmi3_unsupported(instance, "fmi3ActivateModelPartition", NO_CLOCKS);
}
