/* Reader for a bundle's vectors.bin (test programs only, not part of the library).
 * Parses a little-endian buffer already in memory; all accessors copy with memcpy so the
 * arrays need no alignment. The layout is the export helper's (manifest.json). */
#ifndef SLIPEST_VECTORS_H
#define SLIPEST_VECTORS_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_model.h"

typedef struct {
    uint32_t n;
    const uint8_t *inputs;       /* float32 (n,12) physical units */
    const uint8_t *q_inputs;     /* int16 (n,12) */
    const uint8_t *torch_logits; /* float32 (n,3) */
    const uint8_t *q_logits;     /* int32 (n,3) */
    const uint8_t *q_class;      /* int32 (n) */
    const uint8_t *f_class;      /* int32 (n) */
    const uint8_t *q_saturations; /* int32 (n) saturation events of the integer reference */
} slipest_vectors_t;

/* 0 on success, negative on a bad header / truncated file (message in *why). */
int slipest_vectors_parse(const uint8_t *buf, size_t len, slipest_vectors_t *v, const char **why);

void slipest_vectors_input(const slipest_vectors_t *v, uint32_t i, float out[12]);
void slipest_vectors_q_input(const slipest_vectors_t *v, uint32_t i, int16_t out[12]);
void slipest_vectors_torch_logits(const slipest_vectors_t *v, uint32_t i, float out[3]);
void slipest_vectors_q_logits(const slipest_vectors_t *v, uint32_t i, int32_t out[3]);

/* Check one vector; 0 = pass, else a bitmask of failures: q path 1 logits differ, 2 class is
 * not the argmax of q_logits, 16 kernel error, 32 saturation count
 * differs; f32 path 4 a logit off by > tol, 8 class differs
 * from the torch argmax, 16 kernel error. The logits computed are written to *_out. */
int slipest_vectors_check_q(const slipest_vectors_t *v, const slipest_model_q_t *m, uint32_t i, int32_t q_out[3]);
int slipest_vectors_check_f32(const slipest_vectors_t *v, const slipest_model_f32_t *m, uint32_t i, float tol,
                             float f_out[3]);

#endif
