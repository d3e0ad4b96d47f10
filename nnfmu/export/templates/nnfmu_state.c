/* nnfmu FMU core: FMU states. A state is a copy of nnfmu_values (mode, time, samples, inputs held,
 * parameters, outputs and the model state x), so setting it into any instance of the same FMU, a
 * freshly instantiated one included, resumes exactly where it was saved. Every mode allows these calls.
 *
 * States come back from importers and from files, so nothing in one is trusted: a serialized state
 * carries a checksum of its payload, and every field of a state is checked (check_values) before it
 * is set. A refused state is an Error that leaves the instance as it was (nnfmu_reject). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "nnfmu_instance.h"

#define STATE_MAGIC 0x6e6e666d75737433ULL /* "nnfmust3": version 3 of the serialized layout */
#define HEADER_WORDS 3                     /* magic, hash of the instantiation token, checksum of the payload */

typedef struct {
  void *self; /* the state's own address: tells a state passed in place of its address (nnfmu_free_state) */
  unsigned long long magic;
  nnfmu_values values;
} nnfmu_state;

/* 64-bit FNV-1a of n bytes, continuing from h. */
static unsigned long long fnv1a(unsigned long long h, const unsigned char *bytes, size_t n) {
  size_t i;
  for (i = 0; i < n; ++i) h = (h ^ bytes[i]) * 1099511628211ULL;
  return h;
}
#define FNV_OFFSET 1469598103934665603ULL

static unsigned long long token_hash(void) {
  return fnv1a(FNV_OFFSET, (const unsigned char *)NNFMU_TOKEN, strlen(NNFMU_TOKEN));
}

static int is_finite(double a) { return a - a == 0.0; }
static int is_flag(int a) { return a == 0 || a == 1; }

/* NULL if v is a state an instance of this interface can be in; else what is wrong, in `why`. */
static const char *check_values(const nnfmu_instance *inst, const nnfmu_values *v, char *why, size_t size) {
  const int me = inst->interface_type == NNFMU_INTERFACE_ME;
  const int modes = MODE_INSTANTIATED | MODE_INITIALIZATION | MODE_TERMINATED | MODE_ERROR |
                    (me ? MODE_EVENT | MODE_CONTINUOUS : MODE_STEP);
  const unsigned mode = (unsigned)v->mode;
  int i;
  if ((mode & (unsigned)modes) == 0 || (mode & (mode - 1)) != 0) /* one of the modes, exactly */
    snprintf(why, size, "mode %u is not a state of a %s instance", mode,
             me ? "Model Exchange" : "co-simulation");
  else if (!is_finite(v->start_time) || !is_finite(v->time))
    snprintf(why, size, "start time %g s and time %g s must be finite", v->start_time, v->time);
  else if (v->max_samples < 1 || v->max_samples > NNFMU_MAX_SAMPLES_LIMIT)
    snprintf(why, size, "max_samples_per_step %lld is outside [1, %lld]", v->max_samples, NNFMU_MAX_SAMPLES_LIMIT);
  else if (!is_flag(v->x_ready) || !is_flag(v->range_error))
    snprintf(why, size, "flags %d and %d must be 0 or 1", v->x_ready, v->range_error);
  else if (me && v->samples != 0)
    snprintf(why, size, "a Model Exchange state counts no samples, got %lld", v->samples);
  else if (!me && (double)v->samples != nnfmu_samples_by(v, v->time))
    snprintf(why, size, "%lld samples of Ts = %g s do not lead from the start time %.17g s to the time %.17g s",
             v->samples, NNFMU_TS, v->start_time, v->time);
  else if (!me && v->x_ready != (v->samples > 0))
    snprintf(why, size, "the model state is %s but %lld samples were taken", v->x_ready ? "set" : "not set",
             v->samples);
  else why[0] = '\0';
  for (i = 0; !why[0] && i < NNFMU_NU; ++i)
    if (v->outside[i] > 1) snprintf(why, size, "the range flag of input %s is %d", nnfmu_u_names[i], v->outside[i]);
  for (i = 0; !why[0] && !me && v->samples > 0 && i < NNFMU_NY; ++i) /* committed outputs are finite */
    if (!is_finite(v->y[i])) snprintf(why, size, "output %s is %g", nnfmu_y_names[i], v->y[i]);
  for (i = 0; !why[0] && !me && v->x_ready && i < NNFMU_NX; ++i) /* and so are committed states */
    if (!is_finite(v->x[i])) snprintf(why, size, "model state %d is %g", i, v->x[i]);
  return why[0] ? why : NULL;
}

static nnfmu_state *new_state(void) {
  nnfmu_state *s = (nnfmu_state *)malloc(sizeof(nnfmu_state));
  if (s) {
    s->self = s;
    s->magic = STATE_MAGIC;
  }
  return s;
}

static int is_state(const nnfmu_state *s) { return s && s->magic == STATE_MAGIC && s->self == s; }

