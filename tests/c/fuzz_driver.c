/* The FMU fuzz guard (tests/test_fmu_fuzz.py): hostile serialized states and NULL pointers, from C.
 *
 *   fuzz_driver LIB VERSION cs|me N SEED    (built with -I <the FMU's sources>, whose binary LIB is)
 *
 * 1. N serialized states, made from a real one: 1-8 byte flips, a random payload behind a valid header
 *    (with a wrong and with a right checksum), crafted fields with a right checksum (mode 0x7fffffff,
 *    sample count -4e12 with step limit 9e18, NaN time, ...), wrong sizes and NULL, and the real state
 *    itself. Every broken one must be refused with a logged Error while the instance keeps working; the
 *    real one must be accepted and resume. Cases run in forked children, 250 at a time, each batch under
 *    alarm(): a crash or a hang is found and named case by case.
 * 2. Every pointer case of fuzz_pointers.c, each in its own child under alarm().
 *
 * Prints one line per failure and a summary line; exits 0 only if nothing failed. */
#define _POSIX_C_SOURCE 200809L /* fork, alarm, waitpid */
#include <dlfcn.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "fuzz.h"

#define HEADER 24 /* magic, token hash, checksum */
#define BATCH 250
#define SECONDS 10 /* per batch or pointer case: far above the milliseconds they take */

static void *lib;
static const char *const token = NNFMU_TOKEN;
int version, model_exchange, error_logs;
static unsigned char good[HEADER + sizeof(nnfmu_values)];
static void *base; /* the instance the state cases run on (each batch's child has its own copy) */
static unsigned long long seed;

void *sym(const char *name) {
  void *f = dlsym(lib, name);
  if (!f) { printf("missing symbol %s\n", name); exit(3); }
  return f;
}

static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...) {
  (void)env; (void)name; (void)category; (void)message;
  if (status >= fmi2Error) ++error_logs;
}
static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
  (void)env; (void)category; (void)message;
  if (status >= fmi3Error) ++error_logs;
}

void *make_instance(int logger) {
  static fmi2CallbackFunctions with = {logger2, calloc, free, NULL, NULL}, without = {NULL, calloc, free, NULL, NULL};
  fmi2EventInfo info;
  fmi3Boolean a, b, cc, d, e;
  fmi3Float64 next;
  void *c;
  int bad;
  if (version == 2) {
    c = F2(Instantiate)("fuzz", model_exchange ? fmi2ModelExchange : fmi2CoSimulation, token, "",
                        logger ? &with : &without, fmi2False, fmi2False);
    bad = !c || F2(SetupExperiment)(c, fmi2False, 0, 0.0, fmi2False, 0) || F2(EnterInitializationMode)(c) ||
          F2(ExitInitializationMode)(c) ||
          (model_exchange && (F2(NewDiscreteStates)(c, &info) || F2(EnterContinuousTimeMode)(c)));
  } else {
    c = model_exchange ? F3(InstantiateModelExchange)("fuzz", token, NULL, fmi3False, fmi3False, NULL,
                                                      logger ? logger3 : NULL)
                       : F3(InstantiateCoSimulation)("fuzz", token, NULL, fmi3False, fmi3False, fmi3False, fmi3False,
                                                     NULL, 0, NULL, logger ? logger3 : NULL, NULL);
    bad = !c || F3(EnterInitializationMode)(c, fmi3False, 0, 0.0, fmi3False, 0) || F3(ExitInitializationMode)(c) ||
          (model_exchange && (F3(UpdateDiscreteStates)(c, &a, &b, &cc, &d, &e, &next) ||
                              F3(EnterContinuousTimeMode)(c)));
  }
  if (bad || (model_exchange && (version == 2 ? F2(SetTime)(c, 0.01) : F3(SetTime)(c, 0.01))) || advance(c) > 1) {
    printf("could not initialize an instance\n");
    exit(4);
  }
  return c;
}

void free_instance(void *c) {
  if (version == 2) F2(FreeInstance)(c);
  else F3(FreeInstance)(c);
}

int advance(void *c) {
  const unsigned int vr = NNFMU_VR_TIME;
  double t = 0.0, dx[NNFMU_ALLOC(NNFMU_NX)];
  fmi3Boolean event, terminate, early;
  int status;
  if (model_exchange)
    return version == 2 ? F2(GetDerivatives)(c, dx, NNFMU_NX) : F3(GetContinuousStateDerivatives)(c, dx, NNFMU_NX);
  status = version == 2 ? F2(GetReal)(c, &vr, 1, &t) : F3(GetFloat64)(c, &vr, 1, &t, 1);
  if (status > 1) return status;
  return version == 2 ? F2(DoStep)(c, t, NNFMU_TS, fmi2True)
                      : F3(DoStep)(c, t, NNFMU_TS, fmi3True, &event, &terminate, &early, &t);
}

