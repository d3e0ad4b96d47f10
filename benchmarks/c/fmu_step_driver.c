/* Step-time driver for an FMI 2.0 co-simulation FMU: no Python per step.
 *
 * usage: fmu_step_driver LIBRARY GUID TS N_STEPS REPEATS "U_VRS" "Y_VRS"
 *   LIBRARY  path of binaries/<platform>/<id>.so      GUID   the FMU's guid
 *   U_VRS, Y_VRS  comma-separated value references of the inputs and outputs
 * Each repeat instantiates, initialises and runs N_STEPS steps of size Ts, each being what a
 * co-simulation master does: fmi2SetReal(inputs), fmi2DoStep(t, Ts), fmi2GetReal(outputs).
 * The inputs are deterministic sinusoids. Prints the minimum over repeats of the time per step in
 * microseconds and the final outputs (to check that the run is the same in every build):
 *   us_per_step=<min> y_final=<y1>,<y2>,...
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

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
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

int main(int argc, char **argv) {
  fmi2ValueReference u_vr[MAX_VARS], y_vr[MAX_VARS];
  fmi2Real u[MAX_VARS], y[MAX_VARS];
  fmi2CallbackFunctions callbacks = {log_message, NULL, NULL, NULL, NULL};
  double ts, best = 1e300;
  long n_steps, repeats, r, k;
  int n_u, n_y, i;
  void *lib;
  if (argc != 8) {
    fprintf(stderr, "usage: %s LIBRARY GUID TS N_STEPS REPEATS U_VRS Y_VRS\n", argv[0]);
    return 2;
  }
  ts = atof(argv[3]);
  n_steps = atol(argv[4]);
  repeats = atol(argv[5]);
  n_u = parse_vrs(argv[6], u_vr);
  n_y = parse_vrs(argv[7], y_vr);
  lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!lib) {
    fprintf(stderr, "cannot load %s: %s\n", argv[1], dlerror());
    return 2;
  }
  {
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)symbol(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter = (fmi2EnterInitializationModeTYPE *)symbol(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init = (fmi2ExitInitializationModeTYPE *)symbol(lib, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set_real = (fmi2SetRealTYPE *)symbol(lib, "fmi2SetReal");
    fmi2GetRealTYPE *get_real = (fmi2GetRealTYPE *)symbol(lib, "fmi2GetReal");
    fmi2DoStepTYPE *do_step = (fmi2DoStepTYPE *)symbol(lib, "fmi2DoStep");
    fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)symbol(lib, "fmi2FreeInstance");
    for (r = 0; r < repeats; ++r) {
      double t0, elapsed;
      fmi2Component c = instantiate("bench", fmi2CoSimulation, argv[2], "", &callbacks, fmi2False, fmi2False);
      if (!c || setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK || enter(c) != fmi2OK ||
          exit_init(c) != fmi2OK) {
        fprintf(stderr, "initialisation failed\n");
        return 1;
      }
      t0 = now_s();
      for (k = 0; k < n_steps; ++k) {
        for (i = 0; i < n_u; ++i) u[i] = sin(0.01 * (double)k * (i + 1)) * (1.0 + 0.5 * i);
        if (set_real(c, u_vr, (size_t)n_u, u) != fmi2OK || do_step(c, (double)k * ts, ts, fmi2True) != fmi2OK ||
            get_real(c, y_vr, (size_t)n_y, y) != fmi2OK) {
          fprintf(stderr, "step %ld failed\n", k);
          return 1;
        }
      }
      elapsed = (now_s() - t0) / (double)n_steps * 1e6;
      if (elapsed < best) best = elapsed;
      free_instance(c);
    }
  }
  printf("us_per_step=%.4f y_final=", best);
  for (i = 0; i < n_y; ++i) printf("%s%.17g", i ? "," : "", y[i]);
  printf("\n");
  return 0;
}
