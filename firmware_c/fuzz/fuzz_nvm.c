/* RAM NVM and seed image for the store fuzzers; see fuzz_nvm.h. */
#include "fuzz_nvm.h"

#include <stdio.h>
#include <string.h>

uint8_t fuzz_nvm_mem[FUZZ_NVM_SIZE];
static int fail_next;

static slipest_status_t nvm_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (addr > sizeof fuzz_nvm_mem || len > sizeof fuzz_nvm_mem - addr) __builtin_trap();
    memcpy(buf, fuzz_nvm_mem + addr, len);
    return SLIPEST_OK;
}

static slipest_status_t nvm_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (len != FUZZ_NVM_SECTOR || addr % FUZZ_NVM_SECTOR != 0u || addr > sizeof fuzz_nvm_mem - len) {
        __builtin_trap();
    }
    if (fail_next) {
        fail_next = 0;
        return SLIPEST_E_NVM;
    }
    memcpy(fuzz_nvm_mem + addr, buf, len);
    return SLIPEST_OK;
}

static slipest_status_t nvm_erase(void *ctx, uint32_t addr)
{
    (void)ctx;
    if (addr % FUZZ_NVM_SECTOR != 0u || addr > sizeof fuzz_nvm_mem - FUZZ_NVM_SECTOR) __builtin_trap();
    if (fail_next) {
        fail_next = 0;
        return SLIPEST_E_NVM;
    }
    memset(fuzz_nvm_mem + addr, 0xFF, FUZZ_NVM_SECTOR);
    return SLIPEST_OK;
}

void fuzz_nvm_reset(slipest_nvm_t *nvm)
{
    memset(fuzz_nvm_mem, 0xFF, sizeof fuzz_nvm_mem);
    fail_next = 0;
    nvm->read = nvm_read;
    nvm->write = nvm_write;
    nvm->erase = nvm_erase;
    nvm->sector_size = FUZZ_NVM_SECTOR;
    nvm->n_sectors = FUZZ_NVM_SECTORS;
    nvm->ctx = NULL;
}

void fuzz_nvm_fail_next(void)
{
    fail_next = 1;
}

const uint8_t *fuzz_seed_image(size_t *len)
{
    static uint8_t img[SLIPEST_IMAGE_MAX_SIZE];
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
