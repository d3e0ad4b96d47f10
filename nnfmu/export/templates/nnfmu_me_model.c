/* nnfmu: the model's ODE for Model Exchange, in every FMU. Compiles CasADi's generated model_me_casadi.c
 * (not listed as a source file on its own) with its math calls redirected as nnfmu_libm.h explains,
 * exactly as nnfmu_model.c compiles model_casadi.c. The generated file ends with the table
 * nnfmu_model_ode through which the core calls the ODE (nnfmu_instance.h); for a model without an ODE
 * it holds only that table, every entry NULL. */
#include <math.h>

#define NNFMU_LIBM_REDIRECT
#include "nnfmu_libm.h"

#include "model_me_casadi.c"
