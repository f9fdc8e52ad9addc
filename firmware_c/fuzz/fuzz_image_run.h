/* What the two image fuzzers (fuzz_image: format 1, fuzz_image_table: format 2) share. */
#ifndef FUZZ_IMAGE_RUN_H
#define FUZZ_IMAGE_RUN_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_model.h"

/* Copy the fuzzer's input into buf (cap bytes); when it is long enough to hold a header and a
 * trailer, re-seal the copy with a correct CRC-32 half of the time (steered by the input's last
 * byte), so mutations reach the field checks behind the CRC. Returns the length, 0 if it does not fit. */
size_t fuzz_image_copy(uint8_t *buf, size_t cap, const uint8_t *data, size_t size);

/* Run a model the reader accepted, both paths, on inputs at the int16 rails (the overflow bounds
 * must hold there): a class outside 0..2 traps, and ASan/UBSan report any undefined behaviour. */
void fuzz_image_run(const slipest_model_q_t *mq, const slipest_model_f32_t *mf);

#endif
