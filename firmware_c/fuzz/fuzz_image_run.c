/* Shared by fuzz_image and fuzz_image_table: see fuzz_image_run.h. */
#include "fuzz_image_run.h"

#include <string.h>

#include "slipest_image.h"
#include "slipest_infer.h"

size_t fuzz_image_copy(uint8_t *buf, size_t cap, const uint8_t *data, size_t size)
{
    if (size > cap) return 0;
    memcpy(buf, data, size);
    if (size >= SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE && (data[size - 1] & 1u)) {
        size_t body = size - SLIPEST_IMAGE_TRAILER_SIZE;
        uint32_t crc = slipest_crc32(buf, body);
        buf[body] = (uint8_t)crc;
        buf[body + 1] = (uint8_t)(crc >> 8);
        buf[body + 2] = (uint8_t)(crc >> 16);
        buf[body + 3] = (uint8_t)(crc >> 24);
    }
    return size;
}

void fuzz_image_run(const slipest_model_q_t *mq, const slipest_model_f32_t *mf)
{
    int16_t x[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    float xf[SLIPEST_N_FEATURES], lf[SLIPEST_N_CLASSES];
    uint16_t sat;
    int j, cls;

    for (j = 0; j < SLIPEST_N_FEATURES; j++) {
        x[j] = (int16_t)(j & 1 ? -32768 : 32767);
        xf[j] = (float)x[j] * 0.001f;
    }
    cls = slipest_infer_q(mq, x, logits, &sat);
    if (cls < 0 || cls > 2) __builtin_trap();
    cls = slipest_infer_f32(mf, xf, lf);
    if (cls > 2) __builtin_trap();
}
