/* nnfmu FMI 3.0 wrapper: what nnfmu_fmi3.c and nnfmu_fmi3_unsupported.c share. */
#ifndef NNFMU_FMI3_H
#define NNFMU_FMI3_H

#include "fmi3Functions.h"
#include "nnfmu_core.h"
#include "nnfmu_model.h" /* NNFMU_MODEL_EXCHANGE: this FMU offers Model Exchange too (nnfmu_fmi3_me.c) */

/* The importer's logger and its environment; the core keeps a pointer to it as its `env`. */
typedef struct {
  fmi3LogMessageCallback log_message;
  fmi3InstanceEnvironment environment;
} logger_env;

typedef struct {
  logger_env le;
  nnfmu_instance *core;
} fmi3_instance;

#define INSTANCE (((fmi3_instance *)instance)->core)
#define CHECK_INSTANCE() if (!instance) return fmi3Error

#define NO_MX "this FMU is for co-simulation only"
/* The FMI 3 logger sink, shared with nnfmu_fmi3_me.c's instantiate. */
NNFMU_INTERNAL void nnfmu_fmi3_sink(void *env, const char *instance_name, nnfmu_status status, const char *category,
                                    const char *message);
#define NO_CLOCKS "this FMU has no clocks and no event mode"
#define NO_TYPE "this FMU has Float64, Int32 and Boolean variables only"

/* Log "<caller> is not supported: <why>" and return fmi3Error. */
NNFMU_INTERNAL fmi3Status nnfmu_fmi3_unsupported(fmi3Instance instance, const char *caller, const char *why);

#endif /* NNFMU_FMI3_H */
