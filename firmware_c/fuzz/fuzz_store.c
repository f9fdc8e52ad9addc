/* libFuzzer: arbitrary sequences of model-store operations (begin, chunked writes of a valid or
 * mutated image, finish, activate, rollback, abort, reboot) over a RAM NVM that fails or
 * corrupts on command. After every operation: whatever model the store calls active passes
 * slipest_model_q_check() and runs without UB on extreme inputs (ASan + UBSan build).
 * The image written is the example bundle's model.img (path compiled in), so mutations reach
 * finish and activation instead of dying at the magic. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "slipest_infer.h"
#include "slipest_store.h"

#define SECTOR 64u
#define N_SECT (SLIPEST_STORE_NVM_SECTORS(SECTOR))

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static uint8_t mem[N_SECT * SECTOR];
static uint8_t seed_img[SLIPEST_IMAGE_MAX_SIZE];
static size_t seed_len;
static int fail_next; /* fail the next write/erase */

static slipest_status_t f_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (addr > sizeof mem || len > sizeof mem - addr) __builtin_trap(); /* the store stays inside */
    memcpy(buf, mem + addr, len);
    return SLIPEST_OK;
}

static slipest_status_t f_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (len != SECTOR || addr % SECTOR != 0u || addr + len > sizeof mem) __builtin_trap();
    if (fail_next) {
        fail_next = 0;
        return SLIPEST_E_NVM;
    }
    memcpy(mem + addr, buf, len);
    return SLIPEST_OK;
}

static slipest_status_t f_erase(void *ctx, uint32_t addr)
{
    (void)ctx;
    if (addr % SECTOR != 0u || addr + SECTOR > sizeof mem) __builtin_trap();
    if (fail_next) {
        fail_next = 0;
        return SLIPEST_E_NVM;
    }
    memset(mem + addr, 0xFF, SECTOR);
    return SLIPEST_OK;
}

static void check_active(const slipest_store_t *st)
{
    const slipest_model_q_t *m = slipest_store_model_q(st);
    int16_t x[SLIPEST_N_FEATURES];
    int32_t logits[SLIPEST_N_CLASSES];
    uint16_t sat;
    int j;
    if (m == NULL) return;
    if (slipest_model_q_check(m) != SLIPEST_OK) __builtin_trap();
    for (j = 0; j < SLIPEST_N_FEATURES; j++) x[j] = (int16_t)(j & 1 ? -32768 : 32767);
    j = slipest_infer_q(m, x, logits, &sat);
    if (j < 0 || j > 2) __builtin_trap();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static slipest_store_t st;
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
    static const uint8_t key[16] = {1, 2, 3};
    slipest_nvm_t nvm;
    size_t p = 0, img_len;
    uint32_t off = 0;

    if (seed_len == 0u) {
        FILE *fp = fopen(SLIPEST_FUZZ_IMAGE, "rb");
        if (fp == NULL) __builtin_trap();
        seed_len = fread(seed_img, 1, sizeof seed_img, fp);
        fclose(fp);
    }
    memset(mem, 0xFF, sizeof mem);
    fail_next = 0;
    memcpy(img, seed_img, seed_len);
    img_len = seed_len;
    nvm.read = f_read;
    nvm.write = f_write;
    nvm.erase = f_erase;
    nvm.sector_size = SECTOR;
    nvm.n_sectors = N_SECT;
    nvm.ctx = NULL;
    /* first byte: authentication on or off */
    (void)slipest_store_open(&st, &nvm, (size > 0 && (data[0] & 0x80u)) ? key : NULL, 16u);
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
            (void)slipest_store_open(&st, &nvm, (arg & 0x80u) ? key : NULL, 16u);
            break;
        case 8: fail_next = 1; break;
        case 9: /* mutate the image to upload: one byte, or the model version */
            if (p < size) {
                uint8_t v = data[p++];
                if (arg & 1u) img[34] = (uint8_t)(img[34] + v);
                else img[((size_t)arg * 16u + v) % img_len] ^= v;
            }
            break;
        default: /* corrupt one NVM byte (a bit flip in flash) */
            if (p < size) mem[((size_t)arg * 256u + data[p++]) % sizeof mem] ^= 0x10u;
            break;
        }
        check_active(&st);
    }
    return 0;
}
