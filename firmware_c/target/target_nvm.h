/* The model store's NVM in the QEMU test images (co_node_target.c, store_target.c): a RAM array of
 * 64-byte sectors, sized for two slots and the records, standing for the integrator's flash. It
 * is the strict common RAM NVM (firmware_c/common/ram_nvm.h): whole erased sectors written at
 * sector-aligned addresses, sector-aligned erases, nothing outside the area. */
#ifndef TARGET_NVM_H
#define TARGET_NVM_H
#include <stdint.h>

#include "slipest_store.h"

/* small sectors: the area fits the smallest target RAM (16 KiB) */
#define TARGET_NVM_SECTOR 64u
#define TARGET_NVM_BYTES (SLIPEST_STORE_NVM_SECTORS(TARGET_NVM_SECTOR) * TARGET_NVM_SECTOR)

/* the area itself (tests corrupt it to simulate a bad slot) */
extern uint8_t target_nvm_mem[TARGET_NVM_BYTES];

/* Erase the whole area (as a blank flash) and describe it in *nvm. */
void target_nvm_init(slipest_nvm_t *nvm);
#endif
