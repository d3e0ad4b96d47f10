/* A minimal FMI 2.0 / 3.0 co-simulation importer for the test suite (tests/test_fmu_c_importer.py).
 *
 * It is built WITHOUT the C math library (no -lm) and loads an FMU's binary with dlopen, so it shows
 * that the binary brings what it needs; every step is a plain C call, no Python in the loop.
 *
 *   fmu_driver LIB TOKEN VERSION TS run N         N samples, steps of Ts, inputs from a rational formula;
 *                                                 prints the outputs after each step
 *   fmu_driver LIB TOKEN VERSION TS schedule N BLOCK [T0]  from start time T0 (default 0), one instance
 *                                                 steps N samples one by one at fmpy's communication
 *                                                 points (t_n = T0 + n Ts, h = t_n+1 - t_n), a
 *                                                 second one BLOCK samples per step with the same held
 *                                                 inputs; compares them bitwise at every block end, then
 *                                                 asks the second for a step of 1e9 s
 *
 * Value references follow nnfmu's layout: inputs from 4 (2 of them), outputs right after.
 *
 * The same source builds for Windows (LoadLibrary) and for other targets, so that the test suite runs
 * cross-compiled FMU binaries with a driver of their own target (tests/test_fmu_platforms.py). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef _WIN32
#include <windows.h>
static void *open_library(const char *path) { return (void *)LoadLibraryA(path); }
static void *find_symbol(void *library, const char *name) { return (void *)GetProcAddress((HMODULE)library, name); }
static const char *open_error(void) { return "LoadLibraryA failed"; }
static const char *libm_loaded(void) { return "no (Windows: the maths is in the C runtime)"; }
#else
#include <dlfcn.h>
static void *open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *find_symbol(void *library, const char *name) { return dlsym(library, name); }
static const char *open_error(void) { return dlerror(); }
static const char *libm_loaded(void) { return dlopen("libm.so.6", RTLD_LAZY | RTLD_NOLOAD) ? "yes" : "no"; }
#endif

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#define N_U 2
#define N_Y 2
#define VR_U 4
#define VR_Y 6

static void *lib;
static int version;
static const char *token;
static double Ts;

static void *must(const char *name) {
  void *f = find_symbol(lib, name);
  if (!f) { printf("missing symbol %s\n", name); exit(3); }
  return f;
}

/* The per-step functions, looked up once. */
static fmi2SetRealTYPE *set2;
static fmi2GetRealTYPE *get2;
static fmi2DoStepTYPE *step2;
static fmi3SetFloat64TYPE *set3;
static fmi3GetFloat64TYPE *get3;
static fmi3DoStepTYPE *step3;

static void resolve(void) {
  if (version == 2) {
    set2 = (fmi2SetRealTYPE *)must("fmi2SetReal");
    get2 = (fmi2GetRealTYPE *)must("fmi2GetReal");
    step2 = (fmi2DoStepTYPE *)must("fmi2DoStep");
  } else {
    set3 = (fmi3SetFloat64TYPE *)must("fmi3SetFloat64");
    get3 = (fmi3GetFloat64TYPE *)must("fmi3GetFloat64");
    step3 = (fmi3DoStepTYPE *)must("fmi3DoStep");
  }
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                 fmi2String message, ...) {
  (void)env; (void)name; (void)category;
  printf("log %d %s\n", (int)status, message);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
  (void)env; (void)category;
  printf("log %d %s\n", (int)status, message);
}

/* One instance behind a version-neutral face. */
typedef struct { void *c; } fmu;

static fmu instantiate(const char *name, double t0) {
  static fmi2CallbackFunctions callbacks = {logger2, calloc, free, NULL, NULL};
  fmu f;
  if (version == 2) {
    fmi2Component c = ((fmi2InstantiateTYPE *)must("fmi2Instantiate"))(name, fmi2CoSimulation, token, "", &callbacks,
                                                                        fmi2False, fmi2False);
    if (!c || ((fmi2SetupExperimentTYPE *)must("fmi2SetupExperiment"))(c, fmi2False, 0, t0, fmi2False, 0) ||
        ((fmi2EnterInitializationModeTYPE *)must("fmi2EnterInitializationMode"))(c) ||
        ((fmi2ExitInitializationModeTYPE *)must("fmi2ExitInitializationMode"))(c)) { printf("init failed\n"); exit(4); }
    f.c = c;
  } else {
    fmi3Instance c = ((fmi3InstantiateCoSimulationTYPE *)must("fmi3InstantiateCoSimulation"))(
        name, token, "", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger3, NULL);
    if (!c || ((fmi3EnterInitializationModeTYPE *)must("fmi3EnterInitializationMode"))(c, fmi3False, 0, t0, fmi3False, 0) ||
        ((fmi3ExitInitializationModeTYPE *)must("fmi3ExitInitializationMode"))(c)) { printf("init failed\n"); exit(4); }
    f.c = c;
  }
  return f;
}

