/* libFuzzer: arbitrary bytes through the model-image reader (format 1). A long enough input is
 * re-sealed with a correct CRC-32 half of the time (fuzz_image_copy), so mutations reach the field
 * checks behind the CRC. A model the reader accepts must run without UB (this target is built with
 * ASan + UBSan) and give a valid class (fuzz_image_run).
 * Seed corpus: the bundle's model.img (scripts/fuzz.sh copies it in). */
#include <stddef.h>
#include <stdint.h>

#include "fuzz_image_run.h"
#include "slipest_image.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t buf[SLIPEST_IMAGE_MAX_SIZE + 64u];
    static slipest_image_q_storage_t qs;
    static slipest_image_f32_storage_t fs;
    slipest_model_q_t mq;
    slipest_model_f32_t mf;
    size_t len = fuzz_image_copy(buf, sizeof buf, data, size);

    if (len == 0u || slipest_image_read(buf, len, 0u, &mq, &qs, &mf, &fs) != SLIPEST_OK) return 0;
    fuzz_image_run(&mq, &mf);
    return 0;
}
