/* Shared by the fuzzers that drive the model store (fuzz_store, fuzz_co_frames): the strict RAM
 * NVM (firmware_c/common/ram_nvm.h) with 64-byte sectors, trapping on any access outside the area
 * or off a sector boundary (the store must keep to slipest_store.h; a write onto a sector the fuzzer
 * flipped a bit into is an NVM error), which can fail the next write or erase on command, and the
 * seed image those fuzzers upload (the example bundle's model.img, read once per process). */
#ifndef FUZZ_NVM_H
#define FUZZ_NVM_H

#include <stddef.h>
#include <stdint.h>

#include "slipest_store.h"

#define FUZZ_NVM_SECTOR 64u
#define FUZZ_NVM_SECTORS (SLIPEST_STORE_NVM_SECTORS(FUZZ_NVM_SECTOR))
#define FUZZ_NVM_SIZE (FUZZ_NVM_SECTORS * FUZZ_NVM_SECTOR)

extern uint8_t fuzz_nvm_mem[FUZZ_NVM_SIZE];

/* Erase the whole area (0xFF), clear a pending failure, and fill *nvm with the callbacks. */
void fuzz_nvm_reset(slipest_nvm_t *nvm);

/* The next write or erase returns SLIPEST_E_NVM and changes nothing. */
void fuzz_nvm_fail_next(void);

/* The seed image (traps if SLIPEST_FUZZ_IMAGE cannot be read); *len gets its size. */
const uint8_t *fuzz_seed_image(size_t *len);

#endif /* FUZZ_NVM_H */