nnfmu_status nnfmu_get_state(nnfmu_instance *inst, void **state) {
  nnfmu_state *s;
  if (nnfmu_not_null(inst, "getFMUState", "FMUState", state, 1) != NNFMU_OK) return NNFMU_ERROR;
  if (*state && !is_state((const nnfmu_state *)*state))
    return nnfmu_error(inst, "getFMUState: *FMUState must be NULL or a state of this FMU to overwrite");
  s = *state ? (nnfmu_state *)*state : new_state();
  if (!s) return nnfmu_error(inst, "getFMUState: out of memory");
  s->values = inst->v;
  *state = s;
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_state(nnfmu_instance *inst, const void *state) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  char why[300];
  if (!is_state(s))
    return nnfmu_reject(inst, "setFMUState: expected an FMU state of this FMU, got %s; the instance keeps its "
                        "state", s ? "something else" : "NULL");
  if (check_values(inst, &s->values, why, sizeof why))
    return nnfmu_reject(inst, "setFMUState: the state is not valid here: %s; the instance keeps its state", why);
  inst->v = s->values;
  return NNFMU_OK;
}

nnfmu_status nnfmu_free_state(nnfmu_instance *inst, const char *caller, void **state) {
  nnfmu_state *s;
  if (nnfmu_not_null(inst, caller, "FMUState", state, 1) != NNFMU_OK) return NNFMU_ERROR;
  if (*state == (void *)state) { /* the state itself, not its address: its first field points to itself */
    s = (nnfmu_state *)(void *)state;
    nnfmu_log(inst, NNFMU_OK, "%s: got the FMU state where its address belongs; freed it all the same", caller);
  } else if (!*state) {
    return NNFMU_OK;
  } else if (!is_state(s = (nnfmu_state *)*state)) {
    return nnfmu_reject(inst, "%s: *FMUState is not a state of this FMU (freed already?); nothing was freed", caller);
  } else {
    *state = NULL;
  }
  s->self = NULL; /* a later use of the freed state is refused while the memory stays mapped (best effort) */
  s->magic = 0;
  free(s);
  return NNFMU_OK;
}

/* Serialized layout: the HEADER_WORDS 8-byte words, then the values. */
size_t nnfmu_serialized_size(void) { return HEADER_WORDS * sizeof(unsigned long long) + sizeof(nnfmu_values); }

nnfmu_status nnfmu_serialize(nnfmu_instance *inst, const void *state, unsigned char *bytes, size_t size) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  unsigned long long header[HEADER_WORDS];
  if (!is_state(s) || !bytes || size < nnfmu_serialized_size())
    return nnfmu_error(inst, "serializeFMUState: expected a state of this FMU and a buffer of %lu bytes, got %s and "
                       "a buffer of %lu bytes%s", (unsigned long)nnfmu_serialized_size(),
                       is_state(s) ? "one" : "none", (unsigned long)size, bytes ? "" : " at NULL");
  header[0] = STATE_MAGIC;
  header[1] = token_hash();
  header[2] = fnv1a(FNV_OFFSET, (const unsigned char *)&s->values, sizeof s->values);
  memcpy(bytes, header, sizeof header);
  memcpy(bytes + sizeof header, &s->values, sizeof s->values);
  return NNFMU_OK;
}

nnfmu_status nnfmu_deserialize(nnfmu_instance *inst, const unsigned char *bytes, size_t size, void **state) {
  const char *caller = "deserializeFMUState";
  unsigned long long header[HEADER_WORDS];
  nnfmu_values values;
  nnfmu_state *s;
  char why[300];
  if (nnfmu_not_null(inst, caller, "FMUState", state, 1) != NNFMU_OK) return NNFMU_ERROR;
  if (!bytes || size != nnfmu_serialized_size())
    return nnfmu_reject(inst, "%s: expected %lu bytes, got %lu%s; the instance keeps its state", caller,
                        (unsigned long)nnfmu_serialized_size(), (unsigned long)size, bytes ? "" : " at NULL");
  memcpy(header, bytes, sizeof header);
  if (header[0] != STATE_MAGIC || header[1] != token_hash())
    return nnfmu_reject(inst, "%s: the bytes are not a serialized state of this FMU (%s, state format 3); the "
                        "instance keeps its state", caller, NNFMU_MODEL_IDENTIFIER);
  if (header[2] != fnv1a(FNV_OFFSET, bytes + sizeof header, sizeof values))
    return nnfmu_reject(inst, "%s: the checksum does not match: the serialized state is corrupt; the instance "
                        "keeps its state", caller);
  memcpy(&values, bytes + sizeof header, sizeof values);
  if (check_values(inst, &values, why, sizeof why))
    return nnfmu_reject(inst, "%s: the serialized state is not valid: %s; the instance keeps its state", caller, why);
  s = new_state(); /* always a new state; *state is untouched on failure */
  if (!s) return nnfmu_reject(inst, "%s: out of memory", caller);
  s->values = values;
  *state = s;
  return NNFMU_OK;
}
