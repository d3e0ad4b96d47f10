/* nnfmu: resolves the model code's math functions from libm when the binary is loaded (see
 * nnfmu_libm.h for why). The table is written once, before any FMI function can be called, and
 * only read afterwards, so instances in several threads share it safely. */
#include <stddef.h>
#include <stdio.h>

#include "nnfmu_libm.h"

#ifdef NNFMU_LIBM_AT_LOAD_TIME
#include <dlfcn.h>
#include <gnu/lib-names.h> /* LIBM_SO: "libm.so.6" on glibc */

nnfmu_libm_table nnfmu_libm;
static void *libm_handle;
static const char *libm_problem = "the C math library " LIBM_SO " was not loaded";
static char libm_problem_text[200];

#define NNFMU_LIBM_RESOLVE(name, arity)                                                         \
  if (!(*(void **)&nnfmu_libm.name = dlsym(libm_handle, #name))) missing = #name;

__attribute__((constructor)) static void nnfmu_libm_load(void) {
  const char *missing = NULL;
  libm_handle = dlopen(LIBM_SO, RTLD_NOW | RTLD_LOCAL);
  if (!libm_handle) {
    const char *why = dlerror();
    snprintf(libm_problem_text, sizeof libm_problem_text, "cannot load the C math library %s (%s)", LIBM_SO,
             why ? why : "no reason given");
    libm_problem = libm_problem_text;
    return;
  }
  NNFMU_LIBM_FUNCTIONS(NNFMU_LIBM_RESOLVE)
  if (missing) {
    snprintf(libm_problem_text, sizeof libm_problem_text, "the C math library %s lacks %s", LIBM_SO, missing);
    libm_problem = libm_problem_text;
    return;
  }
  libm_problem = NULL;
}

__attribute__((destructor)) static void nnfmu_libm_unload(void) {
  if (libm_handle) dlclose(libm_handle);
  libm_handle = NULL;
}

const char *nnfmu_libm_missing(void) { return libm_problem; }

#else

const char *nnfmu_libm_missing(void) { return NULL; }

#endif
