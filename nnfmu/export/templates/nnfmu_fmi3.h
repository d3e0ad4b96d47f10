/* nnfmu FMI 3.0 wrapper, in every FMU: what nnfmu_fmi3.c (common and co-simulation functions),
 * nnfmu_fmi3_me.c (Model Exchange functions) and nnfmu_fmi3_unsupported.c share. The core decides what
 * an FMU offers. */
#ifndef NNFMU_FMI3_H
#define NNFMU_FMI3_H

#include "fmi3Functions.h"
#include "nnfmu_core.h"

/* The importer's logger and its environment; the core keeps a pointer to it as its `env`. */
typedef struct {
  fmi3LogMessageCallback log_message;
  fmi3InstanceEnvironment environment;
} logger_env;

/* `magic` is FMI3_INSTANCE_MAGIC while the instance lives and cleared when it is freed, so that a call
 * on a freed instance returns fmi3Error while the memory is still mapped. Best effort only: using freed
 * memory is undefined behaviour, and once the allocator reuses it anything can happen. */
#define FMI3_INSTANCE_MAGIC 0x6e6e666d756933ULL /* "nnfmui3" */
typedef struct {
  unsigned long long magic;
  logger_env le;
  nnfmu_instance *core;
} fmi3_instance;

#define INSTANCE (((fmi3_instance *)instance)->core)
#define CHECK_INSTANCE() if (!instance || ((fmi3_instance *)instance)->magic != FMI3_INSTANCE_MAGIC) return fmi3Error
/* Return fmi3Error with a message when `pointer` is NULL although `count` values are to be read or written. */
#define NOT_NULL(caller, pointer, count) \
  if (nnfmu_not_null(INSTANCE, caller, #pointer, pointer, count) != NNFMU_OK) return fmi3Error

/* The FMI 3 logger sink, shared with nnfmu_fmi3_me.c's instantiate. */
NNFMU_INTERNAL void nnfmu_fmi3_sink(void *env, const char *instance_name, nnfmu_status status, const char *category,
                                    const char *message);
#define NO_CLOCKS "this FMU has no clocks and no event mode"
#define NO_TYPE "this FMU has Float64, Int32 and Boolean variables only"

/* Log "<caller> is not supported: <why>" and return fmi3Error. */
NNFMU_INTERNAL fmi3Status nnfmu_fmi3_unsupported(fmi3Instance instance, const char *caller, const char *why);

#endif /* NNFMU_FMI3_H */
