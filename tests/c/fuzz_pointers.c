/* The pointer cases of the fuzz driver: NULL for every pointer argument of every FMI 2 and FMI 3 function an
 * importer may call, one at a time, and calls on a freed instance or a freed FMU state.
 *
 * pointer_case(k) sets up a fresh initialized instance and runs case k only: 1 if it met its expectation,
 * 2 if not (with a FAIL line), 0 when k is past the last case. The driver runs each in its own child. */
#include <stdio.h>
#include <stdlib.h>

#include "fuzz.h"

int case_at, case_want;

int case_check(const char *label, int expect, int status, int logged) {
  static const char *const expected[] = {"Error with a message", "not OK", "OK", "no crash"};
  int ok = expect == ANY || (expect == MUST_WORK && status == 0) || (expect == MUST_FAIL && status != 0) ||
           (expect == MUST_ERROR && status == 3 && logged);
  if (!ok) printf("FAIL pointer case %d, %s: expected %s, got status %d (%d messages)\n", case_want, label,
                  expected[expect], status, logged);
  return ok ? 1 : 2;
}

int instantiated(void *c) { return c ? (free_instance(c), 0) : 3; }

/* fmusim 0.0.39 frees a state by passing the state itself; the instance must go on. */
static int state_itself(void *c) {
  void *s = NULL;
  int status = get_state(c, &s);
  if (status == 0) status = free_state(c, (void **)s);
  return status ? status : advance(c) > 1 ? 3 : 0;
}

static int set_freed_state(void *c) {
  void *s = NULL, *dangling;
  get_state(c, &s);
  dangling = s;
  free_state(c, &s);
  return set_state(c, dangling); /* best effort: the memory is usually still mapped */
}

/* doStep (Model Exchange: getDerivatives) on an instance freed just before: must not report OK. */
static int call_freed(void *c) {
  double t = 0.0, dx[NNFMU_ALLOC(NNFMU_NX)];
  fmi3Boolean b[3];
  free_instance(c);
  if (model_exchange)
    return version == 2 ? F2(GetDerivatives)(c, dx, NNFMU_NX) : F3(GetContinuousStateDerivatives)(c, dx, NNFMU_NX);
  return version == 2 ? F2(DoStep)(c, NNFMU_TS, NNFMU_TS, fmi2True)
                      : F3(DoStep)(c, NNFMU_TS, NNFMU_TS, fmi3True, b, b + 1, b + 2, &t);
}

static int common_cases(void *c, void *st, unsigned char *buf, size_t n) {
  void *st2 = NULL;
  size_t size;
  TRY("getFMUState(FMUState = NULL)", MUST_ERROR, get_state(c, NULL));
  TRY("setFMUState(FMUState = NULL)", MUST_ERROR, set_state(c, NULL));
  TRY("freeFMUState(FMUState = NULL)", MUST_ERROR, free_state(c, NULL));
  TRY("serializeFMUState(FMUState = NULL)", MUST_ERROR, serialize(c, NULL, buf, n));
  TRY("serializeFMUState(serializedState = NULL)", MUST_ERROR, serialize(c, st, NULL, n));
  TRY("deserializeFMUState(serializedState = NULL)", MUST_ERROR, deserialize(c, NULL, n, &st2));
  TRY("deserializeFMUState(FMUState = NULL)", MUST_ERROR, deserialize(c, buf, n, NULL));
  TRY("serializedFMUStateSize(size = NULL)", MUST_ERROR,
      version == 2 ? F2(SerializedFMUstateSize)(c, st, NULL) : F3(SerializedFMUStateSize)(c, st, NULL));
  TRY("serializedFMUStateSize(FMUState = NULL)", ANY,
      version == 2 ? F2(SerializedFMUstateSize)(c, NULL, &size) : F3(SerializedFMUStateSize)(c, NULL, &size));
  TRY("freeFMUState(the state itself, as fmusim 0.0.39 passes it)", MUST_WORK, state_itself(c));
  TRY("setFMUState(a freed state)", MUST_ERROR, set_freed_state(c));
  TRY("doStep or getDerivatives after freeInstance", MUST_FAIL, call_freed(c));
  TRY("freeInstance twice", ANY, (free_instance(c), free_instance(c), 0));
  return 0;
}