int get_state(void *c, void **s) { return version == 2 ? F2(GetFMUstate)(c, s) : F3(GetFMUState)(c, s); }
int set_state(void *c, void *s) { return version == 2 ? F2(SetFMUstate)(c, s) : F3(SetFMUState)(c, s); }
int free_state(void *c, void **s) { return version == 2 ? F2(FreeFMUstate)(c, s) : F3(FreeFMUState)(c, s); }
int serialize(void *c, void *s, unsigned char *bytes, size_t n) {
  return version == 2 ? F2(SerializeFMUstate)(c, s, (fmi2Byte *)bytes, n) : F3(SerializeFMUState)(c, s, bytes, n);
}
int deserialize(void *c, const unsigned char *bytes, size_t n, void **s) {
  return version == 2 ? F2(DeSerializeFMUstate)(c, (const fmi2Byte *)bytes, n, s)
                      : F3(DeserializeFMUState)(c, bytes, n, s);
}

/* ---- the state cases ------------------------------------------------------------------------ */

static unsigned long long next_random(unsigned long long *r) { /* xorshift64* */
  *r ^= *r >> 12; *r ^= *r << 25; *r ^= *r >> 27;
  return *r * 2685821657736338717ULL;
}

static void seal(unsigned char *buf) { /* the checksum of the payload, as the FMU computes it (FNV-1a) */
  unsigned long long h = 1469598103934665603ULL;
  size_t i;
  for (i = HEADER; i < sizeof good; ++i) h = (h ^ buf[i]) * 1099511628211ULL;
  memcpy(buf + 16, &h, 8);
}

/* Change one field of v (crafted case i); returns whether the FMU must refuse the result. */
static int craft(nnfmu_values *v, int i, unsigned long long r) {
  const int cs = !model_exchange;
  switch (i) {
    case 0: v->mode = (nnfmu_mode)0x7fffffff; return 1;
    case 1: v->mode = (nnfmu_mode)0; return 1;
    case 2: v->mode = (nnfmu_mode)(MODE_STEP | MODE_EVENT); return 1;
    case 3: v->mode = (nnfmu_mode)128; return 1;
    case 4: v->mode = cs ? MODE_EVENT : MODE_STEP; return 1; /* the other interface's mode */
    case 5: v->samples = -4000000000000LL; v->max_samples = 9000000000000000000LL; return 1;
    case 6: v->samples = -1; return 1;
    case 7: v->samples += 1; return 1;
    case 8: v->max_samples = 9000000000000000000LL; return 1;
    case 9: v->max_samples = 0; return 1;
    case 10: v->time = NAN; return 1;
    case 11: v->time = INFINITY; return 1;
    case 12: v->start_time = -INFINITY; return 1;
    case 13: v->x_ready = 2; return 1;
    case 14: v->range_error = 7; return 1;
    case 15: v->outside[0] = 2; return NNFMU_NU > 0;
    case 16: v->time += 1e6; return cs;
    case 17: v->start_time = v->time + 1.0; return cs;
    case 18: v->y[0] = NAN; return cs;
    case 19: v->x[0] = INFINITY; return cs && NNFMU_NX > 0;
    case 20: v->x_ready = 0; return cs;
    case 21: v->mode = (nnfmu_mode)(int)(r | 0x100); return 1;
    case 22: v->samples = -(long long)(r >> 2) - 1; return 1;
    default: v->max_samples = (long long)(r >> 1) | 0x100000000LL; return 1;
  }
}
#define N_CRAFTED 24

/* Build state case k into buf; *size its length (0 with *null: a NULL buffer). Returns 1 if it must be refused. */
static int make_case(int k, unsigned char *buf, size_t *size, int *null, const char **kind) {
  unsigned long long r = seed * 1000003ULL + (unsigned long long)k * 7919ULL + 1;
  nnfmu_values v;
  size_t i, n, pos[8];
  int j, must_refuse = 1;
  next_random(&r);
  memcpy(buf, good, sizeof good);
  *size = sizeof good;
  *null = 0;
  switch (k % 6) {
    case 0:
      *kind = "byte flips";
      n = 1 + next_random(&r) % 8;
      for (i = 0; i < n;) { /* at n distinct positions, a nonzero XOR */
        size_t p = next_random(&r) % sizeof good;
        for (j = 0; j < (int)i && pos[j] != p; ++j) continue;
        if (j < (int)i) continue;
        pos[i++] = p;
        buf[p] ^= (unsigned char)(1 + next_random(&r) % 255);
      }
      break;
    case 1: case 2:
      *kind = k % 6 == 1 ? "random payload, wrong checksum" : "random payload, right checksum";
      for (i = 16; i < sizeof good; ++i) buf[i] = (unsigned char)next_random(&r);
      if (k % 6 == 2) seal(buf);
      break;
    case 3:
      *kind = "crafted field";
      memcpy(&v, good + HEADER, sizeof v);
      must_refuse = craft(&v, (k / 6) % N_CRAFTED, next_random(&r));
      memcpy(buf + HEADER, &v, sizeof v);
      seal(buf);
      break;
    case 4: {
      static const long delta[] = {-1, 1, -(long)sizeof good, 8 - (long)sizeof good, 0};
      *kind = "wrong size or NULL";
      *size = sizeof good + delta[(k / 6) % 5];
      *null = (k / 6) % 5 == 4;
      break;
    }
    default:
      *kind = "the real state";
      must_refuse = 0;
  }
  return must_refuse;
}

