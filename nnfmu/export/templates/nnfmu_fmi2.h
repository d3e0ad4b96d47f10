/* nnfmu FMI 2.0 wrapper: what nnfmu_fmi2.c (common and co-simulation functions) and nnfmu_fmi2_me.c (Model
 * Exchange, in FMUs of continuous-time models) share. */
#ifndef NNFMU_FMI2_H
#define NNFMU_FMI2_H

#include "fmi2Functions.h"
#include "nnfmu_core.h"
#include "nnfmu_model.h" /* NNFMU_MODEL_EXCHANGE: this FMU offers Model Exchange too */

/* The importer's logger and its environment; the core keeps a pointer to it as its `env`. */
typedef struct {
  fmi2CallbackLogger logger;
  fmi2ComponentEnvironment environment;
} logger_env;

typedef struct {
  logger_env le;
  nnfmu_instance *core;
} fmi2_instance;

#define INSTANCE (((fmi2_instance *)c)->core)
#define CHECK_INSTANCE() if (!c) return fmi2Error

#endif /* NNFMU_FMI2_H */
