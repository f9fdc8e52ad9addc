/* libFuzzer: arbitrary sequences of model-store operations (begin, chunked writes of a valid or
 * mutated image, finish, activate, rollback, abort, reboot) over a RAM NVM that fails or
 * corrupts on command. After every operation: whatever model the store calls active passes
 * slipest_model_q_check() and runs without UB on extreme inputs (ASan + UBSan build; the check
 * is cached on the model's bytes, see fuzz_model_check.h).
 * The image written is the example bundle's model.img (path compiled in), so mutations reach
 * finish and activation instead of dying at the magic. */
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "fuzz_model_check.h"
#include "fuzz_nvm.h"
#include "slipest_store.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static slipest_store_t st;
    static uint8_t img[SLIPEST_STORE_IMAGE_MAX];
    static const uint8_t key[16] = {1, 2, 3};
    static const slipest_store_auth_t auth = SLIPEST_STORE_AUTH_HMAC_SHA256(key, sizeof key);
    slipest_nvm_t nvm;
    size_t p = 0, img_len;
    uint32_t off = 0;
    const uint8_t *seed = fuzz_seed_image(&img_len);

    fuzz_nvm_reset(&nvm);
    memcpy(img, seed, img_len);
    /* first byte: authentication on or off */
    (void)slipest_store_open(&st, &nvm, (size > 0 && (data[0] & 0x80u)) ? &auth : NULL);
    while (p < size) {
        uint8_t op = data[p++];
        uint8_t arg = p < size ? data[p++] : 0u;
        switch (op % 11u) {
        case 0: /* begin with the image length, or a length from the input */
            off = 0;
            (void)slipest_store_begin(&st, (arg & 1u) ? (uint32_t)img_len : (uint32_t)arg * 16u, arg >> 7);
            break;
        case 1: { /* write the next arg bytes of the image (an out-of-order offset when arg is odd) */
            uint32_t n = arg;
            uint32_t at = (arg & 1u) ? off + 1u : off;
            if (at > img_len) at = (uint32_t)img_len;
            if (n > img_len - at) n = (uint32_t)(img_len - at);
            if (slipest_store_write(&st, at, img + at, n) == SLIPEST_OK) off = at + n;
            break;
        }
        case 2: /* write everything left */
            if (off <= img_len && slipest_store_write(&st, off, img + off, img_len - off) == SLIPEST_OK) {
                off = (uint32_t)img_len;
            }
            break;
        case 3: (void)slipest_store_finish(&st); break;
        case 4: (void)slipest_store_activate(&st); break;
        case 5: (void)slipest_store_rollback(&st); break;
        case 6: (void)slipest_store_abort(&st); break;
        case 7: /* reboot */
            (void)slipest_store_open(&st, &nvm, (arg & 0x80u) ? &auth : NULL);
            break;
        case 8: fuzz_nvm_fail_next(); break;
        case 9: /* mutate the image to upload: one byte, or the model version */
            if (p < size) {
                uint8_t v = data[p++];
                if (arg & 1u) img[SLIPEST_IMAGE_OFF_MODEL_VERSION] = (uint8_t)(img[SLIPEST_IMAGE_OFF_MODEL_VERSION] + v);
                else img[((size_t)arg * 16u + v) % img_len] ^= v;
            }
            break;
        default: /* corrupt one NVM byte (a bit flip in flash) */
            if (p < size) fuzz_nvm_mem[((size_t)arg * 256u + data[p++]) % sizeof fuzz_nvm_mem] ^= 0x10u;
            break;
        }
        fuzz_check_model_q(slipest_store_model_q(&st), 1);
    }
    return 0;
}
