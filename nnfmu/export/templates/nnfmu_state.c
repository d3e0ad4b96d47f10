/* nnfmu FMU core: FMU states. A state is a copy of nnfmu_values (mode, time, samples, inputs held,
 * parameters, outputs and the model state x), so setting it into any instance of the same FMU, a
 * freshly instantiated one included, resumes exactly where it was saved. Every mode allows these calls. */
#include <stdlib.h>
#include <string.h>

#include "nnfmu_instance.h"

#define STATE_MAGIC 0x6e6e666d75737432ULL /* "nnfmust2" */

typedef struct {
  unsigned long long magic;
  nnfmu_values values;
} nnfmu_state;

nnfmu_status nnfmu_get_state(nnfmu_instance *inst, void **state) {
  nnfmu_state *s = (nnfmu_state *)(*state ? *state : malloc(sizeof(nnfmu_state)));
  if (!s) return nnfmu_error(inst, "getFMUState: out of memory");
  s->magic = STATE_MAGIC;
  s->values = inst->v;
  *state = s;
  return NNFMU_OK;
}

nnfmu_status nnfmu_set_state(nnfmu_instance *inst, const void *state) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  if (!s || s->magic != STATE_MAGIC)
    return nnfmu_error(inst, "setFMUState: expected an FMU state of this FMU, got %s", s ? "something else" : "NULL");
  inst->v = s->values;
  return NNFMU_OK;
}

void nnfmu_free_state(void **state) {
  if (state && *state) {
    free(*state);
    *state = NULL;
  }
}

/* Serialized layout: 8-byte magic, 8-byte hash of the instantiation token, then the values. */
static unsigned long long token_hash(void) {
  unsigned long long h = 1469598103934665603ULL; /* FNV-1a */
  const char *c;
  for (c = NNFMU_TOKEN; *c; ++c) h = (h ^ (unsigned char)*c) * 1099511628211ULL;
  return h;
}

size_t nnfmu_serialized_size(void) { return 2 * sizeof(unsigned long long) + sizeof(nnfmu_values); }

nnfmu_status nnfmu_serialize(nnfmu_instance *inst, const void *state, unsigned char *bytes, size_t size) {
  const nnfmu_state *s = (const nnfmu_state *)state;
  unsigned long long header[2];
  if (!s || s->magic != STATE_MAGIC || !bytes || size < nnfmu_serialized_size())
    return nnfmu_error(inst, "serializeFMUState: expected a state of this FMU and a buffer of %lu bytes, got a "
                       "buffer of %lu bytes", (unsigned long)nnfmu_serialized_size(), (unsigned long)size);
  header[0] = STATE_MAGIC;
  header[1] = token_hash();
  memcpy(bytes, header, sizeof header);
  memcpy(bytes + sizeof header, &s->values, sizeof s->values);
  return NNFMU_OK;
}

nnfmu_status nnfmu_deserialize(nnfmu_instance *inst, const unsigned char *bytes, size_t size, void **state) {
  unsigned long long header[2];
  nnfmu_state *s;
  if (!bytes || size != nnfmu_serialized_size())
    return nnfmu_error(inst, "deserializeFMUState: expected %lu bytes, got %lu", (unsigned long)nnfmu_serialized_size(),
                       (unsigned long)size);
  memcpy(header, bytes, sizeof header);
  if (header[0] != STATE_MAGIC || header[1] != token_hash())
    return nnfmu_error(inst, "deserializeFMUState: the bytes are not a serialized state of this FMU (%s)",
                       NNFMU_MODEL_IDENTIFIER);
  s = (nnfmu_state *)malloc(sizeof(nnfmu_state)); /* always a new state; *state is untouched on failure */
  if (!s) return nnfmu_error(inst, "deserializeFMUState: out of memory");
  s->magic = STATE_MAGIC;
  memcpy(&s->values, bytes + sizeof header, sizeof s->values);
  *state = s;
  return NNFMU_OK;
}
