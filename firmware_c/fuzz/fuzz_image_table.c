/* libFuzzer: arbitrary bytes through the format-2 (layer-table) model-image reader, then both kernels.
 * Built only where the library has the layer-table reader (SLIPEST_LAYER_TABLE, e.g. an SN-D bundle's
 * build). As in fuzz_image, mutations reach the layer table, the caps, the shifts, the row bounds and
 * the float checks behind the CRC (fuzz_image_copy), and a model the reader accepts must run without
 * UB (ASan + UBSan) at the int16 rails and give a valid class (fuzz_image_run): the overflow proof of
 * docs/fixed_point.md, exercised on every layer table the reader lets through.
 * Seed: the bundle's model.img (scripts/fuzz.sh). */
#include <stddef.h>
#include <stdint.h>

#include "fuzz_image_run.h"
#include "slipest_image.h"
#include "slipest_image_table.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t buf[SLIPEST_IMAGE_TABLE_MAX_SIZE + 64u];
    static slipest_image_table_q_t qs;
    static slipest_image_table_f32_t fs;
    slipest_model_q_t mq;
    slipest_model_f32_t mf;
    size_t len = fuzz_image_copy(buf, sizeof buf, data, size);

    if (len == 0u || slipest_image_read_table(buf, len, 0u, &mq, &qs, &mf, &fs) != SLIPEST_OK) return 0;
    fuzz_image_run(&mq, &mf);
    return 0;
}
