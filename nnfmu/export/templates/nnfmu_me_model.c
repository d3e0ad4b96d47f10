/* nnfmu: the ODE's maths. Compiles CasADi's generated model_me_casadi.c (not listed as a source file on
 * its own) with its math calls redirected as nnfmu_libm.h explains, exactly as nnfmu_model.c compiles
 * model_casadi.c. */
#include <math.h>

#define NNFMU_LIBM_REDIRECT
#include "nnfmu_libm.h"

#include "model_me_casadi.c"