static int fmi2_cases(void *c) {
  static fmi2CallbackFunctions callbacks = {NULL, calloc, free, NULL, NULL};
  const fmi2ValueReference get_vr[2] = {NNFMU_VR_TIME, NNFMU_VR_Y}, set_vr[2] = {NNFMU_VR_U, NNFMU_VR_U};
  const fmi2ValueReference int_vr[1] = {NNFMU_VR_MAX_SAMPLES}, bool_vr[1] = {NNFMU_VR_RANGE_ERROR};
  const fmi2Integer order[2] = {1, 1};
  double v[2] = {0.0, 0.0};
  fmi2Integer iv[1] = {1000};
  fmi2Boolean bv[1] = {fmi2False};
  fmi2String sv[1] = {""};
  const char *token = (const char *)NNFMU_TOKEN;
  TRY("fmi2GetReal(vr = NULL)", MUST_ERROR, F2(GetReal)(c, NULL, 2, v));
  TRY("fmi2GetReal(value = NULL)", MUST_ERROR, F2(GetReal)(c, get_vr, 2, NULL));
  TRY("fmi2SetReal(vr = NULL)", MUST_ERROR, F2(SetReal)(c, NULL, 2, v));
  TRY("fmi2SetReal(value = NULL)", MUST_ERROR, F2(SetReal)(c, set_vr, 2, NULL));
  TRY("fmi2GetInteger(vr = NULL)", MUST_ERROR, F2(GetInteger)(c, NULL, 1, iv));
  TRY("fmi2GetInteger(value = NULL)", MUST_ERROR, F2(GetInteger)(c, int_vr, 1, NULL));
  TRY("fmi2SetInteger(vr = NULL)", MUST_ERROR, F2(SetInteger)(c, NULL, 1, iv));
  TRY("fmi2SetInteger(value = NULL)", MUST_ERROR, F2(SetInteger)(c, int_vr, 1, NULL));
  TRY("fmi2GetBoolean(vr = NULL)", MUST_ERROR, F2(GetBoolean)(c, NULL, 1, bv));
  TRY("fmi2GetBoolean(value = NULL)", MUST_ERROR, F2(GetBoolean)(c, bool_vr, 1, NULL));
  TRY("fmi2SetBoolean(vr = NULL)", MUST_ERROR, F2(SetBoolean)(c, NULL, 1, bv));
  TRY("fmi2SetBoolean(value = NULL)", MUST_ERROR, F2(SetBoolean)(c, bool_vr, 1, NULL));
  TRY("fmi2GetString(vr = NULL)", MUST_ERROR, F2(GetString)(c, NULL, 1, sv));
  TRY("fmi2GetString(value = NULL)", MUST_ERROR, F2(GetString)(c, get_vr, 1, NULL));
  TRY("fmi2SetString(vr = NULL)", MUST_ERROR, F2(SetString)(c, NULL, 1, sv));
  TRY("fmi2SetString(value = NULL)", MUST_ERROR, F2(SetString)(c, get_vr, 1, NULL));
  TRY("fmi2GetDirectionalDerivative(vUnknown_ref = NULL)", MUST_ERROR,
      F2(GetDirectionalDerivative)(c, NULL, 1, set_vr, 1, v, v));
  TRY("fmi2GetDirectionalDerivative(vKnown_ref = NULL)", MUST_ERROR,
      F2(GetDirectionalDerivative)(c, get_vr + 1, 1, NULL, 1, v, v));
  TRY("fmi2GetDirectionalDerivative(dvKnown = NULL)", MUST_ERROR,
      F2(GetDirectionalDerivative)(c, get_vr + 1, 1, set_vr, 1, NULL, v));
  TRY("fmi2GetDirectionalDerivative(dvUnknown = NULL)", MUST_ERROR,
      F2(GetDirectionalDerivative)(c, get_vr + 1, 1, set_vr, 1, v, NULL));
  TRY("fmi2SetRealInputDerivatives(vr = NULL)", MUST_ERROR, F2(SetRealInputDerivatives)(c, NULL, 1, order, v));
  TRY("fmi2SetRealInputDerivatives(order = NULL)", MUST_ERROR, F2(SetRealInputDerivatives)(c, set_vr, 1, NULL, v));
  TRY("fmi2SetRealInputDerivatives(value = NULL)", MUST_ERROR,
      F2(SetRealInputDerivatives)(c, set_vr, 1, order, NULL));
  TRY("fmi2GetRealOutputDerivatives(vr = NULL)", MUST_ERROR, F2(GetRealOutputDerivatives)(c, NULL, 1, order, v));
  TRY("fmi2GetRealOutputDerivatives(order = NULL)", MUST_ERROR,
      F2(GetRealOutputDerivatives)(c, get_vr + 1, 1, NULL, v));
  TRY("fmi2GetRealOutputDerivatives(value = NULL)", MUST_ERROR,
      F2(GetRealOutputDerivatives)(c, get_vr + 1, 1, order, NULL));
  TRY("fmi2GetStatus(value = NULL)", MUST_ERROR, F2(GetStatus)(c, fmi2DoStepStatus, NULL));
  TRY("fmi2GetRealStatus(value = NULL)", MUST_ERROR, F2(GetRealStatus)(c, fmi2LastSuccessfulTime, NULL));
  TRY("fmi2GetIntegerStatus(value = NULL)", MUST_ERROR, F2(GetIntegerStatus)(c, fmi2DoStepStatus, NULL));
  TRY("fmi2GetBooleanStatus(value = NULL)", MUST_ERROR, F2(GetBooleanStatus)(c, fmi2Terminated, NULL));
  TRY("fmi2GetStringStatus(value = NULL)", MUST_ERROR, F2(GetStringStatus)(c, fmi2PendingStatus, NULL));
  TRY("fmi2SetDebugLogging(categories = NULL)", ANY, F2(SetDebugLogging)(c, fmi2True, 2, NULL));
  TRY("fmi2Instantiate(instanceName = NULL)", ANY, instantiated(F2(Instantiate)(
      NULL, model_exchange ? fmi2ModelExchange : fmi2CoSimulation, token, NULL, &callbacks, fmi2False, fmi2False)));
  TRY("fmi2Instantiate(functions = NULL)", ANY, instantiated(F2(Instantiate)(
      "x", model_exchange ? fmi2ModelExchange : fmi2CoSimulation, token, NULL, NULL, fmi2False, fmi2False)));
  TRY("fmi2Instantiate(fmuGUID = NULL)", MUST_FAIL, instantiated(F2(Instantiate)(
      "x", model_exchange ? fmi2ModelExchange : fmi2CoSimulation, NULL, NULL, &callbacks, fmi2False, fmi2False)));
  if (!model_exchange) return 0;
  TRY("fmi2NewDiscreteStates(eventInfo = NULL)", MUST_ERROR, (F2(EnterEventMode)(c), F2(NewDiscreteStates)(c, NULL)));
  TRY("fmi2CompletedIntegratorStep(enterEventMode = NULL)", MUST_ERROR,
      F2(CompletedIntegratorStep)(c, fmi2True, NULL, bv));
  TRY("fmi2CompletedIntegratorStep(terminateSimulation = NULL)", MUST_ERROR,
      F2(CompletedIntegratorStep)(c, fmi2True, bv, NULL));
  TRY("fmi2SetContinuousStates(x = NULL)", MUST_ERROR, F2(SetContinuousStates)(c, NULL, NNFMU_NX));
  TRY("fmi2GetDerivatives(derivatives = NULL)", MUST_ERROR, F2(GetDerivatives)(c, NULL, NNFMU_NX));
  TRY("fmi2GetEventIndicators(eventIndicators = NULL)", MUST_ERROR, F2(GetEventIndicators)(c, NULL, 1));
  TRY("fmi2GetContinuousStates(x = NULL)", MUST_ERROR, F2(GetContinuousStates)(c, NULL, NNFMU_NX));
  TRY("fmi2GetNominalsOfContinuousStates(x_nominal = NULL)", MUST_ERROR,
      F2(GetNominalsOfContinuousStates)(c, NULL, NNFMU_NX));
  return 0;
}

int pointer_case(int k) {
  void *c = make_instance(1), *st = NULL;
  unsigned char buf[24 + sizeof(nnfmu_values)];
  int done;
  case_at = 0;
  case_want = k;
  if (get_state(c, &st) || serialize(c, st, buf, sizeof buf)) {
    printf("FAIL pointer cases: could not save a state\n");
    return 2;
  }
  done = version == 2 ? fmi2_cases(c) : fmi3_cases(c);
  return done ? done : common_cases(c, st, buf, sizeof buf);
}
