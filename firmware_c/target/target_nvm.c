/* RAM-backed NVM of the QEMU test images (target_nvm.h): the strict common RAM NVM (ram_nvm.h). */
#include "target_nvm.h"

#include "ram_nvm.h"

uint8_t target_nvm_mem[TARGET_NVM_BYTES];
static ram_nvm_t ram;

void target_nvm_init(slipest_nvm_t *nvm)
{
    ram_nvm_init(&ram, target_nvm_mem, TARGET_NVM_SECTOR, SLIPEST_STORE_NVM_SECTORS(TARGET_NVM_SECTOR), nvm);
}
