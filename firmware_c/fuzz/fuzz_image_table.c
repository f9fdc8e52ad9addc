/* libFuzzer: arbitrary bytes through the format-2 (layer-table) model-image reader, then both kernels.
 * Built only where the library has the layer-table reader (SLIPEST_LAYER_TABLE, e.g. an SN-D bundle's
 * build). As in fuzz_image, a long enough input is re-sealed with a correct CRC-32 half of the time
 * (steered by its last byte), so mutations reach the layer table, the caps, the shifts, the row bounds
 * and the float checks behind the CRC. A model the reader accepts must run without UB (ASan + UBSan)
 * on extreme inputs and give a valid class: the overflow proof of docs/fixed_point.md, exercised on
 * every layer table the reader lets through. Seed: the bundle's model.img (scripts/fuzz.sh). */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_image.h"
#include "slipest_image_table.h"
#include "slipest_infer.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t buf[SLIPEST_IMAGE_TABLE_MAX_SIZE + 64u];
    static slipest_image_table_q_t qs;
    static slipest_image_table_f32_t fs;
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
    if (slipest_image_read_table(buf, size, 0u, &mq, &qs, &mf, &fs) != SLIPEST_OK) return 0;
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
