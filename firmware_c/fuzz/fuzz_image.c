/* libFuzzer: arbitrary bytes through the model-image reader. When the input is long enough, the
 * harness re-seals a copy with a correct CRC-32 half of the time (steered by the last byte), so
 * mutations reach the field checks behind the CRC. A model the reader accepts must run without
 * UB (this target is built with ASan + UBSan) and give a valid class.
 * Seed corpus: the example bundle's model.img (scripts/fuzz.sh copies it in). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_image.h"
#include "slipest_infer.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t buf[SLIPEST_IMAGE_MAX_SIZE + 64u];
    static slipest_image_q_storage_t qs;
    static slipest_image_f32_storage_t fs;
    slipest_model_q_t mq;
    slipest_model_f32_t mf;
    int16_t x[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    float xf[SLIPEST_N_FEATURES], lf[SLIPEST_N_CLASSES];
    uint16_t sat;
    int j, cls;

    if (size > sizeof buf) return 0;
    memcpy(buf, data, size);
    if (size >= SLIPEST_IMAGE_HEADER_SIZE + SLIPEST_IMAGE_TRAILER_SIZE && (data[size - 1] & 1u)) {
        size_t body = size - SLIPEST_IMAGE_TRAILER_SIZE;
        uint32_t crc = slipest_crc32(buf, body);
        buf[body] = (uint8_t)crc;
        buf[body + 1] = (uint8_t)(crc >> 8);
        buf[body + 2] = (uint8_t)(crc >> 16);
        buf[body + 3] = (uint8_t)(crc >> 24);
    }
    if (slipest_image_read(buf, size, 0u, &mq, &qs, &mf, &fs) != SLIPEST_OK) return 0;
    for (j = 0; j < SLIPEST_N_FEATURES; j++) {
        x[j] = (int16_t)(j & 1 ? -32768 : 32767); /* extreme inputs: the overflow bounds must hold */
        xf[j] = (float)x[j] * 0.001f;
    }
    cls = slipest_infer_q(&mq, x, logits, &sat);
    if (cls < 0 || cls > 2) __builtin_trap();
    cls = slipest_infer_f32(&mf, xf, lf);
    if (cls > 2) __builtin_trap();
    return 0;
}