static void set_inputs(fmu f, const double *u) {
  unsigned int vr[N_U] = {VR_U, VR_U + 1};
  int status = version == 2 ? set2(f.c, vr, N_U, u) : set3(f.c, vr, N_U, u, N_U);
  if (status) { printf("set failed\n"); exit(5); }
}

static void get_outputs(fmu f, double *y) {
  unsigned int vr[N_Y] = {VR_Y, VR_Y + 1};
  int status = version == 2 ? get2(f.c, vr, N_Y, y) : get3(f.c, vr, N_Y, y, N_Y);
  if (status) { printf("get failed\n"); exit(5); }
}

static void free_instance(fmu f) {
  if (version == 2) ((fmi2FreeInstanceTYPE *)must("fmi2FreeInstance"))(f.c);
  else ((fmi3FreeInstanceTYPE *)must("fmi3FreeInstance"))(f.c);
}

static int do_step(fmu f, double t, double h) {
  fmi3Boolean event, terminate, early;
  fmi3Float64 last;
  if (version == 2) return step2(f.c, t, h, fmi2True);
  return step3(f.c, t, h, fmi3True, &event, &terminate, &early, &last);
}

/* Inputs as exact rationals, so that Python computes the same values. */
static void input(long long k, double *u) {
  u[0] = (double)((k * 7) % 13) / 13.0 * 2.0 + 0.5;
  u[1] = (double)((k * 5) % 11) / 11.0 * 2.0;
}

static int run(long long n) {
  fmu f = instantiate("run", 0.0);
  double u[N_U], y[N_Y];
  long long k;
  for (k = 0; k < n; ++k) {
    input(k, u);
    set_inputs(f, u);
    if (do_step(f, (double)k * Ts, Ts) > 1) { printf("step %lld failed\n", k); return 6; }
    get_outputs(f, y);
    printf("y %.17g %.17g\n", y[0], y[1]);
  }
  free_instance(f);
  return 0;
}

static int schedule(long long n, long long block, double t0) {
  fmu a = instantiate("one-by-one", t0), b = instantiate("blocks", t0);
  double u[N_U], ya[N_Y], yb[N_Y], t = t0, t_next;
  long long k, mismatches = 0;
  int status, worst = 0;
  for (k = 0; k < n; ++k) {
    if (k % block == 0) {
      input(k / block, u);
      set_inputs(a, u);
      set_inputs(b, u);
      status = do_step(b, t0 + (double)k * Ts, (t0 + (double)(k + block) * Ts) - (t0 + (double)k * Ts));
      if (status > worst) worst = status;
    }
    t_next = t0 + (double)(k + 1) * Ts; /* fmpy: time = start + n * interval; h = difference of those */
    status = do_step(a, t, t_next - t);
    if (status > worst) worst = status;
    if (status > 1) { printf("step %lld at t = %.17g failed with status %d\n", k, t, status); return 6; }
    t = t_next;
    if ((k + 1) % block == 0) {
      get_outputs(a, ya);
      get_outputs(b, yb);
      if (memcmp(ya, yb, sizeof ya) != 0) ++mismatches;
    }
  }
  get_outputs(a, ya);
  printf("samples %lld time %.17g worst %d mismatches %lld y %.17g %.17g\n", n, t, worst, mismatches, ya[0], ya[1]);
  status = do_step(b, t0 + (double)n * Ts, 1e9);
  printf("huge step status %d\n", status);
  free_instance(a);
  free_instance(b);
  return 0;
}

int main(int argc, char **argv) {
  if (argc < 7) { printf("usage: fmu_driver LIB TOKEN VERSION TS run N | schedule N BLOCK\n"); return 2; }
  printf("libm loaded before the FMU: %s\n", libm_loaded());
  lib = open_library(argv[1]);
  if (!lib) { printf("loading %s failed: %s\n", argv[1], open_error()); return 1; }
  token = argv[2];
  version = atoi(argv[3]);
  Ts = strtod(argv[4], NULL);
  resolve();
  if (strcmp(argv[5], "run") == 0) return run(atoll(argv[6]));
  if (strcmp(argv[5], "schedule") == 0 && argc > 7)
    return schedule(atoll(argv[6]), atoll(argv[7]), argc > 8 ? strtod(argv[8], NULL) : 0.0);
  printf("unknown mode %s\n", argv[5]);
  return 2;
}
