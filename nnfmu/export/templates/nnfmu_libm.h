/* nnfmu: the C math functions of the model code, without a link-time dependency on libm.
 *
 * glibc keeps sin, exp, tanh, ... in libm.so.6, separate from the C library. nnfmu links its own
 * binary against libm (and defines NNFMU_LINKS_LIBM), but an importer that rebuilds the FMU from
 * its sources may not: fmpy's build_platform_binary (CMake) and a plain `cc -shared` link no libm,
 * and such a binary fails to load in a process that has not loaded libm itself ("undefined symbol:
 * tanh"). So on glibc, unless NNFMU_LINKS_LIBM is defined, the model code calls the functions
 * through pointers that nnfmu_libm.c resolves from libm.so.6 when the binary is loaded: the same
 * functions, hence the same results, with nothing for the linker to resolve. Elsewhere (musl,
 * macOS, Windows) the maths is part of the C library and the calls stay direct.
 */
#ifndef NNFMU_LIBM_H
#define NNFMU_LIBM_H

#include <math.h>

#include "nnfmu_core.h"

#if defined(__GLIBC__) && !defined(NNFMU_LINKS_LIBM)
#define NNFMU_LIBM_AT_LOAD_TIME 1

/* X(name, arity): every function of math.h the generated model code may call. */
#define NNFMU_LIBM_FUNCTIONS(X)                                                                     \
  X(sqrt, 1) X(cbrt, 1) X(exp, 1) X(exp2, 1) X(expm1, 1) X(log, 1) X(log2, 1) X(log10, 1)           \
  X(log1p, 1) X(sin, 1) X(cos, 1) X(tan, 1) X(asin, 1) X(acos, 1) X(atan, 1) X(sinh, 1) X(cosh, 1)  \
  X(tanh, 1) X(asinh, 1) X(acosh, 1) X(atanh, 1) X(erf, 1) X(erfc, 1) X(floor, 1) X(ceil, 1)        \
  X(round, 1) X(trunc, 1) X(fabs, 1) X(pow, 2) X(atan2, 2) X(fmod, 2) X(fmin, 2) X(fmax, 2)        \
  X(hypot, 2) X(copysign, 2) X(remainder, 2)

#define NNFMU_LIBM_POINTER_1(name) double (*name)(double);
#define NNFMU_LIBM_POINTER_2(name) double (*name)(double, double);
#define NNFMU_LIBM_POINTER(name, arity) NNFMU_LIBM_POINTER_##arity(name)

typedef struct {
  NNFMU_LIBM_FUNCTIONS(NNFMU_LIBM_POINTER)
} nnfmu_libm_table;

/* Filled once, when the binary is loaded (a constructor in nnfmu_libm.c), and never written again. */
extern NNFMU_INTERNAL nnfmu_libm_table nnfmu_libm;

#ifdef NNFMU_LIBM_REDIRECT /* defined by nnfmu_model.c, around the generated model code only */
#define sqrt(x) (nnfmu_libm.sqrt(x))
#define cbrt(x) (nnfmu_libm.cbrt(x))
#define exp(x) (nnfmu_libm.exp(x))
#define exp2(x) (nnfmu_libm.exp2(x))
#define expm1(x) (nnfmu_libm.expm1(x))
#define log(x) (nnfmu_libm.log(x))
#define log2(x) (nnfmu_libm.log2(x))
#define log10(x) (nnfmu_libm.log10(x))
#define log1p(x) (nnfmu_libm.log1p(x))
#define sin(x) (nnfmu_libm.sin(x))
#define cos(x) (nnfmu_libm.cos(x))
#define tan(x) (nnfmu_libm.tan(x))
#define asin(x) (nnfmu_libm.asin(x))
#define acos(x) (nnfmu_libm.acos(x))
#define atan(x) (nnfmu_libm.atan(x))
#define sinh(x) (nnfmu_libm.sinh(x))
#define cosh(x) (nnfmu_libm.cosh(x))
#define tanh(x) (nnfmu_libm.tanh(x))
#define asinh(x) (nnfmu_libm.asinh(x))
#define acosh(x) (nnfmu_libm.acosh(x))
#define atanh(x) (nnfmu_libm.atanh(x))
#define erf(x) (nnfmu_libm.erf(x))
#define erfc(x) (nnfmu_libm.erfc(x))
#define floor(x) (nnfmu_libm.floor(x))
#define ceil(x) (nnfmu_libm.ceil(x))
#define round(x) (nnfmu_libm.round(x))
#define trunc(x) (nnfmu_libm.trunc(x))
#define fabs(x) (nnfmu_libm.fabs(x))
#define pow(x, y) (nnfmu_libm.pow(x, y))
#define atan2(x, y) (nnfmu_libm.atan2(x, y))
#define fmod(x, y) (nnfmu_libm.fmod(x, y))
#define fmin(x, y) (nnfmu_libm.fmin(x, y))
#define fmax(x, y) (nnfmu_libm.fmax(x, y))
#define hypot(x, y) (nnfmu_libm.hypot(x, y))
#define copysign(x, y) (nnfmu_libm.copysign(x, y))
#define remainder(x, y) (nnfmu_libm.remainder(x, y))
#endif /* NNFMU_LIBM_REDIRECT */
#endif /* glibc without NNFMU_LINKS_LIBM */

/* NULL when the model's maths is available; else why not (checked by instantiate). */
NNFMU_INTERNAL const char *nnfmu_libm_missing(void);

#endif /* NNFMU_LIBM_H */
