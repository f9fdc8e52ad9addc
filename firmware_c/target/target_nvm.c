/* RAM-backed NVM of the QEMU test images (target_nvm.h). */
#include "target_nvm.h"

#include <string.h>

uint8_t target_nvm_mem[TARGET_NVM_BYTES];

static slipest_status_t nvm_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (addr > sizeof target_nvm_mem || len > sizeof target_nvm_mem - addr) return SLIPEST_E_RANGE;
    memcpy(buf, &target_nvm_mem[addr], len);
    return SLIPEST_OK;
}

static slipest_status_t nvm_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    (void)ctx;
    if (len != TARGET_NVM_SECTOR || addr % TARGET_NVM_SECTOR != 0u || addr > sizeof target_nvm_mem - TARGET_NVM_SECTOR) {
        return SLIPEST_E_RANGE;
    }
    memcpy(&target_nvm_mem[addr], buf, len);
    return SLIPEST_OK;
}

static slipest_status_t nvm_erase(void *ctx, uint32_t addr)
{
    (void)ctx;
    if (addr % TARGET_NVM_SECTOR != 0u || addr > sizeof target_nvm_mem - TARGET_NVM_SECTOR) return SLIPEST_E_RANGE;
    memset(&target_nvm_mem[addr], 0xFF, TARGET_NVM_SECTOR);
    return SLIPEST_OK;
}

void target_nvm_init(slipest_nvm_t *nvm)
{
    memset(target_nvm_mem, 0xFF, sizeof target_nvm_mem);
    nvm->read = nvm_read;
    nvm->write = nvm_write;
    nvm->erase = nvm_erase;
    nvm->sector_size = TARGET_NVM_SECTOR;
    nvm->n_sectors = SLIPEST_STORE_NVM_SECTORS(TARGET_NVM_SECTOR);
    nvm->ctx = NULL;
}
