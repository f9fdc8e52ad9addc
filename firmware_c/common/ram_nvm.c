/* The strict RAM NVM (ram_nvm.h). */
#include "ram_nvm.h"

#include <string.h>

slipest_status_t ram_nvm_write_rule(uint32_t addr, uint32_t len, uint32_t sector, uint32_t size, const uint8_t *cur)
{
    uint32_t i;
    if (len != sector || addr % sector != 0u || addr > size || size - addr < sector) return SLIPEST_E_RANGE;
    for (i = 0; i < len; ++i) {
        if (cur[i] != 0xFFu) return SLIPEST_E_STATE; /* programming needs an erased sector */
    }
    return SLIPEST_OK;
}

slipest_status_t ram_nvm_erase_rule(uint32_t addr, uint32_t sector, uint32_t size)
{
    return (addr % sector != 0u || addr > size || size - addr < sector) ? SLIPEST_E_RANGE : SLIPEST_OK;
}

static int fails_now(ram_nvm_t *r)
{
    r->ops++;
    if (r->fail_all != 0) return 1;
    if (r->fail_at > 0u) {
        r->fail_at--;
        return r->fail_at == 0u;
    }
    return 0;
}

static slipest_status_t r_read(void *ctx, uint32_t addr, uint8_t *buf, uint32_t len)
{
    ram_nvm_t *r = ctx;
    if (r->fail_reads != 0) return SLIPEST_E_NVM;
    if (addr > r->size || len > r->size - addr) {
        r->refused++;
        return SLIPEST_E_RANGE;
    }
    memcpy(buf, r->mem + addr, len);
    return SLIPEST_OK;
}

static slipest_status_t r_write(void *ctx, uint32_t addr, const uint8_t *buf, uint32_t len)
{
    ram_nvm_t *r = ctx;
    slipest_status_t st = ram_nvm_erase_rule(addr, r->sector, r->size); /* the shape first: cur must be inside */
    if (st == SLIPEST_OK) st = ram_nvm_write_rule(addr, len, r->sector, r->size, r->mem + addr);
    if (st != SLIPEST_OK) {
        r->refused++;
        return st;
    }
    if (fails_now(r)) return SLIPEST_E_NVM;
    memcpy(r->mem + addr, buf, len);
    return SLIPEST_OK;
}

static slipest_status_t r_erase(void *ctx, uint32_t addr)
{
    ram_nvm_t *r = ctx;
    if (ram_nvm_erase_rule(addr, r->sector, r->size) != SLIPEST_OK) {
        r->refused++;
        return SLIPEST_E_RANGE;
    }
    if (fails_now(r)) return SLIPEST_E_NVM;
    memset(r->mem + addr, 0xFF, r->sector);
    return SLIPEST_OK;
}

void ram_nvm_init(ram_nvm_t *r, uint8_t *mem, uint32_t sector, uint32_t n_sectors, slipest_nvm_t *nvm)
{
    r->mem = mem;
    r->sector = sector;
    r->size = sector * n_sectors;
    r->fail_at = 0u;
    r->fail_all = 0;
    r->fail_reads = 0;
    r->ops = 0u;
    r->refused = 0u;
    memset(mem, 0xFF, r->size);
    *nvm = (slipest_nvm_t){r_read, r_write, r_erase, sector, n_sectors, r};
}
