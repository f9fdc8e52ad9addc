/* libFuzzer: arbitrary (counter, sample) sequences through the extractor; checks the
 * window invariants and that every closed window yields features without UB. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "slipest_features.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    slipest_extractor_t ex;
    slipest_window_t out[SLIPEST_MAX_CLOSED];
    size_t i;
    slipest_extractor_init(&ex);
    /* each record: 2 bytes counter + 14 bytes sample; byte 0 bit 7 of a record's counter
     * high byte steers a reset now and then */
    for (i = 0; i + 16 <= size; i += 16) {
        uint16_t counter = (uint16_t)(data[i] | (data[i + 1] << 8));
        int16_t s[SLIPEST_N_CHANNELS];
        int r, k;
        memcpy(s, data + i + 2, sizeof s);
        if (data[i + 2] == 0xA5 && data[i + 3] == 0x5A) slipest_extractor_reset_grid(&ex);
        r = slipest_extractor_push(&ex, counter, s, out);
        if (r > SLIPEST_MAX_CLOSED) __builtin_trap();
        for (k = 0; k < r; k++) {
            int16_t fq[SLIPEST_N_FEATURES];
            float ff[SLIPEST_N_FEATURES];
            if (out[k].n == 0 || out[k].n > SLIPEST_SAMPLES_PER_WINDOW) __builtin_trap();
            if ((out[k].n < SLIPEST_SAMPLES_PER_WINDOW) != ((out[k].flags & SLIPEST_FLAG_GAP) != 0)) __builtin_trap();
            if (slipest_window_features_q(&out[k], fq) < 0) __builtin_trap();
            if (slipest_window_features_f32(&out[k], ff) < 0) __builtin_trap();
            if (fq[1] < 0 || ff[1] < 0.0f) __builtin_trap(); /* std is never negative */
        }
    }
    return 0;
}
