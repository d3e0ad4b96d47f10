/* nnfmu FMU core, the bottom layer: logging, errors and the check of the FMI mode a call is allowed in.
 * Every other file of the core calls these, and this file calls none of them (nnfmu_core.c has the order). */
#include <stdarg.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "nnfmu_instance.h"

/* ---- logging ------------------------------------------------------------------------------- */

static void format_message(char *buffer, size_t size, const char *fmt, va_list args) {
  char *c;
  vsnprintf(buffer, size, fmt, args);
  /* FMI 2 loggers treat the message as a printf format: keep it free of conversions. */
  for (c = buffer; *c; ++c) if (*c == '%') *c = '?';
}

static nnfmu_status vlog(nnfmu_instance *inst, nnfmu_status status, const char *fmt, va_list args) {
  static const char *const categories[] = {"logStatusOK", "logStatusWarning", "logStatusDiscard",
                                           "logStatusError", "logStatusFatal"};
  /* Warnings and errors are always reported (FMI: the logger was called when such a status returns). */
  if (!inst->sink || (status == NNFMU_OK && !inst->logging_on)) return status;
  format_message(inst->message, sizeof inst->message, fmt, args);
  inst->sink(inst->env, inst->name, status, categories[status], inst->message);
  return status;
}

nnfmu_status nnfmu_log(nnfmu_instance *inst, nnfmu_status status, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, status, fmt, args);
  va_end(args);
  return status;
}

nnfmu_status nnfmu_error(nnfmu_instance *inst, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, NNFMU_ERROR, fmt, args);
  va_end(args);
  inst->v.mode = MODE_ERROR;
  return NNFMU_ERROR;
}

nnfmu_status nnfmu_reject(nnfmu_instance *inst, const char *fmt, ...) {
  va_list args;
  va_start(args, fmt);
  vlog(inst, NNFMU_ERROR, fmt, args);
  va_end(args);
  return NNFMU_ERROR;
}

nnfmu_status nnfmu_not_null(nnfmu_instance *inst, const char *caller, const char *name, const void *pointer,
                            size_t count) {
  if (pointer || count == 0) return NNFMU_OK;
  return nnfmu_error(inst, "%s: argument %s must not be NULL", caller, name);
}

void nnfmu_log_early(nnfmu_log_sink sink, void *env, const char *instance_name, const char *fmt, ...) {
  char buffer[512];
  va_list args;
  if (!sink) return;
  va_start(args, fmt);
  format_message(buffer, sizeof buffer, fmt, args);
  va_end(args);
  sink(env, instance_name ? instance_name : "", NNFMU_ERROR, "logStatusError", buffer);
}

/* ---- the state machine --------------------------------------------------------------------- */

static const char *mode_name(int mode) {
  switch (mode) {
    case MODE_INSTANTIATED: return "the instantiated state";
    case MODE_INITIALIZATION: return "initialization mode";
    case MODE_STEP: return "step mode";
    case MODE_TERMINATED: return "the terminated state";
    case MODE_EVENT: return "event mode";
    case MODE_CONTINUOUS: return "continuous-time mode";
    default: return "the error state (after an error: call reset, or set an FMU state saved before)";
  }
}

nnfmu_status nnfmu_require(nnfmu_instance *inst, const char *caller, int modes) {
  char allowed[200] = "";
  int m;
  if (inst->v.mode & modes) return NNFMU_OK;
  for (m = MODE_INSTANTIATED; m <= MODE_CONTINUOUS; m <<= 1)
    if (modes & m) {
      if (allowed[0]) strcat(allowed, ", ");
      strcat(allowed, m == MODE_ERROR ? "the error state" : mode_name(m));
    }
  return nnfmu_error(inst, "%s is not allowed in %s; FMI allows it in %s", caller, mode_name(inst->v.mode),
                     allowed);
}
