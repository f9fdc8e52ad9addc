/* RAM NVM and seed image for the store fuzzers; see fuzz_nvm.h. */
#include "fuzz_nvm.h"

#include "ram_nvm.h"

#include <stdio.h>
#include <string.h>

uint8_t fuzz_nvm_mem[FUZZ_NVM_SIZE];
static ram_nvm_t ram;
static slipest_nvm_t strict;

/* The strict RAM NVM, trapping on an access outside the area or off a sector boundary (the store
 * must keep to slipest_store.h). A write onto a sector that is not erased is the fuzzer's own doing
 * (a bit flipped into an erased sector): the store sees it as the failed program it would be. */
static slipest_status_t checked(slipest_status_t st)
{
    if (st == SLIPEST_E_RANGE) __builtin_trap();
    return (st == SLIPEST_E_STATE) ? SLIPEST_E_NVM : st;
}

static slipest_status_t nvm_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    (void)ctx;
    return checked(strict.read(strict.ctx, addr, buf, len));
}

static slipest_status_t nvm_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    (void)ctx;
    return checked(strict.write(strict.ctx, addr, buf, len));
}

static slipest_status_t nvm_erase(void *ctx, uint32_t addr)
{
    (void)ctx;
    return checked(strict.erase(strict.ctx, addr));
}

void fuzz_nvm_reset(slipest_nvm_t *nvm)
{
    ram_nvm_init(&ram, fuzz_nvm_mem, FUZZ_NVM_SECTOR, FUZZ_NVM_SECTORS, &strict);
    *nvm = strict;
    nvm->read = nvm_read;
    nvm->write = nvm_write;
    nvm->erase = nvm_erase;
    nvm->ctx = NULL;
}

void fuzz_nvm_fail_next(void)
{
    ram.fail_at = 1u;
}

const uint8_t *fuzz_seed_image(size_t *len)
{
    static uint8_t img[SLIPEST_STORE_IMAGE_MAX];
    static size_t img_len;
    if (img_len == 0u) {
        FILE *fp = fopen(SLIPEST_FUZZ_IMAGE, "rb");
        if (fp == NULL) __builtin_trap();
        img_len = fread(img, 1, sizeof img, fp);
        fclose(fp);
        if (img_len == 0u) __builtin_trap();
    }
    *len = img_len;
    return img;
}
