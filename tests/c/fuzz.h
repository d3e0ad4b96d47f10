/* What the FMU fuzz driver's two files share (tests/c/fuzz_driver.c, tests/c/fuzz_pointers.c).
 *
 * The driver is compiled against one FMU's sources (-I <unzipped FMU>/sources) so that it knows the
 * layout of a serialized state (nnfmu_values) and the value references; it loads the FMU's binary
 * with dlopen and calls it like an importer, with no Python per call. */
#ifndef FUZZ_H
#define FUZZ_H

#include <stddef.h>
#include <stdio.h>

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"
#include "nnfmu_instance.h" /* nnfmu_values, NNFMU_VR_*, NNFMU_TS: the layout the binary was built with */

void *sym(const char *name); /* the FMU's function `name`; exits if it is missing */
#define F2(name) ((fmi2##name##TYPE *)sym("fmi2" #name))
#define F3(name) ((fmi3##name##TYPE *)sym("fmi3" #name))

extern int version;       /* 2 or 3 */
extern int model_exchange; /* 1: instances are Model Exchange ones */
extern int error_logs;    /* how many Error messages the FMU logged */

/* An initialized instance: co-simulation in step mode after one sample, or Model Exchange in
 * continuous-time mode. `logger` 0 instantiates it without a logger. Exits on failure. */
void *make_instance(int logger);
void free_instance(void *c);
/* One more piece of work: doStep(t, Ts) from where the instance is, or getDerivatives. Its status. */
int advance(void *c);
int get_state(void *c, void **state);
int set_state(void *c, void *state);
int free_state(void *c, void **state);
int serialize(void *c, void *state, unsigned char *bytes, size_t size);
int deserialize(void *c, const unsigned char *bytes, size_t size, void **state);

/* Run pointer case number k (fuzz_pointers.c) in this process; returns 0 once k is past the last case. */
int pointer_case(int k);
int fmi3_cases(void *c); /* fuzz_pointers3.c */

/* The pointer cases: TRY(label, expect, expr) runs expr if it is case number case_want (counting with case_at)
 * and returns 1 if the status met `expect`, else 2 (with a FAIL line); a list of TRYs returns 0 when past it. */
enum { MUST_ERROR, MUST_FAIL, MUST_WORK, ANY }; /* Error and a logged message; not OK; OK; anything but a crash */
extern int case_at, case_want;
int case_check(const char *label, int expect, int status, int logged);
int instantiated(void *c); /* 0 for an instance (then freed), 3 for NULL */
#define TRY(label, expect, expr)                            \
  if (case_at++ == case_want) {                             \
    int logs_ = error_logs, status_;                        \
    printf("pointer case %d: %s\n", case_want, label);      \
    fflush(stdout);                                         \
    status_ = (int)(expr);                                  \
    return case_check(label, expect, status_, error_logs - logs_); \
  }

#endif /* FUZZ_H */
