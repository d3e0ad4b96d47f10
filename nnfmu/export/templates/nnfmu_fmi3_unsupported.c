/* nnfmu FMI 3.0: the functions that do not apply to a co-simulation FMU without clocks or event mode.
 * They exist because importers look up the whole API; each logs why and returns fmi3Error. */
#include <stddef.h>

#include "nnfmu_fmi3.h"

#define U(x) (void)(x)

#ifndef NNFMU_MODEL_EXCHANGE /* else in nnfmu_fmi3_me.c */
fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3EnterEventMode", NO_CLOCKS);
}
#endif
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
#ifndef NNFMU_MODEL_EXCHANGE /* else in nnfmu_fmi3_me.c */
fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
  U(discreteStatesNeedUpdate); U(terminateSimulation); U(nominalsOfContinuousStatesChanged);
  U(valuesOfContinuousStatesChanged); U(nextEventTimeDefined); U(nextEventTime);
  return nnfmu_fmi3_unsupported(instance, "fmi3UpdateDiscreteStates", NO_CLOCKS);
}
#endif

#ifndef NNFMU_MODEL_EXCHANGE /* else in nnfmu_fmi3_me.c */
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
  U(unknowns); U(nUnknowns); U(knowns); U(nKnowns); U(seed); U(nSeed); U(sensitivity); U(nSensitivity);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetDirectionalDerivative",
                                "providesDirectionalDerivatives is false");
}
#endif
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

/* Model exchange. */
#ifndef NNFMU_MODEL_EXCHANGE /* else in nnfmu_fmi3_me.c */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
  return nnfmu_fmi3_unsupported(instance, "fmi3EnterContinuousTimeMode", NO_MX);
}
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
  U(noSetFMUStatePriorToCurrentPoint); U(enterEventMode); U(terminateSimulation);
  return nnfmu_fmi3_unsupported(instance, "fmi3CompletedIntegratorStep", NO_MX);
}
fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
  U(time);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetTime", NO_MX);
}
fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
  U(continuousStates); U(nContinuousStates);
  return nnfmu_fmi3_unsupported(instance, "fmi3SetContinuousStates", NO_MX);
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
  U(derivatives); U(nContinuousStates);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetContinuousStateDerivatives", NO_MX);
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
  U(eventIndicators); U(nEventIndicators);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetEventIndicators", NO_MX);
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
  U(continuousStates); U(nContinuousStates);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetContinuousStates", NO_MX);
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
  U(nominals); U(nContinuousStates);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetNominalsOfContinuousStates", NO_MX);
}
fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
  U(nEventIndicators);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetNumberOfEventIndicators", NO_MX);
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
  U(nContinuousStates);
  return nnfmu_fmi3_unsupported(instance, "fmi3GetNumberOfContinuousStates", NO_MX);
}
#endif /* NNFMU_MODEL_EXCHANGE */
