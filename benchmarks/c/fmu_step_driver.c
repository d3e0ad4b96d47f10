/* Step-time driver for an FMI 2.0 co-simulation FMU: no Python per step, process CPU time.
 *
 * usage: fmu_step_driver LIBRARY GUID TS N_STEPS "U_VRS" "Y_VRS" [REPEATS]
 *   LIBRARY  path of binaries/<platform>/<id>.so      GUID   the FMU's guid
 *   U_VRS, Y_VRS  comma-separated value references of the inputs and outputs
 * Instantiates and initialises the FMU, runs N_STEPS steps once to warm the caches, then REPEATS
 * times (default 3) resets the instance and times N_STEPS steps of size Ts, each being what a
 * co-simulation master does: fmi2SetReal(inputs), fmi2DoStep(t, Ts), fmi2GetReal(outputs). The
 * inputs are deterministic sinusoids computed before the timed loop. The time is the process's CPU
 * time (CLOCK_PROCESS_CPUTIME_ID), so time slices lost to other processes on a shared machine do not
 * count; pin the process to one core (taskset) so that it does not migrate. The least of the
 * repeats is the run that other processes disturbed least (they still evict the caches when they
 * run on the same core). Prints it, per step, in microseconds, and the final outputs (to check that
 * every build computes the same run):
 *   us_per_step=<t> y_final=<y1>,<y2>,...
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_VARS 64

static double cpu_seconds(void) {
  struct timespec t;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void log_message(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                        fmi2String message, ...) {
  (void)env;
  fprintf(stderr, "[%s %d %s] %s\n", name, (int)status, category, message);
}

static int parse_vrs(const char *text, fmi2ValueReference *vrs) {
  int n = 0;
  char *end;
  while (*text && n < MAX_VARS) {
    vrs[n++] = (fmi2ValueReference)strtoul(text, &end, 10);
    text = (*end == ',') ? end + 1 : end;
    if (end == text && *text) break; /* not a number: stop */
  }
  return n;
}

static void *symbol(void *lib, const char *name) {
  void *f = dlsym(lib, name);
  if (!f) {
    fprintf(stderr, "missing FMI function %s\n", name);
    exit(2);
  }
  return f;
}

typedef struct {
  fmi2SetRealTYPE *set_real;
  fmi2GetRealTYPE *get_real;
  fmi2DoStepTYPE *do_step;
} stepper;

/* n_steps steps from the instance's current state; returns 0 on success. */
static int run(const stepper *s, fmi2Component c, const double *inputs, long n_steps, double ts,
               const fmi2ValueReference *u_vr, int n_u, const fmi2ValueReference *y_vr, int n_y, double *y) {
  long k;
  for (k = 0; k < n_steps; ++k)
    if (s->set_real(c, u_vr, (size_t)n_u, inputs + k * n_u) != fmi2OK ||
        s->do_step(c, (double)k * ts, ts, fmi2True) != fmi2OK || s->get_real(c, y_vr, (size_t)n_y, y) != fmi2OK) {
      fprintf(stderr, "step %ld failed\n", k);
      return 1;
    }
  return 0;
}

int main(int argc, char **argv) {
  fmi2ValueReference u_vr[MAX_VARS], y_vr[MAX_VARS];
  fmi2Real y[MAX_VARS];
  fmi2CallbackFunctions callbacks = {log_message, NULL, NULL, NULL, NULL};
  double ts, t0, best = 1e300, *inputs;
  long n_steps, k;
  int n_u, n_y, i, pass, repeats;
  void *lib;
  stepper s;
  if (argc != 7 && argc != 8) {
    fprintf(stderr, "usage: %s LIBRARY GUID TS N_STEPS U_VRS Y_VRS [REPEATS]\n", argv[0]);
    return 2;
  }
  repeats = argc == 8 ? atoi(argv[7]) : 3;
  ts = atof(argv[3]);
  n_steps = atol(argv[4]);
  n_u = parse_vrs(argv[5], u_vr);
  n_y = parse_vrs(argv[6], y_vr);
  inputs = (double *)malloc(sizeof(double) * (size_t)(n_steps * (n_u > 0 ? n_u : 1)));
  for (k = 0; k < n_steps; ++k)
    for (i = 0; i < n_u; ++i) inputs[k * n_u + i] = sin(0.01 * (double)k * (i + 1)) * (1.0 + 0.5 * i);
  lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!inputs || !lib) {
    fprintf(stderr, "cannot load %s: %s\n", argv[1], lib ? "out of memory" : dlerror());
    return 2;
  }
  s.set_real = (fmi2SetRealTYPE *)symbol(lib, "fmi2SetReal");
  s.get_real = (fmi2GetRealTYPE *)symbol(lib, "fmi2GetReal");
  s.do_step = (fmi2DoStepTYPE *)symbol(lib, "fmi2DoStep");
  {
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)symbol(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = (fmi2EnterInitializationModeTYPE *)symbol(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init = (fmi2ExitInitializationModeTYPE *)symbol(lib, "fmi2ExitInitializationMode");
    fmi2ResetTYPE *reset = (fmi2ResetTYPE *)symbol(lib, "fmi2Reset");
    fmi2Component c = instantiate("bench", fmi2CoSimulation, argv[2], "", &callbacks, fmi2False, fmi2False);
    for (pass = 0; pass <= repeats; ++pass) { /* pass 0 warms the caches, the others are timed */
      if (!c || (pass && reset(c) != fmi2OK) || setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||
          enter(c) != fmi2OK || exit_init(c) != fmi2OK) {
        fprintf(stderr, "initialisation failed\n");
        return 1;
      }
      t0 = cpu_seconds();
      if (run(&s, c, inputs, n_steps, ts, u_vr, n_u, y_vr, n_y, y)) return 1;
      t0 = cpu_seconds() - t0;
      if (pass && t0 < best) best = t0;
    }
  }
  printf("us_per_step=%.4f y_final=", best / (double)n_steps * 1e6);
  for (i = 0; i < n_y; ++i) printf("%s%.17g", i ? "," : "", y[i]);
  printf("\n");
  return 0;
}