static void restore_good(void *c) {
  void *s = NULL;
  if (deserialize(c, good, sizeof good, &s) || set_state(c, s) || free_state(c, &s)) {
    printf("FAIL the real state could not be restored\n");
    exit(1);
  }
}

/* State cases [a, b) on this process's copy of `base`; 1 if any expectation failed. */
static int state_cases(int a, int b) {
  unsigned char buf[sizeof good];
  const char *kind;
  size_t size;
  int k, null, must_refuse, status, logs, failed = 0;
  for (k = a; k < b; ++k) {
    void *s = NULL;
    must_refuse = make_case(k, buf, &size, &null, &kind);
    logs = error_logs;
    status = deserialize(base, null ? NULL : buf, size, &s);
    if (status == 0) {
      if (must_refuse) { printf("FAIL state case %d (%s) was accepted\n", k, kind); failed = 1; }
      if (set_state(base, s) == 0) status = advance(base); /* whatever it holds: no crash, no hang */
      free_state(base, &s);
      if (k % 6 == 5 && status > 1) { /* the real state resumes */
        printf("FAIL state case %d (%s): resuming gave %d\n", k, kind, status);
        failed = 1;
      }
      restore_good(base);
    } else {
      if (!must_refuse) { printf("FAIL state case %d (%s) was refused\n", k, kind); failed = 1; }
      if (s || error_logs == logs) {
        printf("FAIL state case %d (%s): no message, or *state written\n", k, kind);
        failed = 1;
      }
      if ((status = advance(base)) > 1) {
        printf("FAIL state case %d (%s): the instance then gave %d\n", k, kind, status);
        failed = 1;
      }
    }
  }
  return failed;
}

/* Run body(a, b) in a child under alarm(); its exit code, or -signal. */
static int in_child(int (*body)(int, int), int a, int b) {
  int status;
  pid_t pid;
  fflush(stdout);
  pid = fork();
  if (pid == 0) {
    alarm(SECONDS);
    status = body(a, b);
    fflush(stdout);
    _exit(status);
  }
  if (pid < 0 || waitpid(pid, &status, 0) < 0) { printf("fork failed\n"); exit(5); }
  return WIFSIGNALED(status) ? -WTERMSIG(status) : WEXITSTATUS(status);
}

static const char *death(int code) { return code == -SIGALRM ? "HANG" : "CRASH"; }

static int run_pointer_case(int k, int unused) { (void)unused; return pointer_case(k); }

int main(int argc, char **argv) {
  int n, a, k, code, failures = 0, pointer_cases = 0;
  void *s = NULL;
  if (argc < 6) { printf("usage: fuzz_driver LIB VERSION cs|me N SEED\n"); return 2; }
  lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
  if (!lib) { printf("loading %s failed: %s\n", argv[1], dlerror()); return 1; }
  version = atoi(argv[2]);
  model_exchange = strcmp(argv[3], "me") == 0;
  n = atoi(argv[4]);
  seed = strtoull(argv[5], NULL, 10);
  base = make_instance(1);
  if (get_state(base, &s) || serialize(base, s, good, sizeof good) || free_state(base, &s)) {
    printf("could not save the real state (is the driver built from this FMU's sources?)\n");
    return 4;
  }
  for (a = 0; a < n; a += BATCH) {
    code = in_child(state_cases, a, a + BATCH < n ? a + BATCH : n);
    failures += code != 0;
    if (code < 0) /* find the case: one child each */
      for (k = a; k < a + BATCH && k < n; ++k)
        if ((code = in_child(state_cases, k, k + 1)) < 0) printf("%s in state case %d\n", death(code), k);
  }
  for (k = 0; (code = in_child(run_pointer_case, k, 0)) != 0; ++k, ++pointer_cases) {
    if (code < 0) printf("%s in pointer case %d\n", death(code), k);
    failures += code != 1; /* 1: the case ran and met its expectation */
  }
  printf("states %d pointer-cases %d failures %d\n", n, pointer_cases, failures);
  return failures != 0;
}
