/* nnfmu FMI 2.0 wrapper, in every FMU: what nnfmu_fmi2.c (common and co-simulation functions) and
 * nnfmu_fmi2_me.c (Model Exchange functions) share. The core decides what an FMU offers. */
#ifndef NNFMU_FMI2_H
#define NNFMU_FMI2_H

#include "fmi2Functions.h"
#include "nnfmu_core.h"

/* The importer's logger and its environment; the core keeps a pointer to it as its `env`. */
typedef struct {
  fmi2CallbackLogger logger;
  fmi2ComponentEnvironment environment;
} logger_env;

/* `magic` is FMI2_INSTANCE_MAGIC while the instance lives and cleared when it is freed, so that a call
 * on a freed instance returns fmi2Error while the memory is still mapped. Best effort only: using freed
 * memory is undefined behaviour, and once the allocator reuses it anything can happen. */
#define FMI2_INSTANCE_MAGIC 0x6e6e666d756932ULL /* "nnfmui2" */
typedef struct {
  unsigned long long magic;
  logger_env le;
  nnfmu_instance *core;
} fmi2_instance;

#define INSTANCE (((fmi2_instance *)c)->core)
#define CHECK_INSTANCE() if (!c || ((fmi2_instance *)c)->magic != FMI2_INSTANCE_MAGIC) return fmi2Error
/* Return fmi2Error with a message when `pointer` is NULL although `count` values are to be read or written. */
#define NOT_NULL(caller, pointer, count) \
  if (nnfmu_not_null(INSTANCE, caller, #pointer, pointer, count) != NNFMU_OK) return fmi2Error

#endif /* NNFMU_FMI2_H */
