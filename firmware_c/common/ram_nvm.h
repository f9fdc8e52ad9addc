/* The one strict RAM NVM (slipest_nvm_t over a caller's array) of every C test, fuzzer and QEMU
 * image, and the rules the emulator's file NVM applies too; the Python RamNvm
 * (host_tools/canopen_node.py) mirrors them. Like flash it refuses, without changing anything:
 * a write that is not one whole sector, not sector-aligned, outside the area, or onto a sector
 * that is not erased (programming only clears bits); an erase off a sector boundary or outside
 * the area; a read outside the area. A test can make the K-th write or erase from now, every
 * write and erase, or every read fail. */
#ifndef RAM_NVM_H
#define RAM_NVM_H

#include <stdint.h>

#include "slipest_store.h"

typedef struct {
    uint8_t *mem;       /* n_sectors * sector_size bytes */
    uint32_t sector;    /* sector size */
    uint32_t size;      /* bytes of the area */
    uint32_t fail_at;   /* 0: never; K: the K-th write or erase from now fails (SLIPEST_E_NVM) */
    int fail_all;       /* non-zero: every write and erase fails (SLIPEST_E_NVM) */
    int fail_reads;     /* non-zero: every read fails (SLIPEST_E_NVM) */
    uint32_t ops;       /* writes and erases attempted */
    uint32_t refused;   /* accesses refused by the rules (a store that keeps to slipest_store.h: 0) */
} ram_nvm_t;

/* Erase mem (0xFF) and describe it in *nvm with r as its context. */
void ram_nvm_init(ram_nvm_t *r, uint8_t *mem, uint32_t sector, uint32_t n_sectors, slipest_nvm_t *nvm);

/* SLIPEST_OK when a write of len bytes at addr is one whole aligned sector inside an area of size
 * bytes and cur (that sector as it is now) is erased; else SLIPEST_E_RANGE (shape) or
 * SLIPEST_E_STATE (not erased). */
slipest_status_t ram_nvm_write_rule(uint32_t addr, uint32_t len, uint32_t sector, uint32_t size, const uint8_t *cur);

/* SLIPEST_OK when an erase at addr is sector-aligned inside an area of size bytes, else SLIPEST_E_RANGE. */
slipest_status_t ram_nvm_erase_rule(uint32_t addr, uint32_t sector, uint32_t size);

#endif /* RAM_NVM_H */
