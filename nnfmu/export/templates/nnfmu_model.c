/* nnfmu: the model's maths. Compiles CasADi's generated model_casadi.c (which is not listed as a
 * source file on its own) with its math calls redirected as nnfmu_libm.h explains, so that a binary
 * built from the listed sources by any importer needs no libm at link time. */
#include <math.h>

#define NNFMU_LIBM_REDIRECT
#include "nnfmu_libm.h"

#include "model_casadi.c"
